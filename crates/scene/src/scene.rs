//! The scene value type: tracks, interaction labels, map and signals.

use crate::map::{Map, MapPoint};

/// WOMD `Track.ObjectType`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ObjectType {
    /// Type not set (also what unknown codes map to).
    #[default]
    Unset = 0,
    /// A motor vehicle.
    Vehicle = 1,
    /// A pedestrian.
    Pedestrian = 2,
    /// A cyclist.
    Cyclist = 3,
    /// Any other object.
    Other = 4,
}

impl ObjectType {
    /// The variant for a protobuf code; unknown codes map to `Unset`.
    pub fn from_code(code: i32) -> Self {
        match code {
            1 => Self::Vehicle,
            2 => Self::Pedestrian,
            3 => Self::Cyclist,
            4 => Self::Other,
            _ => Self::Unset,
        }
    }

    /// The protobuf enum code (inverse of [`ObjectType::from_code`]).
    pub fn code(self) -> i32 {
        self as i32
    }

    /// Lower-case name as used in reports (`vehicle`, `pedestrian`, `cyclist`, `other`, `unset`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Unset => "unset",
            Self::Vehicle => "vehicle",
            Self::Pedestrian => "pedestrian",
            Self::Cyclist => "cyclist",
            Self::Other => "other",
        }
    }
}

/// The state of one object at one time step, world frame.
///
/// When `valid` is false the other fields carry no meaning (WOMD writes −1 there).
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct AgentState {
    /// Centre x, world frame, metres.
    pub x_m: f64,
    /// Centre y, world frame, metres.
    pub y_m: f64,
    /// Centre z (elevation), world frame, metres.
    pub z_m: f64,
    /// Bounding-box length (along the heading), metres.
    pub length_m: f32,
    /// Bounding-box width, metres.
    pub width_m: f32,
    /// Bounding-box height, metres.
    pub height_m: f32,
    /// Heading of the box's length axis, radians, world frame (counter-clockwise from +x).
    pub heading_rad: f32,
    /// Velocity x component, world frame, m/s.
    pub velocity_x_mps: f32,
    /// Velocity y component, world frame, m/s.
    pub velocity_y_mps: f32,
    /// Whether the object was observed at this step; if false, ignore every other field.
    pub valid: bool,
}

impl AgentState {
    /// Speed (norm of the velocity), m/s.
    pub fn speed_mps(&self) -> f32 {
        (self.velocity_x_mps * self.velocity_x_mps + self.velocity_y_mps * self.velocity_y_mps)
            .sqrt()
    }
}

/// One object's states over every time step of the scene (`states.len() == scene.num_steps()`).
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Track {
    /// Object id, unique within the scene (referenced by [`Scene::objects_of_interest`]).
    pub id: i64,
    /// What kind of object this is.
    pub object_type: ObjectType,
    /// `[num_steps]` states, one per time step of the scene (check each state's `valid`).
    pub states: Vec<AgentState>,
}

impl Track {
    /// Number of valid steps.
    pub fn num_valid(&self) -> usize {
        self.states.iter().filter(|s| s.valid).count()
    }
}

/// WOMD `RequiredPrediction.DifficultyLevel`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum PredictionDifficulty {
    /// No difficulty given (also what unknown codes map to).
    #[default]
    None = 0,
    /// WOMD difficulty level 1.
    Level1 = 1,
    /// WOMD difficulty level 2.
    Level2 = 2,
}

impl PredictionDifficulty {
    /// The variant for a protobuf code; unknown codes map to `None`.
    pub fn from_code(code: i32) -> Self {
        match code {
            1 => Self::Level1,
            2 => Self::Level2,
            _ => Self::None,
        }
    }
}

/// A track the benchmark asks to predict.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct PredictionTarget {
    /// Index into [`Scene::tracks`].
    pub track_index: usize,
    /// Difficulty level the benchmark assigns to this target.
    pub difficulty: PredictionDifficulty,
}

/// WOMD `TrafficSignalLaneState.State`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SignalState {
    /// State unknown (also what unknown codes map to).
    #[default]
    Unknown = 0,
    /// Red arrow.
    ArrowStop = 1,
    /// Yellow arrow.
    ArrowCaution = 2,
    /// Green arrow.
    ArrowGo = 3,
    /// Red light.
    Stop = 4,
    /// Yellow light.
    Caution = 5,
    /// Green light.
    Go = 6,
    /// Flashing red.
    FlashingStop = 7,
    /// Flashing yellow.
    FlashingCaution = 8,
}

impl SignalState {
    /// The variant for a protobuf code; unknown codes map to `Unknown`.
    pub fn from_code(code: i32) -> Self {
        match code {
            1 => Self::ArrowStop,
            2 => Self::ArrowCaution,
            3 => Self::ArrowGo,
            4 => Self::Stop,
            5 => Self::Caution,
            6 => Self::Go,
            7 => Self::FlashingStop,
            8 => Self::FlashingCaution,
            _ => Self::Unknown,
        }
    }
}

/// The state of the signal controlling one lane at one step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct SignalLaneState {
    /// Id of the controlled lane ([`Lane::id`](crate::Lane::id)).
    pub lane_id: i64,
    /// The signal's state at this step.
    pub state: SignalState,
    /// Where vehicles in that lane must stop, world frame, when given.
    pub stop_point: Option<MapPoint>,
}

/// One traffic scenario: tracks over time, which of them matter, the map and the signals.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Scene {
    /// Scenario id from the dataset (or the generator), used to name and look up the scene.
    pub scenario_id: String,
    /// One timestamp per step, seconds (10 Hz in WOMD).
    pub timestamps_secs: Vec<f64>,
    /// The "now" step: history is `..=current_step`, future is after it.
    pub current_step: usize,
    /// Index of the self-driving car's track, when known.
    pub sdc_track_index: Option<usize>,
    /// Every object of the scene, each with one state per step.
    pub tracks: Vec<Track>,
    /// Track *ids* (not indices) of objects labelled as interacting.
    pub objects_of_interest: Vec<i64>,
    /// Tracks the benchmark asks to predict (by index into [`Scene::tracks`]).
    pub tracks_to_predict: Vec<PredictionTarget>,
    /// Static map features (world frame).
    pub map: Map,
    /// Signal states per step (`signals_per_step.len() == num_steps` when present, else empty).
    pub signals_per_step: Vec<Vec<SignalLaneState>>,
}

/// A scene that breaks an invariant of [`Scene`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneError {
    /// `timestamps_secs` is empty.
    #[error("scene has no time steps")]
    NoSteps,
    /// `current_step` is not below the number of steps.
    #[error("current step {current_step} is outside the {num_steps} steps")]
    CurrentStepOutOfRange {
        /// The offending `current_step`.
        current_step: usize,
        /// Number of steps of the scene.
        num_steps: usize,
    },
    /// A track's `states` length differs from the number of steps.
    #[error("track {track_id} has {got} states but the scene has {num_steps} steps")]
    TrackLength {
        /// Id of the track.
        track_id: i64,
        /// Number of states it has.
        got: usize,
        /// Number of steps of the scene.
        num_steps: usize,
    },
    /// A valid state has a NaN, infinite or huge field (beyond [`MAX_ABS_VALUE`]).
    #[error(
        "track {track_id} step {step}: field `{field}` is not finite or beyond ±1e7 in a valid state"
    )]
    NonFiniteState {
        /// Id of the track.
        track_id: i64,
        /// Step of the state.
        step: usize,
        /// Name of the non-finite field (e.g. `center_x`).
        field: &'static str,
    },
    /// A map point is NaN, infinite or huge.
    #[allow(missing_docs)]
    #[error("map feature {feature_id}: a point is not finite or beyond ±1e7 m")]
    NonFiniteMapPoint { feature_id: i64 },
    /// A timestamp is NaN or infinite.
    #[allow(missing_docs)]
    #[error("timestamp at step {step} is not finite")]
    NonFiniteTimestamp { step: usize },
    /// A timestamp is not after the one before it.
    #[allow(missing_docs)]
    #[error("timestamps out of order: step {step} at {secs} s is not after the step before")]
    TimestampOrder { step: usize, secs: f64 },
    /// Two tracks share an id.
    #[allow(missing_docs)]
    #[error("track id {track_id} is used by more than one track")]
    DuplicateTrackId { track_id: i64 },
    /// An SDC or prediction-target track index is out of range.
    #[error("{what} index {index} is outside the {num_tracks} tracks")]
    TrackIndexOutOfRange {
        /// Which index: `sdc_track` or `tracks_to_predict`.
        what: &'static str,
        /// The out-of-range index.
        index: usize,
        /// Number of tracks of the scene.
        num_tracks: usize,
    },
    /// `signals_per_step` is non-empty but its length differs from the number of steps.
    #[allow(missing_docs)]
    #[error("signals cover {got} steps but the scene has {num_steps}")]
    SignalLength { got: usize, num_steps: usize },
}

/// The largest magnitude of any number of a valid state or map point (metres, m/s, radians):
/// 10,000 km, far beyond any map, and small enough that every later computation in `f32`
/// stays finite.
pub const MAX_ABS_VALUE: f64 = 1e7;

/// Finite and within [`MAX_ABS_VALUE`].
fn plausible(v: impl Into<f64>) -> bool {
    let v = v.into();
    v.is_finite() && v.abs() <= MAX_ABS_VALUE
}

impl Scene {
    /// Number of time steps (`timestamps_secs.len()`).
    pub fn num_steps(&self) -> usize {
        self.timestamps_secs.len()
    }

    /// Index of the track with this id.
    pub fn track_index(&self, id: i64) -> Option<usize> {
        self.tracks.iter().position(|t| t.id == id)
    }

    /// The valid state of track `id` at the current step, if any.
    pub fn current_state(&self, id: i64) -> Option<&AgentState> {
        let track = &self.tracks[self.track_index(id)?];
        track.states.get(self.current_step).filter(|s| s.valid)
    }

    /// Checks the invariants every consumer relies on: consistent lengths, indices in range,
    /// timestamps in order, unique track ids, finite numbers within [`MAX_ABS_VALUE`] wherever
    /// `valid` is set and in the map. Readers call this before returning a scene.
    pub fn validate(&self) -> Result<(), SceneError> {
        let num_steps = self.num_steps();
        if num_steps == 0 {
            return Err(SceneError::NoSteps);
        }
        if self.current_step >= num_steps {
            return Err(SceneError::CurrentStepOutOfRange {
                current_step: self.current_step,
                num_steps,
            });
        }
        if let Some(step) = self.timestamps_secs.iter().position(|t| !t.is_finite()) {
            return Err(SceneError::NonFiniteTimestamp { step });
        }
        if let Some(step) =
            (1..num_steps).find(|&k| self.timestamps_secs[k] <= self.timestamps_secs[k - 1])
        {
            return Err(SceneError::TimestampOrder {
                step,
                secs: self.timestamps_secs[step],
            });
        }
        let mut ids: Vec<i64> = self.tracks.iter().map(|t| t.id).collect();
        ids.sort_unstable();
        if let Some(w) = ids.windows(2).find(|w| w[0] == w[1]) {
            return Err(SceneError::DuplicateTrackId { track_id: w[0] });
        }
        for track in &self.tracks {
            if track.states.len() != num_steps {
                return Err(SceneError::TrackLength {
                    track_id: track.id,
                    got: track.states.len(),
                    num_steps,
                });
            }
            for (step, s) in track.states.iter().enumerate() {
                if !s.valid {
                    continue;
                }
                let checks: [(&'static str, bool); 9] = [
                    ("center_x", plausible(s.x_m)),
                    ("center_y", plausible(s.y_m)),
                    ("center_z", plausible(s.z_m)),
                    ("length", plausible(s.length_m)),
                    ("width", plausible(s.width_m)),
                    ("height", plausible(s.height_m)),
                    ("heading", plausible(s.heading_rad)),
                    ("velocity_x", plausible(s.velocity_x_mps)),
                    ("velocity_y", plausible(s.velocity_y_mps)),
                ];
                if let Some((field, _)) = checks.iter().find(|(_, ok)| !ok) {
                    return Err(SceneError::NonFiniteState {
                        track_id: track.id,
                        step,
                        field,
                    });
                }
            }
        }
        let num_tracks = self.tracks.len();
        if let Some(i) = self.sdc_track_index.filter(|&i| i >= num_tracks) {
            return Err(SceneError::TrackIndexOutOfRange {
                what: "sdc_track",
                index: i,
                num_tracks,
            });
        }
        if let Some(t) = self
            .tracks_to_predict
            .iter()
            .find(|t| t.track_index >= num_tracks)
        {
            return Err(SceneError::TrackIndexOutOfRange {
                what: "tracks_to_predict",
                index: t.track_index,
                num_tracks,
            });
        }
        if !self.signals_per_step.is_empty() && self.signals_per_step.len() != num_steps {
            return Err(SceneError::SignalLength {
                got: self.signals_per_step.len(),
                num_steps,
            });
        }
        let finite = |p: &MapPoint| plausible(p.x_m) && plausible(p.y_m) && plausible(p.z_m);
        let m = &self.map;
        let bad = m
            .lanes
            .iter()
            .find(|f| !f.polyline.iter().all(finite))
            .map(|f| f.id)
            .or_else(|| {
                m.road_lines
                    .iter()
                    .find(|f| !f.polyline.iter().all(finite))
                    .map(|f| f.id)
            })
            .or_else(|| {
                m.road_edges
                    .iter()
                    .find(|f| !f.polyline.iter().all(finite))
                    .map(|f| f.id)
            })
            .or_else(|| {
                m.stop_signs
                    .iter()
                    .find(|f| !finite(&f.position))
                    .map(|f| f.id)
            })
            .or_else(|| {
                m.crosswalks
                    .iter()
                    .find(|f| !f.polygon.iter().all(finite))
                    .map(|f| f.id)
            })
            .or_else(|| {
                m.speed_bumps
                    .iter()
                    .find(|f| !f.polygon.iter().all(finite))
                    .map(|f| f.id)
            })
            .or_else(|| {
                m.driveways
                    .iter()
                    .find(|f| !f.polygon.iter().all(finite))
                    .map(|f| f.id)
            });
        if let Some(feature_id) = bad {
            return Err(SceneError::NonFiniteMapPoint { feature_id });
        }
        Ok(())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn tiny_scene() -> Scene {
        let state = AgentState {
            valid: true,
            length_m: 4.5,
            width_m: 2.0,
            ..Default::default()
        };
        Scene {
            scenario_id: "tiny".into(),
            timestamps_secs: vec![0.0, 0.1, 0.2],
            current_step: 1,
            tracks: vec![Track {
                id: 7,
                object_type: ObjectType::Vehicle,
                states: vec![state; 3],
            }],
            ..Default::default()
        }
    }

    #[test]
    fn valid_scene_passes() {
        tiny_scene().validate().unwrap();
    }

    #[test]
    fn nan_in_valid_state_is_reported_with_field() {
        let mut scene = tiny_scene();
        scene.tracks[0].states[2].x_m = f64::NAN;
        assert_eq!(
            scene.validate(),
            Err(SceneError::NonFiniteState {
                track_id: 7,
                step: 2,
                field: "center_x"
            })
        );
        // An invalid state may hold anything.
        scene.tracks[0].states[2].valid = false;
        scene.validate().unwrap();
    }

    #[test]
    fn bad_lengths_and_indices_are_reported() {
        let mut scene = tiny_scene();
        scene.current_step = 3;
        assert!(matches!(
            scene.validate(),
            Err(SceneError::CurrentStepOutOfRange { .. })
        ));
        let mut scene = tiny_scene();
        scene.tracks[0].states.pop();
        assert!(matches!(
            scene.validate(),
            Err(SceneError::TrackLength { .. })
        ));
        let mut scene = tiny_scene();
        scene.sdc_track_index = Some(1);
        assert!(matches!(
            scene.validate(),
            Err(SceneError::TrackIndexOutOfRange { .. })
        ));
    }

    #[test]
    fn huge_values_duplicate_ids_and_time_out_of_order_are_reported() {
        let mut scene = tiny_scene();
        scene.tracks[0].states[1].velocity_y_mps = 1e30;
        assert_eq!(
            scene.validate(),
            Err(SceneError::NonFiniteState {
                track_id: 7,
                step: 1,
                field: "velocity_y"
            })
        );
        let mut scene = tiny_scene();
        scene.tracks[0].states[0].x_m = -MAX_ABS_VALUE;
        scene.validate().unwrap();
        scene.tracks[0].states[0].x_m = -1e300;
        assert!(scene.validate().is_err());
        let mut scene = tiny_scene();
        scene.tracks.push(scene.tracks[0].clone());
        assert_eq!(
            scene.validate(),
            Err(SceneError::DuplicateTrackId { track_id: 7 })
        );
        let mut scene = tiny_scene();
        scene.timestamps_secs = vec![0.0, 0.2, 0.2];
        let e = scene.validate().unwrap_err();
        assert_eq!(e, SceneError::TimestampOrder { step: 2, secs: 0.2 });
        assert!(e.to_string().contains("step 2"), "{e}");
    }
}
