//! WOMD "motion tf.Example" → [`Scene`].
//!
//! The format stores a fixed number of agent slots (128) with 10 past, 1 current and 80 future
//! steps as row-major `[slots, steps]` arrays, a flattened road graph of sampled points, and
//! 16 traffic-light slots per step. Choices made here, since the format is lossy:
//! - an agent slot becomes a track when its `state/id` is not −1 or any of its steps is valid;
//! - timestamps come from `timestamp_micros` of any valid agent at that step; steps with none
//!   are filled at 0.1 s spacing from the nearest known one;
//! - road-graph points are grouped into one map feature per consecutive run of valid points
//!   with the same id; types map as `shared/spec/womd-format.md` lists (1–3 lanes, 6–13 road
//!   lines, 15/16 road edges, 17 stop sign, 18 crosswalk, 19 speed bump, 20 driveway);
//!   other type codes are ignored.

use std::collections::BTreeMap;

use prost::Message;
use scbg_scene::{
    AgentState, Crosswalk, Driveway, Lane, LaneType, Map, MapPoint, ObjectType,
    PredictionDifficulty, PredictionTarget, RoadEdge, RoadEdgeType, RoadLine, RoadLineType, Scene,
    SignalLaneState, SignalState, SpeedBump, StopSign, Track,
};

use crate::proto::{self, FeatureKind};

const PARTS: [(&str, usize); 3] = [("past", 10), ("current", 1), ("future", 80)];
const NUM_STEPS: usize = 91;
const CURRENT_STEP: usize = 10;
const STEP_SECS: f64 = 0.1;

/// A tf.Example that does not have the WOMD motion layout.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum ExampleError {
    /// A required feature key is absent.
    #[allow(missing_docs)]
    #[error("feature `{key}` is missing")]
    Missing { key: String },
    /// A feature holds a different list kind than expected.
    #[error("feature `{key}` is a {got} list, expected a {expected} list")]
    WrongKind {
        /// Feature key.
        key: String,
        /// List kind found (`bytes`, `float`, `int64` or `empty`).
        got: &'static str,
        /// List kind expected.
        expected: &'static str,
    },
    /// A feature has the wrong number of values.
    #[error("feature `{key}` has {got} values, expected {expected}")]
    WrongLength {
        /// Feature key.
        key: String,
        /// Number of values found.
        got: usize,
        /// Number of values expected.
        expected: usize,
    },
    /// `scenario/id` is not valid UTF-8.
    #[error("feature `scenario/id` is not UTF-8")]
    BadScenarioId,
    /// The converted scene fails [`Scene::validate`].
    #[error(transparent)]
    Scene(#[from] scbg_scene::SceneError),
}

/// Typed access to an Example's feature map.
struct Features<'a>(&'a BTreeMap<String, proto::Feature>);

fn kind_name(k: &Option<FeatureKind>) -> &'static str {
    match k {
        Some(FeatureKind::BytesList(_)) => "bytes",
        Some(FeatureKind::FloatList(_)) => "float",
        Some(FeatureKind::Int64List(_)) => "int64",
        None => "empty",
    }
}

impl<'a> Features<'a> {
    fn get(&self, key: &str) -> Result<&'a proto::Feature, ExampleError> {
        self.0
            .get(key)
            .ok_or_else(|| ExampleError::Missing { key: key.into() })
    }

    fn floats(&self, key: &str, expected: usize) -> Result<&'a [f32], ExampleError> {
        match &self.get(key)?.kind {
            Some(FeatureKind::FloatList(l)) if l.value.len() == expected => Ok(&l.value),
            Some(FeatureKind::FloatList(l)) => Err(ExampleError::WrongLength {
                key: key.into(),
                got: l.value.len(),
                expected,
            }),
            other => Err(ExampleError::WrongKind {
                key: key.into(),
                got: kind_name(other),
                expected: "float",
            }),
        }
    }

    fn ints(&self, key: &str, expected: usize) -> Result<&'a [i64], ExampleError> {
        match &self.get(key)?.kind {
            Some(FeatureKind::Int64List(l)) if l.value.len() == expected => Ok(&l.value),
            Some(FeatureKind::Int64List(l)) => Err(ExampleError::WrongLength {
                key: key.into(),
                got: l.value.len(),
                expected,
            }),
            other => Err(ExampleError::WrongKind {
                key: key.into(),
                got: kind_name(other),
                expected: "int64",
            }),
        }
    }

    /// Length of a float or int list, to size the road graph and slot arrays.
    fn len(&self, key: &str) -> Result<usize, ExampleError> {
        Ok(match &self.get(key)?.kind {
            Some(FeatureKind::FloatList(l)) => l.value.len(),
            Some(FeatureKind::Int64List(l)) => l.value.len(),
            Some(FeatureKind::BytesList(l)) => l.value.len(),
            None => 0,
        })
    }
}

/// Per-step state arrays `[slots, 91]` gathered from the past/current/future keys.
fn state_field_f32(f: &Features<'_>, name: &str, slots: usize) -> Result<Vec<f32>, ExampleError> {
    let mut out = vec![0.0f32; slots * NUM_STEPS];
    let mut step0 = 0;
    for (part, steps) in PARTS {
        let values = f.floats(&format!("state/{part}/{name}"), slots * steps)?;
        for slot in 0..slots {
            out[slot * NUM_STEPS + step0..slot * NUM_STEPS + step0 + steps]
                .copy_from_slice(&values[slot * steps..(slot + 1) * steps]);
        }
        step0 += steps;
    }
    Ok(out)
}

fn state_field_i64(f: &Features<'_>, name: &str, slots: usize) -> Result<Vec<i64>, ExampleError> {
    let mut out = vec![0i64; slots * NUM_STEPS];
    let mut step0 = 0;
    for (part, steps) in PARTS {
        let values = f.ints(&format!("state/{part}/{name}"), slots * steps)?;
        for slot in 0..slots {
            out[slot * NUM_STEPS + step0..slot * NUM_STEPS + step0 + steps]
                .copy_from_slice(&values[slot * steps..(slot + 1) * steps]);
        }
        step0 += steps;
    }
    Ok(out)
}

fn timestamps(micros: &[i64], valid: &[i64], slots: usize) -> Vec<f64> {
    let mut known: Vec<Option<f64>> = (0..NUM_STEPS)
        .map(|step| {
            (0..slots)
                .find(|&slot| valid[slot * NUM_STEPS + step] > 0)
                .map(|slot| micros[slot * NUM_STEPS + step] as f64 * 1e-6)
        })
        .collect();
    let anchor = known.iter().position(Option::is_some);
    match anchor {
        None => (0..NUM_STEPS).map(|s| s as f64 * STEP_SECS).collect(),
        Some(a) => {
            let t_a = known[a].expect("anchor is known");
            let mut last = (a, t_a);
            for (step, t) in known.iter_mut().enumerate() {
                match t {
                    Some(v) if step >= a => last = (step, *v),
                    Some(_) => {}
                    None if step < a => *t = Some(t_a - (a - step) as f64 * STEP_SECS),
                    None => *t = Some(last.1 + (step - last.0) as f64 * STEP_SECS),
                }
            }
            known.into_iter().map(|t| t.expect("filled")).collect()
        }
    }
}

fn road_graph(f: &Features<'_>) -> Result<Map, ExampleError> {
    let n = f.len("roadgraph_samples/id")?;
    let xyz = f.floats("roadgraph_samples/xyz", n * 3)?;
    let ids = f.ints("roadgraph_samples/id", n)?;
    let types = f.ints("roadgraph_samples/type", n)?;
    let valid = f.ints("roadgraph_samples/valid", n)?;
    let mut map = Map::default();
    let mut i = 0;
    while i < n {
        if valid[i] <= 0 {
            i += 1;
            continue;
        }
        let (id, ty) = (ids[i], types[i]);
        let start = i;
        while i < n && valid[i] > 0 && ids[i] == id && types[i] == ty {
            i += 1;
        }
        let pts: Vec<MapPoint> = (start..i)
            .map(|k| MapPoint {
                x_m: f64::from(xyz[3 * k]),
                y_m: f64::from(xyz[3 * k + 1]),
                z_m: f64::from(xyz[3 * k + 2]),
            })
            .collect();
        match ty {
            1..=3 => map.lanes.push(Lane {
                id,
                lane_type: LaneType::from_code(ty as i32),
                polyline: pts,
                ..Default::default()
            }),
            6..=13 => map.road_lines.push(RoadLine {
                id,
                line_type: RoadLineType::from_code((ty - 5) as i32),
                polyline: pts,
            }),
            15 | 16 => map.road_edges.push(RoadEdge {
                id,
                edge_type: RoadEdgeType::from_code((ty - 14) as i32),
                polyline: pts,
            }),
            17 => map.stop_signs.push(StopSign {
                id,
                lanes: vec![],
                position: pts[0],
            }),
            18 => map.crosswalks.push(Crosswalk { id, polygon: pts }),
            19 => map.speed_bumps.push(SpeedBump { id, polygon: pts }),
            20 => map.driveways.push(Driveway { id, polygon: pts }),
            _ => {}
        }
    }
    Ok(map)
}

fn signals(f: &Features<'_>) -> Result<Vec<Vec<SignalLaneState>>, ExampleError> {
    let lights = f.len("traffic_light_state/current/state")?;
    let mut out = Vec::with_capacity(NUM_STEPS);
    for (part, steps) in PARTS {
        let key = |name: &str| format!("traffic_light_state/{part}/{name}");
        let n = steps * lights;
        let state = f.ints(&key("state"), n)?;
        let valid = f.ints(&key("valid"), n)?;
        let id = f.ints(&key("id"), n)?;
        let (x, y, z) = (
            f.floats(&key("x"), n)?,
            f.floats(&key("y"), n)?,
            f.floats(&key("z"), n)?,
        );
        for step in 0..steps {
            out.push(
                (0..lights)
                    .map(|l| step * lights + l)
                    .filter(|&k| valid[k] > 0)
                    .map(|k| SignalLaneState {
                        lane_id: id[k],
                        state: SignalState::from_code(state[k] as i32),
                        stop_point: Some(MapPoint {
                            x_m: f64::from(x[k]),
                            y_m: f64::from(y[k]),
                            z_m: f64::from(z[k]),
                        }),
                    })
                    .collect(),
            );
        }
    }
    Ok(out)
}

/// Number of feature keys in a serialized tf.Example (for inspection and tests).
pub fn count_feature_keys(bytes: &[u8]) -> Result<usize, prost::DecodeError> {
    Ok(proto::Example::decode(bytes)?
        .features
        .map_or(0, |f| f.feature.len()))
}

/// True when a decoded record looks like a WOMD motion tf.Example.
pub(crate) fn is_motion_example(example: &proto::Example) -> bool {
    example.features.as_ref().is_some_and(|f| {
        f.feature.contains_key("scenario/id") && f.feature.contains_key("state/id")
    })
}

/// Converts a decoded WOMD motion tf.Example into a validated [`Scene`].
pub fn scene_from_example(example: &proto::Example) -> Result<Scene, ExampleError> {
    let empty = BTreeMap::new();
    let f = Features(example.features.as_ref().map_or(&empty, |f| &f.feature));
    let scenario_id = match &f.get("scenario/id")?.kind {
        Some(FeatureKind::BytesList(b)) if !b.value.is_empty() => {
            String::from_utf8(b.value[0].clone()).map_err(|_| ExampleError::BadScenarioId)?
        }
        other => {
            return Err(ExampleError::WrongKind {
                key: "scenario/id".into(),
                got: kind_name(other),
                expected: "bytes",
            });
        }
    };
    let slots = f.len("state/id")?;
    let ids = f.floats("state/id", slots)?;
    let types = f.floats("state/type", slots)?;
    let is_sdc = f.ints("state/is_sdc", slots)?;
    let to_predict = f.ints("state/tracks_to_predict", slots)?;
    let interest = f.ints("state/objects_of_interest", slots)?;
    let difficulty = f.ints("state/difficulty_level", slots).ok();
    let valid = state_field_i64(&f, "valid", slots)?;
    let micros = state_field_i64(&f, "timestamp_micros", slots)?;
    let [x, y, z, yaw, length, width, height, vx, vy] = [
        "x",
        "y",
        "z",
        "bbox_yaw",
        "length",
        "width",
        "height",
        "velocity_x",
        "velocity_y",
    ]
    .map(|name| state_field_f32(&f, name, slots));
    let (x, y, z, yaw) = (x?, y?, z?, yaw?);
    let (length, width, height, vx, vy) = (length?, width?, height?, vx?, vy?);

    let mut tracks = Vec::new();
    let mut scene_index_of_slot = vec![None; slots];
    for slot in 0..slots {
        let row = slot * NUM_STEPS..(slot + 1) * NUM_STEPS;
        let any_valid = valid[row.clone()].iter().any(|&v| v > 0);
        if ids[slot] == -1.0 && !any_valid {
            continue;
        }
        scene_index_of_slot[slot] = Some(tracks.len());
        tracks.push(Track {
            id: ids[slot] as i64,
            object_type: ObjectType::from_code(types[slot] as i32),
            states: row
                .map(|k| AgentState {
                    x_m: f64::from(x[k]),
                    y_m: f64::from(y[k]),
                    z_m: f64::from(z[k]),
                    length_m: length[k],
                    width_m: width[k],
                    height_m: height[k],
                    heading_rad: yaw[k],
                    velocity_x_mps: vx[k],
                    velocity_y_mps: vy[k],
                    valid: valid[k] > 0,
                })
                .collect(),
        });
    }
    let kept = |slot: usize| scene_index_of_slot[slot];
    let scene = Scene {
        scenario_id,
        timestamps_secs: timestamps(&micros, &valid, slots),
        current_step: CURRENT_STEP,
        sdc_track_index: (0..slots).find(|&s| is_sdc[s] > 0).and_then(kept),
        objects_of_interest: (0..slots)
            .filter(|&s| interest[s] > 0 && kept(s).is_some())
            .map(|s| ids[s] as i64)
            .collect(),
        tracks_to_predict: (0..slots)
            .filter(|&s| to_predict[s] > 0)
            .filter_map(|s| {
                kept(s).map(|track_index| PredictionTarget {
                    track_index,
                    difficulty: PredictionDifficulty::from_code(
                        difficulty.map_or(0, |d| d[s] as i32),
                    ),
                })
            })
            .collect(),
        map: road_graph(&f)?,
        signals_per_step: signals(&f)?,
        tracks,
    };
    scene.validate()?;
    Ok(scene)
}
