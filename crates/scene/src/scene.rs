//! The scene value type: tracks, interaction labels, map and signals.

use crate::map::{Map, MapPoint};

/// WOMD `Track.ObjectType`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash, Default)]
pub enum ObjectType {
    #[default]
    Unset = 0,
    Vehicle = 1,
    Pedestrian = 2,
    Cyclist = 3,
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
    pub x_m: f64,
    pub y_m: f64,
    pub z_m: f64,
    pub length_m: f32,
    pub width_m: f32,
    pub height_m: f32,
    pub heading_rad: f32,
    pub velocity_x_mps: f32,
    pub velocity_y_mps: f32,
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
    pub id: i64,
    pub object_type: ObjectType,
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
    #[default]
    None = 0,
    Level1 = 1,
    Level2 = 2,
}

impl PredictionDifficulty {
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
    pub difficulty: PredictionDifficulty,
}

/// WOMD `TrafficSignalLaneState.State`.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default)]
pub enum SignalState {
    #[default]
    Unknown = 0,
    ArrowStop = 1,
    ArrowCaution = 2,
    ArrowGo = 3,
    Stop = 4,
    Caution = 5,
    Go = 6,
    FlashingStop = 7,
    FlashingCaution = 8,
}

impl SignalState {
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
    pub lane_id: i64,
    pub state: SignalState,
    pub stop_point: Option<MapPoint>,
}

/// One traffic scenario: tracks over time, which of them matter, the map and the signals.
#[derive(Debug, Clone, PartialEq, Default)]
pub struct Scene {
    pub scenario_id: String,
    /// One timestamp per step, seconds (10 Hz in WOMD).
    pub timestamps_secs: Vec<f64>,
    /// The "now" step: history is `..=current_step`, future is after it.
    pub current_step: usize,
    /// Index of the self-driving car's track, when known.
    pub sdc_track_index: Option<usize>,
    pub tracks: Vec<Track>,
    /// Track *ids* (not indices) of objects labelled as interacting.
    pub objects_of_interest: Vec<i64>,
    pub tracks_to_predict: Vec<PredictionTarget>,
    pub map: Map,
    /// Signal states per step (`signals_per_step.len() == num_steps` when present, else empty).
    pub signals_per_step: Vec<Vec<SignalLaneState>>,
}

/// A scene that breaks an invariant of [`Scene`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum SceneError {
    #[error("scene has no time steps")]
    NoSteps,
    #[error("current step {current_step} is outside the {num_steps} steps")]
    CurrentStepOutOfRange {
        current_step: usize,
        num_steps: usize,
    },
    #[error("track {track_id} has {got} states but the scene has {num_steps} steps")]
    TrackLength {
        track_id: i64,
        got: usize,
        num_steps: usize,
    },
    #[error("track {track_id} step {step}: field `{field}` is not finite in a valid state")]
    NonFiniteState {
        track_id: i64,
        step: usize,
        field: &'static str,
    },
    #[error("map feature {feature_id}: a point is not finite")]
    NonFiniteMapPoint { feature_id: i64 },
    #[error("timestamp at step {step} is not finite")]
    NonFiniteTimestamp { step: usize },
    #[error("{what} index {index} is outside the {num_tracks} tracks")]
    TrackIndexOutOfRange {
        what: &'static str,
        index: usize,
        num_tracks: usize,
    },
    #[error("signals cover {got} steps but the scene has {num_steps}")]
    SignalLength { got: usize, num_steps: usize },
}

impl Scene {
    pub fn num_steps(&self) -> usize {
        self.timestamps_secs.len()
    }

    /// Index of the track with this id.
    pub fn track_index(&self, id: i64) -> Option<usize> {
        self.tracks.iter().position(|t| t.id == id)
    }

    /// Checks the invariants every consumer relies on: consistent lengths, indices in range,
    /// finite numbers wherever `valid` is set. Readers call this before returning a scene.
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
                    ("center_x", s.x_m.is_finite()),
                    ("center_y", s.y_m.is_finite()),
                    ("center_z", s.z_m.is_finite()),
                    ("length", s.length_m.is_finite()),
                    ("width", s.width_m.is_finite()),
                    ("height", s.height_m.is_finite()),
                    ("heading", s.heading_rad.is_finite()),
                    ("velocity_x", s.velocity_x_mps.is_finite()),
                    ("velocity_y", s.velocity_y_mps.is_finite()),
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
        let finite = |p: &MapPoint| p.x_m.is_finite() && p.y_m.is_finite() && p.z_m.is_finite();
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
}
