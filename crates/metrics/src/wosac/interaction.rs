//! Time to collision with the object in front (§5 of the spec).

use super::LARGE_DISTANCE_M;

/// Longest reported time to collision, seconds.
pub(crate) const MAX_TIME_TO_COLLISION_S: f32 = 5.0;

/// What the time to collision needs of one object at one step.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub(crate) struct TtcBox {
    pub x_m: f32,
    pub y_m: f32,
    pub length_m: f32,
    pub width_m: f32,
    pub heading_rad: f32,
    /// 2-D speed (NaN at the ends of the series).
    pub speed_mps: f32,
    pub valid: bool,
}

/// Time to collision of `boxes[ego]` with the nearest valid object in front of it, in
/// `[0, 5]` seconds (5 when there is none or it is not slower). The ego's own validity is not
/// checked; the heading difference is the absolute difference, *not* wrapped (official quirk).
pub(crate) fn time_to_collision(ego: usize, boxes: &[TtcBox]) -> f32 {
    let max_heading_diff = 75f64.to_radians() as f32;
    let max_heading_diff_small_overlap = 10f64.to_radians() as f32;
    let small_overlap_m = 0.5f32;
    let e = boxes[ego];
    let (sin_e, cos_e) = (-e.heading_rad).sin_cos();
    let mut best = f32::INFINITY;
    let mut best_index = usize::MAX;
    for (o, b) in boxes.iter().enumerate() {
        let yaw_diff = (b.heading_rad - e.heading_rad).abs();
        let (sin_d, cos_d) = yaw_diff.sin_cos();
        let lon_offset = b.length_m / 2.0 * cos_d.abs() + b.width_m / 2.0 * sin_d.abs();
        let lat_offset = b.length_m / 2.0 * sin_d.abs() + b.width_m / 2.0 * cos_d.abs();
        let (rx, ry) = (b.x_m - e.x_m, b.y_m - e.y_m);
        // (p_o − p_e) rotated by −ψ_e.
        let dx = cos_e * rx - sin_e * ry;
        let dy = sin_e * rx + cos_e * ry;
        let lon = dx - e.length_m / 2.0 - lon_offset;
        let lat = dy.abs() - e.width_m / 2.0 - lat_offset;
        let in_front = lon > 0.0
            && yaw_diff <= max_heading_diff
            && lat < 0.0
            && (lat < -small_overlap_m || yaw_diff <= max_heading_diff_small_overlap);
        let masked = if b.valid && in_front {
            lon
        } else {
            lon + LARGE_DISTANCE_M
        };
        if best_index == usize::MAX || masked < best {
            best = masked;
            best_index = o;
        }
    }
    let Some(ahead) = boxes.get(best_index) else {
        return MAX_TIME_TO_COLLISION_S;
    };
    let relative_speed = e.speed_mps - ahead.speed_mps;
    if relative_speed > 0.0 {
        (best / relative_speed).min(MAX_TIME_TO_COLLISION_S)
    } else {
        MAX_TIME_TO_COLLISION_S
    }
}
