//! The challenge definitions and the scores of one scenario and of a data set.

use serde::Serialize;

/// Which challenge definition to score with.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize)]
pub enum WosacConfig {
    /// The 2025 challenge: traffic-light term (weight 0.05), road-edge distance weight 0.05,
    /// time to collision scored on vehicles only.
    #[default]
    V2025,
    /// The 2024 challenge: no traffic-light term (weight 0), road-edge distance weight 0.10,
    /// time to collision scored on every evaluated object. The traffic-light likelihood and
    /// rate are still computed and reported, but do not enter any score.
    V2024,
}

impl WosacConfig {
    /// Meta-metric weights, in the order of [`FeatureLikelihoods::to_array`]; they sum to 1.
    pub fn weights(self) -> [f32; 10] {
        let (road_edge, traffic_light) = match self {
            Self::V2025 => (0.05, 0.05),
            Self::V2024 => (0.10, 0.0),
        };
        [
            0.05,
            0.05,
            0.05,
            0.05,
            0.10,
            0.25,
            0.10,
            road_edge,
            0.25,
            traffic_light,
        ]
    }

    /// Whether time to collision is scored on vehicles only (2025) or on every evaluated
    /// object (2024).
    pub fn time_to_collision_vehicles_only(self) -> bool {
        matches!(self, Self::V2025)
    }
}

/// The ten per-feature likelihoods (each in `[0, 1]`; NaN when no step of any evaluated object
/// is valid in the log, as in the official code).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct FeatureLikelihoods {
    /// Linear speed (kinematic).
    pub linear_speed: f32,
    /// Linear acceleration (kinematic).
    pub linear_acceleration: f32,
    /// Angular speed (kinematic).
    pub angular_speed: f32,
    /// Angular acceleration (kinematic).
    pub angular_acceleration: f32,
    /// Signed distance to the nearest object (interactive).
    pub distance_to_nearest_object: f32,
    /// Collision indication (interactive).
    pub collision_indication: f32,
    /// Time to collision with the object in front (interactive).
    pub time_to_collision: f32,
    /// Signed distance to the road edge (map-based).
    pub distance_to_road_edge: f32,
    /// Off-road indication (map-based).
    pub offroad_indication: f32,
    /// Traffic-light violation indication (map-based; weight 0 in [`WosacConfig::V2024`]).
    pub traffic_light_violation: f32,
}

impl FeatureLikelihoods {
    /// The likelihoods in the fixed feature order (the order of the fields and of
    /// [`WosacConfig::weights`]).
    pub fn to_array(&self) -> [f32; 10] {
        [
            self.linear_speed,
            self.linear_acceleration,
            self.angular_speed,
            self.angular_acceleration,
            self.distance_to_nearest_object,
            self.collision_indication,
            self.time_to_collision,
            self.distance_to_road_edge,
            self.offroad_indication,
            self.traffic_light_violation,
        ]
    }

    /// The inverse of [`FeatureLikelihoods::to_array`].
    pub fn from_array(a: [f32; 10]) -> Self {
        Self {
            linear_speed: a[0],
            linear_acceleration: a[1],
            angular_speed: a[2],
            angular_acceleration: a[3],
            distance_to_nearest_object: a[4],
            collision_indication: a[5],
            time_to_collision: a[6],
            distance_to_road_edge: a[7],
            offroad_indication: a[8],
            traffic_light_violation: a[9],
        }
    }

    /// The meta-metric `Σ w_k · L_k` (features with weight 0 are left out, so a NaN there
    /// does not propagate).
    pub fn metametric(&self, config: WosacConfig) -> f32 {
        self.to_array()
            .iter()
            .zip(config.weights())
            .filter(|(_, w)| *w != 0.0)
            .fold(0.0, |acc, (l, w)| acc + w * l)
    }

    /// The three bucket scores `Σ w_k L_k / Σ w_k` within each bucket.
    pub fn buckets(&self, config: WosacConfig) -> BucketScores {
        let l = self.to_array();
        let w = config.weights();
        let bucket = |range: std::ops::Range<usize>| {
            let (mut num, mut den) = (0.0f32, 0.0f32);
            for k in range {
                if w[k] != 0.0 {
                    num += w[k] * l[k];
                    den += w[k];
                }
            }
            num / den
        };
        BucketScores {
            kinematic: bucket(0..4),
            interactive: bucket(4..7),
            map_based: bucket(7..10),
        }
    }
}

/// The weighted bucket scores of the meta-metric (§8 of the spec).
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize)]
pub struct BucketScores {
    /// Speeds and accelerations, linear and angular.
    pub kinematic: f32,
    /// Nearest-object distance, collision, time to collision.
    pub interactive: f32,
    /// Road-edge distance, off-road, traffic-light violation.
    pub map_based: f32,
}

/// Every WOSAC number for one scenario.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScenarioMetrics {
    /// The scene's scenario id.
    pub scenario_id: String,
    /// The realism meta-metric `Σ w_k L_k`.
    pub metametric: f32,
    /// Bucket scores (kinematic, interactive, map-based).
    pub buckets: BucketScores,
    /// Per-feature likelihoods.
    pub likelihoods: FeatureLikelihoods,
    /// Mean over rollouts and evaluated objects of the average displacement error, metres.
    pub average_displacement_error_m: f32,
    /// Minimum over rollouts of the mean (over evaluated objects) displacement error, metres.
    pub min_average_displacement_error_m: f32,
    /// Fraction of (rollout, evaluated object) pairs that collide at a log-valid future step.
    pub simulated_collision_rate: f32,
    /// Fraction of (rollout, evaluated object) pairs that go off-road at a log-valid future step.
    pub simulated_offroad_rate: f32,
    /// Fraction of (rollout, evaluated object) pairs that run a red light at a log-valid future
    /// step (no vehicle filter).
    pub simulated_traffic_light_violation_rate: f32,
}

/// Dataset-level WOSAC numbers: every per-scenario field averaged with equal weight, buckets
/// recomputed from the averaged likelihoods.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct DatasetMetrics {
    /// Number of scenarios averaged.
    pub num_scenarios: usize,
    /// Mean meta-metric.
    pub metametric: f32,
    /// Buckets of the mean likelihoods.
    pub buckets: BucketScores,
    /// Mean per-feature likelihoods.
    pub likelihoods: FeatureLikelihoods,
    /// Mean average displacement error, metres.
    pub average_displacement_error_m: f32,
    /// Mean minADE, metres.
    pub min_average_displacement_error_m: f32,
    /// Mean simulated collision rate.
    pub simulated_collision_rate: f32,
    /// Mean simulated off-road rate.
    pub simulated_offroad_rate: f32,
    /// Mean simulated traffic-light violation rate.
    pub simulated_traffic_light_violation_rate: f32,
}
