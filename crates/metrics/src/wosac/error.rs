//! Why a scene or a set of rollouts cannot be scored.

/// Why a scene or a set of rollouts cannot be scored.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum WosacError {
    /// The scene does not have 91 steps with step 10 as the current step.
    #[error(
        "scene {scenario_id}: {num_steps} steps with current step {current_step}; \
         WOSAC needs 91 steps with current step 10"
    )]
    SceneLayout {
        /// The scene's id.
        scenario_id: String,
        /// Number of steps of the scene.
        num_steps: usize,
        /// The scene's current step.
        current_step: usize,
    },
    /// The scene has neither an SDC nor tracks to predict.
    #[allow(missing_docs)]
    #[error("scene {scenario_id}: no evaluated object (no SDC and no tracks to predict)")]
    NoEvaluatedObjects { scenario_id: String },
    /// An evaluated object (SDC or track to predict) is not valid at the current step, so it
    /// is not simulated.
    #[allow(missing_docs)]
    #[error(
        "scene {scenario_id}: evaluated object {object_id} is not valid at step 10 (not a sim agent)"
    )]
    EvaluatedNotSimulated { scenario_id: String, object_id: i64 },
    /// The map has no road-edge polyline with at least two points.
    #[allow(missing_docs)]
    #[error("scene {scenario_id}: no road-edge polyline with at least 2 points")]
    NoRoadEdges { scenario_id: String },
    /// `trajectories` does not hold 32 joint scenes.
    #[allow(missing_docs)]
    #[error("got {got} rollouts; WOSAC needs exactly 32")]
    RolloutCount { got: usize },
    /// A joint scene does not hold one trajectory per entry of `object_ids`.
    #[allow(missing_docs)]
    #[error("rollout {rollout} has {got} trajectories but `object_ids` lists {expected}")]
    TrajectoryCount {
        rollout: usize,
        got: usize,
        expected: usize,
    },
    /// A trajectory does not have 80 steps.
    #[allow(missing_docs)]
    #[error("rollout {rollout}, object {object_id}: {got} steps; WOSAC needs 80")]
    StepCount {
        rollout: usize,
        object_id: i64,
        got: usize,
    },
    /// A simulated value is NaN or infinite.
    #[allow(missing_docs)]
    #[error("rollout {rollout}, object {object_id}, future step {step}: `{field}` is not finite")]
    NonFinite {
        rollout: usize,
        object_id: i64,
        step: usize,
        field: &'static str,
    },
    /// `object_ids` names an object that is not a sim agent of the scene.
    #[allow(missing_docs)]
    #[error(
        "object {object_id} in the rollouts is not a sim agent of the scene (unknown id or not valid at step 10)"
    )]
    UnknownObject { object_id: i64 },
    /// A sim agent of the scene is missing from `object_ids`.
    #[allow(missing_docs)]
    #[error("sim agent {object_id} is missing from the rollouts")]
    MissingObject { object_id: i64 },
    /// `object_ids` names an object twice.
    #[allow(missing_docs)]
    #[error("object {object_id} appears more than once in the rollouts")]
    DuplicateObject { object_id: i64 },
}

impl WosacError {
    /// A short, stable description of the kind of problem, without ids or counts, for skip
    /// counters in summaries.
    pub fn reason(&self) -> &'static str {
        match self {
            Self::SceneLayout { .. } => "not 91 steps with current step 10",
            Self::NoEvaluatedObjects { .. } => "no evaluated object (no SDC, no track to predict)",
            Self::EvaluatedNotSimulated { .. } => {
                "an evaluated object (SDC or track to predict) is not valid at the current step"
            }
            Self::NoRoadEdges { .. } => "no road edge in the map",
            Self::RolloutCount { .. } => "not 32 rollouts",
            Self::TrajectoryCount { .. } | Self::StepCount { .. } => "rollouts of the wrong shape",
            Self::NonFinite { .. } => "a simulated value is not finite",
            Self::UnknownObject { .. }
            | Self::MissingObject { .. }
            | Self::DuplicateObject { .. } => "rollouts that do not list every sim agent once",
        }
    }
}
