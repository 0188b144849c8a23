//! The `scbg` Python module (`scbg._scbg`): numpy in and out, the same `scbg` library calls as
//! the HTTP server. Inference runs with the interpreter released (other Python threads go on).
//!
//! **Architecture invariant:** glue between Python and the `scbg` library; no numerics,
//! formats or models of its own.

use std::collections::HashMap;
use std::sync::Arc;

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use scbg::scene::Scene as RustScene;
use scbg::{Courtesy, SceneArrays};

/// An `anyhow` error as a Python exception: the caller's fault is a `ValueError`.
fn py_err(err: anyhow::Error) -> PyErr {
    if scbg::is_invalid_request(&err) {
        PyValueError::new_err(format!("{err:#}"))
    } else {
        PyRuntimeError::new_err(format!("{err:#}"))
    }
}

/// One traffic scenario.
#[pyclass(module = "scbg", frozen)]
#[derive(Clone)]
struct Scene {
    inner: Arc<RustScene>,
}

fn polylines(lines: Vec<PyReadonlyArray2<'_, f64>>, what: &str) -> PyResult<Vec<Vec<[f64; 2]>>> {
    lines
        .iter()
        .enumerate()
        .map(|(k, a)| {
            let a = a.as_array();
            if a.ncols() != 2 {
                return Err(PyValueError::new_err(format!(
                    "{what}[{k}]: expected shape [n, 2], got {:?}",
                    a.shape()
                )));
            }
            Ok(a.rows().into_iter().map(|r| [r[0], r[1]]).collect())
        })
        .collect()
}

#[pymethods]
impl Scene {
    /// A scene from arrays (see the stubs).
    #[staticmethod]
    #[pyo3(signature = (scenario_id, ids, states, valid, object_types=None, current_step=10, sdc_id=None, objects_of_interest=Vec::new(), lanes=Vec::new(), road_edges=Vec::new(), road_lines=Vec::new(), lane_types=None))]
    #[allow(clippy::too_many_arguments)]
    fn from_arrays(
        scenario_id: String,
        ids: PyReadonlyArray1<'_, i64>,
        states: PyReadonlyArray3<'_, f64>,
        valid: PyReadonlyArray2<'_, bool>,
        object_types: Option<Vec<String>>,
        current_step: usize,
        sdc_id: Option<i64>,
        objects_of_interest: Vec<i64>,
        lanes: Vec<PyReadonlyArray2<'_, f64>>,
        road_edges: Vec<PyReadonlyArray2<'_, f64>>,
        road_lines: Vec<PyReadonlyArray2<'_, f64>>,
        lane_types: Option<Vec<String>>,
    ) -> PyResult<Self> {
        let (ids, states, valid) = (ids.as_array(), states.as_array(), valid.as_array());
        let [n, t, f] = [states.shape()[0], states.shape()[1], states.shape()[2]];
        if f != 7 {
            return Err(PyValueError::new_err(format!(
                "states: expected shape [agents, steps, 7] (x, y, heading, vx, vy, length, width), got {:?}",
                states.shape()
            )));
        }
        if ids.len() != n || valid.shape() != [n, t] {
            return Err(PyValueError::new_err(format!(
                "ids {:?} and valid {:?} must match states' [agents, steps] = [{n}, {t}]",
                ids.shape(),
                valid.shape()
            )));
        }
        let scene = SceneArrays {
            scenario_id,
            ids: ids.to_vec(),
            states: (0..n)
                .map(|i| {
                    (0..t)
                        .map(|k| std::array::from_fn(|j| states[[i, k, j]]))
                        .collect()
                })
                .collect(),
            valid: (0..n)
                .map(|i| (0..t).map(|k| valid[[i, k]]).collect())
                .collect(),
            object_types,
            current_step,
            sdc_id,
            objects_of_interest,
            lanes: polylines(lanes, "lanes")?,
            lane_types,
            road_edges: polylines(road_edges, "road_edges")?,
            road_lines: polylines(road_lines, "road_lines")?,
        }
        .build()
        .map_err(|e| PyValueError::new_err(e.0))?;
        Ok(Self {
            inner: Arc::new(scene),
        })
    }

    #[getter]
    fn scenario_id(&self) -> String {
        self.inner.scenario_id.clone()
    }

    #[getter]
    fn current_step(&self) -> usize {
        self.inner.current_step
    }

    #[getter]
    fn num_steps(&self) -> usize {
        self.inner.num_steps()
    }

    #[getter]
    fn sdc_id(&self) -> Option<i64> {
        self.inner.sdc_track_index.map(|i| self.inner.tracks[i].id)
    }

    #[getter]
    fn ids<'py>(&self, py: Python<'py>) -> Bound<'py, PyArray1<i64>> {
        Array1::from_iter(self.inner.tracks.iter().map(|t| t.id)).into_pyarray(py)
    }

    #[getter]
    fn objects_of_interest(&self) -> Vec<i64> {
        self.inner.objects_of_interest.clone()
    }

    /// `points [n, 2]` (world metres) kept in lane as scbg's closed loop keeps a plan: each
    /// point pulled to within `max_offset_m` of the nearest lane heading its way, and the rest
    /// of a plan that leaves every lane carried on along its lane's route. `agent_id`, the
    /// track whose plan it is, starts the plan on the lane under it.
    #[pyo3(signature = (points, max_offset_m=scbg::DEFAULT_LANE_KEEPING_M, agent_id=None))]
    fn keep_in_lane<'py>(
        &self,
        py: Python<'py>,
        points: PyReadonlyArray2<'_, f64>,
        max_offset_m: f64,
        agent_id: Option<i64>,
    ) -> PyResult<Bound<'py, PyArray2<f64>>> {
        let mut plan = polylines(vec![points], "points")?.remove(0);
        let scene = Arc::clone(&self.inner);
        py.detach(|| scbg::keep_in_lane(&scene, agent_id, &mut plan, max_offset_m))
            .map_err(py_err)?;
        let mut out = Array2::<f64>::zeros((plan.len(), 2));
        for (k, p) in plan.iter().enumerate() {
            out[[k, 0]] = p[0];
            out[[k, 1]] = p[1];
        }
        Ok(out.into_pyarray(py))
    }

    /// `([agents, steps, 7], [agents, steps])`.
    fn states<'py>(
        &self,
        py: Python<'py>,
    ) -> (Bound<'py, PyArray3<f64>>, Bound<'py, PyArray2<bool>>) {
        let s = &self.inner;
        let (n, t) = (s.tracks.len(), s.num_steps());
        let mut states = Array3::<f64>::zeros((n, t, 7));
        let mut valid = Array2::<bool>::from_elem((n, t), false);
        for (i, tr) in s.tracks.iter().enumerate() {
            for (k, a) in tr.states.iter().enumerate() {
                let row = [
                    a.x_m,
                    a.y_m,
                    f64::from(a.heading_rad),
                    f64::from(a.velocity_x_mps),
                    f64::from(a.velocity_y_mps),
                    f64::from(a.length_m),
                    f64::from(a.width_m),
                ];
                for (j, v) in row.into_iter().enumerate() {
                    states[[i, k, j]] = v;
                }
                valid[[i, k]] = a.valid;
            }
        }
        (states.into_pyarray(py), valid.into_pyarray(py))
    }

    fn __repr__(&self) -> String {
        format!(
            "Scene({:?}, {} tracks, {} steps, current step {})",
            self.inner.scenario_id,
            self.inner.tracks.len(),
            self.inner.num_steps(),
            self.inner.current_step
        )
    }
}

/// A trained generator folder.
#[pyclass(module = "scbg", frozen)]
struct Model {
    inner: Arc<scbg::Model>,
}

#[pymethods]
impl Model {
    /// `policy`: how a courtesy becomes B's future, `"generator"` (the learned g(x, ψ)) or
    /// `"ranked"` (B's sampled futures ranked by their ψ labels).
    #[new]
    #[pyo3(signature = (path, predictor=None, policy="generator"))]
    fn new(
        py: Python<'_>,
        path: std::path::PathBuf,
        predictor: Option<std::path::PathBuf>,
        policy: &str,
    ) -> PyResult<Self> {
        let options = scbg::LoadOptions {
            predictor,
            policy: policy.parse().map_err(PyValueError::new_err)?,
            cached_pairs: 256,
        };
        let model = py
            .detach(|| scbg::Model::load(&path, &options))
            .map_err(py_err)?;
        Ok(Self {
            inner: Arc::new(model),
        })
    }

    #[getter]
    fn variant(&self) -> String {
        self.inner.variant().name().to_string()
    }

    /// How a courtesy becomes B's future: `generator` or `ranked`.
    #[getter]
    fn policy(&self) -> String {
        self.inner.policy().name().to_string()
    }

    /// Whose reward the model's courtesy counts: `pair` (A alone) or
    /// `neighbours <radius> m <sum|proximity>`.
    #[getter]
    fn audience(&self) -> String {
        self.inner.audience()
    }

    /// How many generators plan together: 1, or an ensemble folder's members.
    #[getter]
    fn members(&self) -> usize {
        self.inner.members()
    }

    #[pyo3(signature = (scene, a, b, quantile=None, psi=None))]
    fn generate<'py>(
        &self,
        py: Python<'py>,
        scene: &Scene,
        a: i64,
        b: i64,
        quantile: Option<f32>,
        psi: Option<f32>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let courtesy =
            Courtesy::from_request(quantile, psi).map_err(|e| PyValueError::new_err(e.0))?;
        let (model, s) = (self.inner.clone(), scene.inner.clone());
        let out = py
            .detach(move || model.generate(&s, a, b, &[courtesy]))
            .map_err(py_err)?;
        let g = &out.trajectories[0];
        let d = PyDict::new(py);
        d.set_item("quantile", g.quantile)?;
        d.set_item("psi", g.psi)?;
        d.set_item("psi_low", g.psi_low)?;
        d.set_item("psi_high", g.psi_high)?;
        d.set_item("achieved_psi", g.achieved_psi)?;
        d.set_item("a_expected_speed_mps", g.a_expected_reward_conditional)?;
        d.set_item(
            "a_expected_speed_marginal_mps",
            g.a_expected_reward_marginal,
        )?;
        let xy = Array2::from_shape_fn((g.world_xy_m.len(), 2), |(i, j)| g.world_xy_m[i][j]);
        d.set_item("world_xy_m", xy.into_pyarray(py))?;
        Ok(d)
    }

    fn courtesy<'py>(
        &self,
        py: Python<'py>,
        scene: &Scene,
        a: i64,
        b: i64,
        future_xy_m: PyReadonlyArray2<'py, f64>,
    ) -> PyResult<Bound<'py, PyDict>> {
        let f = future_xy_m.as_array();
        if f.ncols() != 2 {
            return Err(PyValueError::new_err(format!(
                "future_xy_m: expected shape [80, 2], got {:?}",
                f.shape()
            )));
        }
        let future: Vec<[f64; 2]> = f.rows().into_iter().map(|r| [r[0], r[1]]).collect();
        let (model, s) = (self.inner.clone(), scene.inner.clone());
        let c = py
            .detach(move || model.courtesy_of(&s, a, b, &future))
            .map_err(py_err)?;
        let d = PyDict::new(py);
        d.set_item("psi", c.psi)?;
        d.set_item(
            "a_expected_reward_conditional",
            c.a_expected_reward_conditional,
        )?;
        d.set_item("a_expected_reward_marginal", c.a_expected_reward_marginal)?;
        Ok(d)
    }

    #[pyo3(signature = (scene, controlled, ego=None, ego_mode="external", others="log", replan_every=None))]
    #[allow(clippy::too_many_arguments)]
    fn simulation(
        &self,
        py: Python<'_>,
        scene: &Scene,
        controlled: HashMap<i64, f32>,
        ego: Option<i64>,
        ego_mode: &str,
        others: &str,
        replan_every: Option<usize>,
    ) -> PyResult<Simulation> {
        let options = scbg::LoopOptions {
            ego: ego_mode.parse().map_err(PyValueError::new_err)?,
            others: others.parse().map_err(PyValueError::new_err)?,
            replan_every,
        };
        let controlled = controlled
            .into_iter()
            .map(|(id, q)| {
                Courtesy::quantile(q)
                    .map(|c| scbg::ControlledAgent::new(id, c))
                    .map_err(|e| PyValueError::new_err(format!("agent {id}: {}", e.0)))
            })
            .collect::<PyResult<Vec<_>>>()?;
        let (model, s) = (self.inner.clone(), scene.inner.clone());
        let session = py
            .detach(move || scbg::Session::start(model, s, ego, controlled, &options))
            .map_err(py_err)?;
        Ok(Simulation { session })
    }

    fn __repr__(&self) -> String {
        format!(
            "Model(variant={:?}, audience={:?}, policy={:?})",
            self.variant(),
            self.audience(),
            self.policy()
        )
    }
}

/// A closed-loop simulation.
#[pyclass(module = "scbg")]
struct Simulation {
    session: scbg::Session,
}

type StepArrays<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<bool>>,
);

fn snapshot_arrays<'py>(py: Python<'py>, snap: &[scbg::Snapshot]) -> StepArrays<'py> {
    let ids = Array1::from_iter(snap.iter().map(|a| a.id));
    let states = Array2::from_shape_fn((snap.len(), 5), |(i, j)| {
        let s = &snap[i].state;
        match j {
            0 => s.x_m,
            1 => s.y_m,
            2 => f64::from(s.heading_rad),
            3 => f64::from(s.velocity_x_mps),
            _ => f64::from(s.velocity_y_mps),
        }
    });
    let valid = Array1::from_iter(snap.iter().map(|a| a.state.valid));
    (
        ids.into_pyarray(py),
        states.into_pyarray(py),
        valid.into_pyarray(py),
    )
}

#[pymethods]
impl Simulation {
    fn reset<'py>(&mut self, py: Python<'py>) -> PyResult<StepArrays<'py>> {
        let session = &mut self.session;
        py.detach(|| session.reset()).map_err(py_err)?;
        Ok(snapshot_arrays(py, &self.session.snapshot()))
    }

    #[pyo3(signature = (ego_state=None))]
    fn step<'py>(
        &mut self,
        py: Python<'py>,
        ego_state: Option<PyReadonlyArray1<'py, f64>>,
    ) -> PyResult<StepArrays<'py>> {
        let ego = match ego_state {
            None => None,
            Some(a) => {
                let a = a.as_array();
                if a.len() != 5 {
                    return Err(PyValueError::new_err(format!(
                        "ego_state: expected [x, y, heading, vx, vy], got {} values",
                        a.len()
                    )));
                }
                Some(scbg::EgoPose {
                    x_m: a[0],
                    y_m: a[1],
                    heading_rad: a[2] as f32,
                    velocity_mps: [a[3] as f32, a[4] as f32],
                })
            }
        };
        let session = &mut self.session;
        let snap = py.detach(|| session.step(ego)).map_err(py_err)?;
        Ok(snapshot_arrays(py, &snap))
    }

    #[getter]
    fn step_index(&self) -> usize {
        self.session.step_index()
    }

    #[getter]
    fn finished(&self) -> bool {
        self.session.finished()
    }

    #[getter]
    fn ego_id(&self) -> i64 {
        self.session.ego_id()
    }

    /// The scene with the simulated steps as its future.
    fn scene(&self) -> Scene {
        Scene {
            inner: Arc::new(self.session.to_scene()),
        }
    }
}

/// Every scenario of a WOMD file.
#[pyfunction]
fn read_scenarios(py: Python<'_>, path: std::path::PathBuf) -> PyResult<Vec<Scene>> {
    let scenes = py
        .detach(|| scbg::data::read_scenes(&path))
        .map_err(|e| PyValueError::new_err(format!("{e:#}")))?;
    Ok(scenes
        .into_iter()
        .map(|s| Scene { inner: Arc::new(s) })
        .collect())
}

/// Every scenario of WOMD bytes.
#[pyfunction]
fn scenarios_from_bytes(py: Python<'_>, data: Vec<u8>) -> PyResult<Vec<Scene>> {
    let scenes = py
        .detach(|| scbg::data::scenes_from_bytes(data))
        .map_err(py_err)?;
    Ok(scenes
        .into_iter()
        .map(|s| Scene { inner: Arc::new(s) })
        .collect())
}

/// WOSAC 2025 realism of a submission (shards or `.tar.gz` archives of them) against the
/// logged scenarios of WOMD files: `scbg eval wosac`'s `wosac.json` as a dict.
#[pyfunction]
fn score_wosac<'py>(
    py: Python<'py>,
    scenario_files: Vec<std::path::PathBuf>,
    submission_files: Vec<std::path::PathBuf>,
) -> PyResult<Bound<'py, PyAny>> {
    let text = |paths: Vec<std::path::PathBuf>| -> Vec<String> {
        paths
            .iter()
            .map(|p| p.to_string_lossy().into_owned())
            .collect()
    };
    let (scenarios, submission) = (text(scenario_files), text(submission_files));
    let json = py
        .detach(move || -> anyhow::Result<String> {
            let score = scbg::wosac::score_submission(&scenarios, &submission, &scbg::Quiet)?;
            Ok(serde_json::to_string(&score)?)
        })
        .map_err(py_err)?;
    py.import("json")?.call_method1("loads", (json,))
}

#[pymodule]
fn _scbg(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Model>()?;
    m.add_class::<Scene>()?;
    m.add_class::<Simulation>()?;
    m.add_function(wrap_pyfunction!(read_scenarios, m)?)?;
    m.add_function(wrap_pyfunction!(scenarios_from_bytes, m)?)?;
    m.add_function(wrap_pyfunction!(score_wosac, m)?)?;
    Ok(())
}
