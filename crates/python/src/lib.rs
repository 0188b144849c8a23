//! The `scbg` Python module (`scbg._scbg`): numpy in and out, the same `scbg` library calls as
//! the HTTP server. Inference runs with the interpreter released (other Python threads go on).
//!
//! **Architecture invariant:** glue between Python and the `scbg` library; no numerics,
//! formats or models of its own.

use std::collections::HashMap;
use std::sync::{Arc, Mutex};

use numpy::ndarray::{Array1, Array2, Array3};
use numpy::{
    IntoPyArray, PyArray1, PyArray2, PyArray3, PyReadonlyArray1, PyReadonlyArray2, PyReadonlyArray3,
};
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use scbg::choices::Courtesy;
use scbg::generate::PairContext;
use scbg::generator::LoadedScbg;
use scbg::scene::{
    AgentState, Lane, Map, MapPoint, ObjectType, RoadEdge, RoadEdgeType, RoadLine, RoadLineType,
    Scene as RustScene, Track,
};

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

fn object_type(name: &str) -> PyResult<ObjectType> {
    Ok(match name {
        "vehicle" => ObjectType::Vehicle,
        "pedestrian" => ObjectType::Pedestrian,
        "cyclist" => ObjectType::Cyclist,
        "other" => ObjectType::Other,
        "unset" => ObjectType::Unset,
        other => {
            return Err(PyValueError::new_err(format!(
                "object type {other:?}: expected vehicle, pedestrian, cyclist, other or unset"
            )));
        }
    })
}

fn polylines(lines: Vec<PyReadonlyArray2<'_, f64>>, what: &str) -> PyResult<Vec<Vec<MapPoint>>> {
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
            Ok(a.rows()
                .into_iter()
                .map(|r| MapPoint {
                    x_m: r[0],
                    y_m: r[1],
                    z_m: 0.0,
                })
                .collect())
        })
        .collect()
}

#[pymethods]
impl Scene {
    /// A scene from arrays (see the stubs).
    #[staticmethod]
    #[pyo3(signature = (scenario_id, ids, states, valid, object_types=None, current_step=10, sdc_id=None, objects_of_interest=Vec::new(), lanes=Vec::new(), road_edges=Vec::new(), road_lines=Vec::new()))]
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
        let types = match object_types {
            Some(v) if v.len() != n => {
                return Err(PyValueError::new_err(format!(
                    "object_types has {} names for {n} agents",
                    v.len()
                )));
            }
            Some(v) => v
                .iter()
                .map(|s| object_type(s))
                .collect::<PyResult<Vec<_>>>()?,
            None => vec![ObjectType::Vehicle; n],
        };
        let tracks = (0..n)
            .map(|i| Track {
                id: ids[i],
                object_type: types[i],
                states: (0..t)
                    .map(|k| {
                        let s = states.slice(numpy::ndarray::s![i, k, ..]);
                        AgentState {
                            x_m: s[0],
                            y_m: s[1],
                            z_m: 0.0,
                            heading_rad: s[2] as f32,
                            velocity_x_mps: s[3] as f32,
                            velocity_y_mps: s[4] as f32,
                            length_m: s[5] as f32,
                            width_m: s[6] as f32,
                            height_m: 1.6,
                            valid: valid[[i, k]],
                        }
                    })
                    .collect(),
            })
            .collect::<Vec<_>>();
        let sdc_track_index = match sdc_id {
            None => None,
            Some(id) => Some(tracks.iter().position(|tr| tr.id == id).ok_or_else(|| {
                PyValueError::new_err(format!("sdc_id {id} is not one of the ids"))
            })?),
        };
        let mut id = 0i64;
        let mut next = || {
            id += 1;
            id
        };
        let map = Map {
            lanes: polylines(lanes, "lanes")?
                .into_iter()
                .map(|polyline| Lane {
                    id: next(),
                    polyline,
                    ..Default::default()
                })
                .collect(),
            road_edges: polylines(road_edges, "road_edges")?
                .into_iter()
                .map(|polyline| RoadEdge {
                    id: next(),
                    edge_type: RoadEdgeType::Boundary,
                    polyline,
                })
                .collect(),
            road_lines: polylines(road_lines, "road_lines")?
                .into_iter()
                .map(|polyline| RoadLine {
                    id: next(),
                    line_type: RoadLineType::BrokenSingleWhite,
                    polyline,
                })
                .collect(),
            ..Default::default()
        };
        let scene = RustScene {
            scenario_id,
            timestamps_secs: (0..t).map(|k| k as f64 * 0.1).collect(),
            current_step,
            sdc_track_index,
            tracks,
            objects_of_interest,
            tracks_to_predict: Vec::new(),
            map,
            signals_per_step: Vec::new(),
        };
        scene
            .validate()
            .map_err(|e| PyValueError::new_err(format!("invalid scene: {e}")))?;
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

type Contexts = HashMap<(usize, i64, i64), (Arc<RustScene>, Arc<PairContext>)>;

/// Pair contexts kept per model.
const MAX_CONTEXTS: usize = 256;

/// A trained generator folder.
#[pyclass(module = "scbg", frozen)]
struct Model {
    inner: Arc<LoadedScbg>,
    /// Pair contexts by (scene object, A, B): repeated generation on a loaded scene costs the
    /// generator and J_φ only. The entry holds the scene, so its address names it while
    /// cached (another scene with the same id gets its own context).
    contexts: Mutex<Contexts>,
}

fn courtesy_of(quantile: Option<f32>, psi: Option<f32>) -> PyResult<Courtesy> {
    match (quantile, psi) {
        (Some(q), None) => Ok(Courtesy::Quantile(q)),
        (None, Some(p)) => Ok(Courtesy::Psi(p)),
        (Some(_), Some(_)) => Err(PyValueError::new_err(
            "give either quantile or psi, not both",
        )),
        (None, None) => Err(PyValueError::new_err("give quantile (in [0, 1]) or psi")),
    }
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
        let policy: scbg::choices::Policy = policy.parse().map_err(PyValueError::new_err)?;
        let mut model = py
            .detach(|| scbg::generator::load_scbg(&path, predictor.as_deref()))
            .map_err(py_err)?;
        model.scbg.policy = policy;
        Ok(Self {
            inner: Arc::new(model),
            contexts: Mutex::new(HashMap::new()),
        })
    }

    #[getter]
    fn variant(&self) -> String {
        self.inner.checkpoint.variant.name().to_string()
    }

    /// How a courtesy becomes B's future: `generator` or `ranked`.
    #[getter]
    fn policy(&self) -> String {
        self.inner.scbg.policy.name().to_string()
    }

    /// Whose reward the model's courtesy counts: `pair` (A alone) or
    /// `neighbours <radius> m <sum|proximity>`.
    #[getter]
    fn audience(&self) -> String {
        self.inner.checkpoint.labels.audience.describe()
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
        let courtesy = courtesy_of(quantile, psi)?;
        let key = (Arc::as_ptr(&scene.inner) as usize, a, b);
        let cached = self
            .contexts
            .lock()
            .expect("contexts")
            .get(&key)
            .map(|(_, c)| c.clone());
        let (model, s) = (self.inner.clone(), scene.inner.clone());
        let (ctx, out) = py
            .detach(move || -> anyhow::Result<_> {
                let ctx = match cached {
                    Some(c) => c,
                    None => Arc::new(scbg::generate::pair_context(&model, &s, a, b)?),
                };
                let out = scbg::generate::generate_in(&model, &ctx, &[courtesy])?;
                Ok((ctx, out))
            })
            .map_err(py_err)?;
        let mut contexts = self.contexts.lock().expect("contexts");
        if contexts.len() >= MAX_CONTEXTS {
            contexts.clear();
        }
        contexts.insert(key, (scene.inner.clone(), ctx));
        let g = &out[0];
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
            .detach(move || scbg::generate::courtesy(&model, &s, a, b, &future))
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
        let ego_mode: scbg::sim::EgoMode = ego_mode.parse().map_err(PyValueError::new_err)?;
        let others: scbg::sim::OthersMode = others.parse().map_err(PyValueError::new_err)?;
        let mut controlled: Vec<scbg::sim::ControlledAgent> = controlled
            .into_iter()
            .map(|(id, q)| scbg::sim::ControlledAgent {
                id,
                courtesy: Courtesy::Quantile(q),
            })
            .collect();
        controlled.sort_by_key(|c| c.id);
        let config = scbg::sim::SimConfig {
            replan_every: replan_every
                .unwrap_or_else(|| scbg::sim::default_replan_every(self.inner.scbg.policy)),
            ego: ego_mode,
            others,
            ..Default::default()
        };
        let s = scene.inner.clone();
        let ctl = controlled.clone();
        let sim = py
            .detach(move || scbg::sim::start(&s, ego, &ctl, config, None))
            .map_err(py_err)?;
        Ok(Simulation {
            model: self.inner.clone(),
            scene: scene.inner.clone(),
            ego,
            controlled,
            config,
            sim,
        })
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
    model: Arc<LoadedScbg>,
    scene: Arc<RustScene>,
    ego: Option<i64>,
    controlled: Vec<scbg::sim::ControlledAgent>,
    config: scbg::sim::SimConfig,
    sim: scbg::sim::Simulation,
}

type StepArrays<'py> = (
    Bound<'py, PyArray1<i64>>,
    Bound<'py, PyArray2<f64>>,
    Bound<'py, PyArray1<bool>>,
);

fn snapshot_arrays<'py>(py: Python<'py>, snap: &[scbg::sim::AgentSnapshot]) -> StepArrays<'py> {
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
        let (s, ego, ctl, config) = (
            self.scene.clone(),
            self.ego,
            self.controlled.clone(),
            self.config,
        );
        self.sim = py
            .detach(move || scbg::sim::start(&s, ego, &ctl, config, None))
            .map_err(py_err)?;
        Ok(snapshot_arrays(py, &self.sim.snapshot()))
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
                Some(self.sim.external_ego_state(
                    a[0],
                    a[1],
                    a[2] as f32,
                    [a[3] as f32, a[4] as f32],
                ))
            }
        };
        let (model, ctl) = (self.model.clone(), self.controlled.clone());
        let sim = &mut self.sim;
        let snap = py
            .detach(|| scbg::sim::step(&model, sim, &ctl, ego))
            .map_err(py_err)?;
        Ok(snapshot_arrays(py, &snap))
    }

    #[getter]
    fn step_index(&self) -> usize {
        self.sim.step_index()
    }

    #[getter]
    fn finished(&self) -> bool {
        self.sim.finished()
    }

    #[getter]
    fn ego_id(&self) -> i64 {
        self.sim.ego_id()
    }

    /// The scene with the simulated steps as its future.
    fn scene(&self) -> Scene {
        Scene {
            inner: Arc::new(self.sim.to_scene()),
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

#[pymodule]
fn _scbg(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add_class::<Model>()?;
    m.add_class::<Scene>()?;
    m.add_class::<Simulation>()?;
    m.add_function(wrap_pyfunction!(read_scenarios, m)?)?;
    m.add_function(wrap_pyfunction!(scenarios_from_bytes, m)?)?;
    Ok(())
}
