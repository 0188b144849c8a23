//! The kinematic model a controlled agent is followed through: a bicycle with bounded
//! acceleration, jerk, steering angle and steering rate, and the plan tracker that commands it.
//!
//! The bicycle (centre-of-mass reference, equal axle distances, wheelbase 0.6 × the box
//! length) integrates at the scene's 10 Hz:
//! `β = atan(tan δ / 2)`, `ẋ = v cos(θ + β)`, `ẏ = v sin(θ + β)`, `θ̇ = v cos β tan δ / L`.
//! Speeds never go negative (no reversing).
//!
//! The tracker follows a time-indexed plan (`plan[k]` is where the agent should be `k + 1`
//! steps after the plan started): longitudinally the plan's acceleration as feed-forward plus
//! a PD on the along-track position and speed errors (`a = a_ref + 3 (v_ref − v) + 2 e_lon`,
//! ω ≈ 1.4 rad/s, damping ≈ 1.06); laterally pure pursuit of the first plan point at least `max(4 m, 0.8 s · v)` ahead.

use scbg_scene::AgentState;
use serde::{Deserialize, Serialize};

/// Seconds per step (10 Hz).
pub const STEP_SECS: f64 = 0.1;

/// Physical limits of a followed agent.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct VehicleLimits {
    /// Maximum acceleration, m/s².
    pub max_accel_mps2: f64,
    /// Maximum braking, m/s² (positive).
    pub max_brake_mps2: f64,
    /// Maximum jerk, m/s³ (bounds the change of acceleration per step).
    pub max_jerk_mps3: f64,
    /// Maximum steering angle, rad.
    pub max_steer_rad: f64,
    /// Maximum steering rate, rad/s.
    pub max_steer_rate_radps: f64,
    /// Maximum speed, m/s.
    pub max_speed_mps: f64,
}

impl Default for VehicleLimits {
    /// The synthetic world's limits (3 m/s² up, 7.5 m/s² down, 25 m/s³) and a passenger car's
    /// steering (±0.6 rad, 1 rad/s).
    fn default() -> Self {
        Self {
            max_accel_mps2: 3.0,
            max_brake_mps2: 7.5,
            max_jerk_mps3: 25.0,
            max_steer_rad: 0.6,
            max_steer_rate_radps: 1.0,
            max_speed_mps: 40.0,
        }
    }
}

/// The state of one followed agent.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Bicycle {
    /// Centre x, world frame, m.
    pub x_m: f64,
    /// Centre y, world frame, m.
    pub y_m: f64,
    /// Heading, rad.
    pub heading_rad: f64,
    /// Speed, m/s (≥ 0).
    pub speed_mps: f64,
    /// Acceleration of the last step, m/s².
    pub accel_mps2: f64,
    /// Steering angle, rad.
    pub steer_rad: f64,
    /// Wheelbase, m.
    pub wheelbase_m: f64,
}

impl Bicycle {
    /// The bicycle at a recorded state; `previous` (the step before) gives the acceleration
    /// and, through the yaw rate, the steering angle.
    pub fn from_state(state: &AgentState, previous: Option<&AgentState>) -> Self {
        let speed = f64::from(state.speed_mps());
        let wheelbase_m = (0.6 * f64::from(state.length_m)).max(1.0);
        let (mut accel, mut steer) = (0.0, 0.0);
        if let Some(p) = previous.filter(|p| p.valid) {
            accel = (speed - f64::from(p.speed_mps())) / STEP_SECS;
            if speed > 1.0 {
                let yaw_rate =
                    scbg_scene::wrap_angle_rad(f64::from(state.heading_rad - p.heading_rad))
                        / STEP_SECS;
                steer = (yaw_rate * wheelbase_m / speed).atan();
            }
        }
        Self {
            x_m: state.x_m,
            y_m: state.y_m,
            heading_rad: f64::from(state.heading_rad),
            speed_mps: speed,
            accel_mps2: accel.clamp(-7.5, 3.0),
            steer_rad: steer.clamp(-0.6, 0.6),
            wheelbase_m,
        }
    }

    /// One step with commanded acceleration and steering angle, within `limits`.
    pub fn step(&mut self, accel_cmd: f64, steer_cmd: f64, limits: &VehicleLimits) {
        let max_da = limits.max_jerk_mps3 * STEP_SECS;
        let a = accel_cmd
            .clamp(-limits.max_brake_mps2, limits.max_accel_mps2)
            .clamp(self.accel_mps2 - max_da, self.accel_mps2 + max_da);
        let max_dd = limits.max_steer_rate_radps * STEP_SECS;
        let steer = steer_cmd
            .clamp(-limits.max_steer_rad, limits.max_steer_rad)
            .clamp(self.steer_rad - max_dd, self.steer_rad + max_dd);
        let v_next = (self.speed_mps + a * STEP_SECS).clamp(0.0, limits.max_speed_mps);
        let v = 0.5 * (self.speed_mps + v_next);
        let beta = (0.5 * steer.tan()).atan();
        self.x_m += v * (self.heading_rad + beta).cos() * STEP_SECS;
        self.y_m += v * (self.heading_rad + beta).sin() * STEP_SECS;
        self.heading_rad = scbg_scene::wrap_angle_rad(
            self.heading_rad + v * beta.cos() * steer.tan() / self.wheelbase_m * STEP_SECS,
        );
        // The acceleration state is the commanded one (within limits), so the jerk bound holds
        // even when the speed stops at zero.
        self.accel_mps2 = a;
        self.speed_mps = v_next;
        self.steer_rad = steer;
    }

    /// The bicycle as a scene state (box and height from `template`).
    pub fn state(&self, template: &AgentState) -> AgentState {
        let (s, c) = self.heading_rad.sin_cos();
        AgentState {
            x_m: self.x_m,
            y_m: self.y_m,
            z_m: template.z_m,
            length_m: template.length_m,
            width_m: template.width_m,
            height_m: template.height_m,
            heading_rad: self.heading_rad as f32,
            velocity_x_mps: (self.speed_mps * c) as f32,
            velocity_y_mps: (self.speed_mps * s) as f32,
            valid: true,
        }
    }

    /// The commands that follow `plan` at its step `k` (`plan[k]` is where the agent should
    /// be after this step; `start` is where the plan started): `(acceleration, steering)`.
    pub fn track(&self, start: [f64; 2], plan: &[[f64; 2]], k: usize) -> (f64, f64) {
        if plan.is_empty() {
            return (-self.speed_mps / STEP_SECS, self.steer_rad);
        }
        let k = k.min(plan.len() - 1);
        let at = |i: usize| if i == 0 { start } else { plan[i - 1] };
        let (sn, cs) = self.heading_rad.sin_cos();
        // Where the plan says the agent is now (point k), and its speed over this step.
        let now = at(k);
        let v_ref = (plan[k][0] - now[0]).hypot(plan[k][1] - now[1]) / STEP_SECS;
        let v_next = plan.get(k + 1).map_or(v_ref, |p| {
            (p[0] - plan[k][0]).hypot(p[1] - plan[k][1]) / STEP_SECS
        });
        let e_lon = (now[0] - self.x_m) * cs + (now[1] - self.y_m) * sn;
        let accel = (v_next - v_ref) / STEP_SECS + 3.0 * (v_ref - self.speed_mps) + 2.0 * e_lon;
        // Pure pursuit.
        let lookahead = (0.8 * self.speed_mps).max(4.0);
        let target = plan[k..]
            .iter()
            .find(|p| (p[0] - self.x_m).hypot(p[1] - self.y_m) >= lookahead)
            .unwrap_or(&plan[plan.len() - 1]);
        let (dx, dy) = (target[0] - self.x_m, target[1] - self.y_m);
        let dist = dx.hypot(dy);
        if dist < 1.0 {
            return (accel, self.steer_rad);
        }
        let alpha = scbg_scene::wrap_angle_rad(dy.atan2(dx) - self.heading_rad);
        let curvature = 2.0 * alpha.sin() / dist;
        (accel, (curvature * self.wheelbase_m).atan())
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn car(x: f64, y: f64, heading: f32, speed: f32) -> AgentState {
        AgentState {
            x_m: x,
            y_m: y,
            length_m: 4.5,
            width_m: 1.9,
            height_m: 1.6,
            heading_rad: heading,
            velocity_x_mps: speed * heading.cos(),
            velocity_y_mps: speed * heading.sin(),
            valid: true,
            ..Default::default()
        }
    }

    #[test]
    fn limits_hold_for_any_command() {
        let limits = VehicleLimits::default();
        let mut b = Bicycle::from_state(&car(0.0, 0.0, 0.0, 10.0), None);
        for (a, d) in [(100.0, 5.0), (-100.0, -5.0), (100.0, 0.0), (-100.0, 5.0)] {
            for _ in 0..20 {
                let before = b;
                b.step(a, d, &limits);
                let da = (b.accel_mps2 - before.accel_mps2).abs();
                assert!(da <= limits.max_jerk_mps3 * STEP_SECS + 1e-9, "jerk {da}");
                assert!(b.accel_mps2 <= limits.max_accel_mps2 + 1e-9);
                assert!(b.accel_mps2 >= -limits.max_brake_mps2 - 1e-9);
                assert!(b.steer_rad.abs() <= limits.max_steer_rad + 1e-12);
                let dd = (b.steer_rad - before.steer_rad).abs();
                assert!(dd <= limits.max_steer_rate_radps * STEP_SECS + 1e-12);
                assert!(b.speed_mps >= 0.0);
            }
        }
    }

    /// A plan along a circle of radius 30 m at 8 m/s is followed to within a few decimetres.
    #[test]
    fn tracks_a_curved_plan() {
        let (r, v) = (30.0, 8.0);
        let pose = |t: f64| {
            let th = v * t / r;
            [r * th.sin(), r * (1.0 - th.cos())]
        };
        let plan: Vec<[f64; 2]> = (1..=80).map(|k| pose(k as f64 * STEP_SECS)).collect();
        let mut b = Bicycle::from_state(&car(0.0, 0.0, 0.0, v as f32), None);
        let limits = VehicleLimits::default();
        let mut worst: f64 = 0.0;
        for k in 0..80 {
            let (a, d) = b.track([0.0, 0.0], &plan, k);
            b.step(a, d, &limits);
            worst = worst.max((b.x_m - plan[k][0]).hypot(b.y_m - plan[k][1]));
        }
        assert!(worst < 0.6, "worst tracking error {worst} m");
    }

    /// A plan that stops is followed to a stop near its end, without reversing.
    #[test]
    fn tracks_a_stop() {
        let plan: Vec<[f64; 2]> = (1..=80)
            .map(|k| {
                let t = (k as f64 * STEP_SECS).min(4.0);
                [10.0 * t - 1.25 * t * t, 0.0]
            })
            .collect();
        let mut b = Bicycle::from_state(&car(0.0, 0.0, 0.0, 10.0), None);
        for k in 0..80 {
            let (a, d) = b.track([0.0, 0.0], &plan, k);
            b.step(a, d, &VehicleLimits::default());
        }
        assert!(b.speed_mps < 0.3, "speed {}", b.speed_mps);
        assert!((b.x_m - 20.0).abs() < 1.0, "stopped at {}", b.x_m);
        assert!(b.y_m.abs() < 0.1);
    }
}
