//! 2-D rigid transforms between the world frame and agent frames.

use std::f64::consts::PI;

/// Wraps an angle to `(-π, π]`.
pub fn wrap_angle_rad(angle_rad: f64) -> f64 {
    // `fmod` returns its argument unchanged when |a| < 2π: skip the (slow) call then. Same bits.
    let mut a = if angle_rad.abs() < 2.0 * PI {
        angle_rad
    } else {
        angle_rad % (2.0 * PI)
    };
    if a <= -PI {
        a += 2.0 * PI;
    } else if a > PI {
        a -= 2.0 * PI;
    }
    a
}

/// A 2-D pose (position and heading) in the world frame.
///
/// `Pose2` doubles as the transform `world_from_agent`: [`Pose2::agent_from_world`] maps a world
/// point into the frame whose origin is the pose's position and whose x axis points along the
/// heading; [`Pose2::world_from_agent`] is its inverse.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Pose2 {
    /// Position x, world frame, metres.
    pub x_m: f64,
    /// Position y, world frame, metres.
    pub y_m: f64,
    /// Heading, radians, world frame (direction of the agent frame's x axis).
    pub heading_rad: f64,
}

impl Pose2 {
    /// A pose from its position (metres) and heading (radians).
    pub fn new(x_m: f64, y_m: f64, heading_rad: f64) -> Self {
        Self {
            x_m,
            y_m,
            heading_rad,
        }
    }

    /// Maps a world-frame point into this pose's frame (translate by −position, rotate by −heading).
    pub fn agent_from_world(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        let (s, c) = self.heading_rad.sin_cos();
        let dx = x_m - self.x_m;
        let dy = y_m - self.y_m;
        (c * dx + s * dy, -s * dx + c * dy)
    }

    /// Rotates a world-frame vector (velocity, direction) into this pose's frame.
    pub fn agent_from_world_vector(&self, vx: f64, vy: f64) -> (f64, f64) {
        let (s, c) = self.heading_rad.sin_cos();
        (c * vx + s * vy, -s * vx + c * vy)
    }

    /// Maps a point in this pose's frame back into the world frame.
    pub fn world_from_agent(&self, x_m: f64, y_m: f64) -> (f64, f64) {
        let (s, c) = self.heading_rad.sin_cos();
        (self.x_m + c * x_m - s * y_m, self.y_m + s * x_m + c * y_m)
    }

    /// Heading of a world-frame heading expressed in this pose's frame, wrapped to `(-π, π]`.
    pub fn agent_from_world_heading(&self, heading_rad: f64) -> f64 {
        wrap_angle_rad(heading_rad - self.heading_rad)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn round_trip_world_agent() {
        let pose = Pose2::new(10.0, -3.0, 0.7);
        let (ax, ay) = pose.agent_from_world(12.5, 4.0);
        let (wx, wy) = pose.world_from_agent(ax, ay);
        assert!((wx - 12.5).abs() < 1e-12 && (wy - 4.0).abs() < 1e-12);
    }

    #[test]
    fn heading_axis_maps_to_x() {
        let pose = Pose2::new(1.0, 1.0, std::f64::consts::FRAC_PI_2);
        let (ax, ay) = pose.agent_from_world(1.0, 3.0);
        assert!((ax - 2.0).abs() < 1e-12 && ay.abs() < 1e-12);
    }

    #[test]
    fn wrap_angle() {
        assert!((wrap_angle_rad(3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle_rad(-3.0 * PI) - PI).abs() < 1e-12);
        assert!((wrap_angle_rad(0.5) - 0.5).abs() < 1e-12);
        assert!((wrap_angle_rad(-PI / 2.0 - 2.0 * PI) + PI / 2.0).abs() < 1e-12);
    }

    #[test]
    fn wrap_angle_fast_path_has_the_same_bits_as_fmod() {
        let reference = |x: f64| {
            let mut a = x % (2.0 * PI);
            if a <= -PI {
                a += 2.0 * PI;
            } else if a > PI {
                a -= 2.0 * PI;
            }
            a
        };
        let mut x = -20.0f64;
        while x < 20.0 {
            for v in [
                x,
                f64::from_bits(x.to_bits() + 1),
                2.0 * PI,
                -2.0 * PI,
                PI,
                -PI,
            ] {
                assert_eq!(wrap_angle_rad(v).to_bits(), reference(v).to_bits(), "{v}");
            }
            x += 0.001_3;
        }
        assert!(wrap_angle_rad(f64::NAN).is_nan());
    }
}
