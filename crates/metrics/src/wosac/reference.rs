//! The official values of the specification's reference scenario (`shared/spec/wosac.md` §11):
//! the genuine WOMD scenario `637f20cafde22ff8` (`womd/motion_data_one_scenario.tfrecord` of
//! the shared real data), scored by Waymo's evaluation code (2025 definition) for two
//! baselines. Every front end that scores rollouts checks itself against them.

/// Id of the reference scenario.
pub const SCENARIO_ID: &str = "637f20cafde22ff8";

/// The official numbers of one baseline on the reference scenario.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Reference {
    /// The realism meta-metric.
    pub metametric: f32,
    /// The ten likelihoods in [`super::FeatureLikelihoods::to_array`] order.
    pub likelihoods: [f32; 10],
    /// Average displacement error and minADE (equal: the 32 rollouts are identical), metres.
    pub ade_m: f32,
    /// Simulated collision rate.
    pub collision_rate: f32,
    /// Simulated off-road rate.
    pub offroad_rate: f32,
}

/// Log replay ([`super::log_replay_rollouts`]).
pub const LOG_REPLAY: Reference = Reference {
    metametric: 0.8266314,
    likelihoods: [
        0.82652855, 0.5305248, 0.48732617, 0.6562856, 0.40035117, 0.99996877, 0.8362134, 0.5591777,
        0.99996877, 0.99996877,
    ],
    ade_m: 0.0,
    collision_rate: 0.25,
    offroad_rate: 0.0,
};

/// Constant velocity ([`super::constant_velocity_rollouts`]).
pub const CONSTANT_VELOCITY: Reference = Reference {
    metametric: 0.21769527,
    likelihoods: [
        0.075650506,
        0.12974364,
        0.061595537,
        0.3092796,
        0.26297095,
        0.07476451,
        0.64172214,
        0.22063595,
        0.0747645,
        0.99996877,
    ],
    ade_m: 2.1528234,
    collision_rate: 0.5,
    offroad_rate: 0.25,
};

/// The JSON names of the ten likelihoods (the fields of [`super::FeatureLikelihoods`]), in
/// [`super::FeatureLikelihoods::to_array`] order.
pub const LIKELIHOOD_NAMES: [&str; 10] = [
    "linear_speed",
    "linear_acceleration",
    "angular_speed",
    "angular_acceleration",
    "distance_to_nearest_object",
    "collision_indication",
    "time_to_collision",
    "distance_to_road_edge",
    "offroad_indication",
    "traffic_light_violation",
];

impl Reference {
    /// Each number beside its official value: (name, value, official), the meta-metric first,
    /// then the likelihoods, ADE, minADE and the two rates.
    pub fn compare(&self, m: &super::ScenarioMetrics) -> Vec<(&'static str, f32, f32)> {
        let mut rows = vec![("metametric", m.metametric, self.metametric)];
        let l = m.likelihoods.to_array();
        for (k, name) in LIKELIHOOD_NAMES.iter().enumerate() {
            rows.push((name, l[k], self.likelihoods[k]));
        }
        rows.extend([
            (
                "average_displacement_error",
                m.average_displacement_error_m,
                self.ade_m,
            ),
            (
                "min_average_displacement_error",
                m.min_average_displacement_error_m,
                self.ade_m,
            ),
            (
                "simulated_collision_rate",
                m.simulated_collision_rate,
                self.collision_rate,
            ),
            (
                "simulated_offroad_rate",
                m.simulated_offroad_rate,
                self.offroad_rate,
            ),
        ]);
        rows
    }
}
