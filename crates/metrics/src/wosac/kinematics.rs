//! Kinematic features from central differences (§5 of the spec).

use std::f32::consts::PI;

/// `wrap(θ) = ((θ + π) mod 2π) − π` with floor modulo (float32), result in `[−π, π)`.
pub(crate) fn wrap_angle(angle_rad: f32) -> f32 {
    let two_pi = 2.0 * PI;
    let mut r = (angle_rad + PI) % two_pi;
    // `%` truncates; floor modulo takes the divisor's sign.
    if r != 0.0 && r < 0.0 {
        r += two_pi;
    }
    r - PI
}

/// `D(a)[t] = (a[t+1] − a[t−1]) / 2` for interior steps, NaN at both ends.
pub(crate) fn central_difference(a: &[f32]) -> Vec<f32> {
    let n = a.len();
    (0..n)
        .map(|t| {
            if t == 0 || t + 1 >= n {
                f32::NAN
            } else {
                (a[t + 1] - a[t - 1]) / 2.0
            }
        })
        .collect()
}

/// The four kinematic series of one object, one value per step (NaN where the differences
/// reach past the series).
#[derive(Debug, Clone)]
pub(crate) struct Kinematics {
    /// 3-D speed, m/s (NaN at the first and last step).
    pub speed_mps: Vec<f32>,
    /// Signed change of speed, m/s² (NaN at the first two and last two steps).
    pub acceleration_mps2: Vec<f32>,
    /// Angular speed, rad/s.
    pub angular_speed_radps: Vec<f32>,
    /// Angular acceleration, rad/s².
    pub angular_acceleration_radps2: Vec<f32>,
}

/// Linear speed `|D(x), D(y), D(z)| / dt` (`z = None`: 2-D).
fn speed(x: &[f32], y: &[f32], z: Option<&[f32]>, dt_s: f32) -> Vec<f32> {
    let dx = central_difference(x);
    let dy = central_difference(y);
    let dz = z.map(central_difference);
    (0..x.len())
        .map(|t| {
            let dz2 = dz.as_ref().map_or(0.0, |d| d[t] * d[t]);
            (dx[t] * dx[t] + dy[t] * dy[t] + dz2).sqrt() / dt_s
        })
        .collect()
}

/// 2-D speed (z taken as 0), m/s, as the time to collision uses it.
pub(crate) fn speed_2d(x: &[f32], y: &[f32], dt_s: f64) -> Vec<f32> {
    speed(x, y, None, dt_s as f32)
}

/// Speed, acceleration, angular speed and angular acceleration of one object's series.
pub(crate) fn kinematic_features(
    x: &[f32],
    y: &[f32],
    z: &[f32],
    heading_rad: &[f32],
    dt_s: f64,
) -> Kinematics {
    // The official code divides float32 tensors by Python doubles: dt is cast to float32, and
    // dt² is squared in double precision, then cast.
    let dt2_s2 = (dt_s * dt_s) as f32;
    let dt_s = dt_s as f32;
    let speed_mps = speed(x, y, Some(z), dt_s);
    let acceleration_mps2 = central_difference(&speed_mps)
        .into_iter()
        .map(|d| d / dt_s)
        .collect();
    // The official code wraps twice the central difference, then halves it again.
    let wrapped_half = |a: &[f32]| -> Vec<f32> {
        central_difference(a)
            .into_iter()
            .map(|d| wrap_angle(d * 2.0) / 2.0)
            .collect()
    };
    let heading_step = wrapped_half(heading_rad);
    let heading_step2 = wrapped_half(&heading_step);
    Kinematics {
        speed_mps,
        acceleration_mps2,
        angular_speed_radps: heading_step.iter().map(|w| w / dt_s).collect(),
        angular_acceleration_radps2: heading_step2.iter().map(|a| a / dt2_s2).collect(),
    }
}
