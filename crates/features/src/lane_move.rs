//! Completed lane moves: a future of an agent that drifts off its lane path, moved a full
//! lane over along that path (the courteous lane change done at once and fully). Plain
//! geometry on points in the agent's frame; the labels add such futures to B's sampled ones
//! and the generator to its choices.

use crate::AgentSample;

/// How far a completed lane move ends from B's offset at the current step, metres: about a
/// lane's width (3.4–3.8 m in the synthetic world, 3.7 m on a US freeway).
pub const LANE_MOVE_M: f32 = 3.5;

/// A mode leaves B's lane when its offset from B's lane path at the horizon differs from B's
/// at the current step by at least this much, metres.
const LANE_LEAVING_M: f32 = 1.0;

/// A mode whose offset at the horizon differs by more than this, metres, has turned off B's
/// lane path (at a junction, onto another road) rather than changed lanes: no lane move.
const LANE_MOVE_MAX_DRIFT_M: f32 = 5.0;

/// A sample's lane path with the lanes beside it: what a lane move follows, and where it
/// may end.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct LanePath {
    /// The valid points of [`AgentSample::lane_path_xy_m`], in the sample's frame.
    pub points: Vec<[f32; 2]>,
    /// Per point: whether a lane runs beside it, `[left, right]`
    /// ([`AgentSample::lane_path_beside`]).
    pub beside: Vec<[bool; 2]>,
}

/// The valid points of a sample's lane path ([`AgentSample::lane_path_xy_m`]) and the lanes
/// beside them, in its frame; empty when it has none.
pub fn sample_lane_path(sample: &AgentSample) -> LanePath {
    let beside = |k: usize| sample.lane_path_beside.get(k).copied().unwrap_or_default();
    let (points, beside) = sample
        .lane_path_xy_m
        .chunks_exact(2)
        .zip(&sample.lane_path_valid)
        .enumerate()
        .filter(|(_, (_, valid))| **valid)
        .map(|(k, (p, _))| ([p[0], p[1]], beside(k)))
        .unzip();
    LanePath { points, beside }
}

/// A mode that leaves its lane, with the move completed: each step keeps the mode's progress
/// along the lane path `path` (arc length of its projection), and its offset from the path
/// eases (half a cosine) from B's offset at the current step to [`LANE_MOVE_M`] beyond it, on
/// the side the mode drifts to (or the mode's own offset at the horizon if that is further),
/// within `steps` steps. The courteous lane change — moving over for a faster A, or out of
/// its way — done at once and fully; a predictor's mode mean, an average of moves at many
/// moments, often ends half a lane over, where A still has B ahead. The
/// offset is taken from the path, not from B's frame, so the copy follows the road's
/// curvature. `None` when the mode keeps its lane (drifts less than 1 m), turns off it
/// (drifts more than 5 m: a turn at a junction is not a lane change), `path` has fewer than
/// two points, or no lane runs beside the path on the mode's side from where the move is half
/// done to the mode's last point (it would end on a gore, a shoulder or the verge, or on a lane
/// that ends within the horizon, an acceleration lane or a lane drop, which the copy would
/// leave off the road). After that the copy keeps its offset from the path, as a driver keeps
/// to the lane it changed into.
///
/// `mode`: `[T]` positions in B's frame; `lane`: the lane path in the same frame.
pub fn lane_move(mode: &[[f32; 2]], lane: &LanePath, steps: usize) -> Option<Vec<[f32; 2]>> {
    let path = &lane.points;
    if path.len() < 2 || mode.is_empty() {
        return None;
    }
    // Per segment: start, unit tangent, length, and arc length at its start.
    let mut segments = Vec::with_capacity(path.len() - 1);
    let mut arc = 0.0f32;
    for w in path.windows(2) {
        let d = [w[1][0] - w[0][0], w[1][1] - w[0][1]];
        let len = d[0].hypot(d[1]).max(1e-6);
        segments.push((w[0], [d[0] / len, d[1] / len], len, arc));
        arc += len;
    }
    let last = segments.len() - 1;
    // (arc length, signed offset, left positive) of a point's projection on the path; the
    // first and last segments extend beyond the path's ends.
    let project = |p: [f32; 2]| {
        let mut best = (f32::INFINITY, 0.0f32, 0.0f32);
        for (i, &(a, t, len, s0)) in segments.iter().enumerate() {
            let v = [p[0] - a[0], p[1] - a[1]];
            let lo = if i == 0 { f32::NEG_INFINITY } else { 0.0 };
            let hi = if i == last { f32::INFINITY } else { len };
            let u = (v[0] * t[0] + v[1] * t[1]).clamp(lo, hi);
            let dist = (v[0] - u * t[0]).hypot(v[1] - u * t[1]);
            if dist < best.0 {
                best = (dist, s0 + u, t[0] * v[1] - t[1] * v[0]);
            }
        }
        (best.1, best.2)
    };
    // The segment holding arc length `s` (the first or last beyond the path's ends).
    let segment_at = |s: f32| {
        segments
            .iter()
            .position(|seg| s < seg.3 + seg.2)
            .unwrap_or(last)
    };
    let place = |s: f32, offset: f32| {
        let (a, t, _, s0) = segments[segment_at(s)];
        let u = s - s0;
        [
            a[0] + u * t[0] - offset * t[1],
            a[1] + u * t[1] + offset * t[0],
        ]
    };
    // Whether the mode leaves its lane, from its last point alone (most keep their lane: the
    // labels ask this of every sampled future of B, and sample and rank at every plan).
    let (_, start) = project([0.0, 0.0]);
    let drift = project(*mode.last()?).1 - start;
    if !(LANE_LEAVING_M..=LANE_MOVE_MAX_DRIFT_M).contains(&drift.abs()) {
        return None;
    }
    let along: Vec<(f32, f32)> = mode.iter().map(|&p| project(p)).collect();
    let side = usize::from(drift < 0.0);
    let steps = steps.max(1);
    // The path point nearest arc length `s`, and whether a lane runs beside it on that side.
    let lane_beside = |s: f32| {
        let i = segment_at(s);
        let (_, _, len, s0) = segments[i];
        let k = if s - s0 < 0.5 * len { i } else { i + 1 };
        lane.beside.get(k).is_some_and(|b| b[side])
    };
    let done = steps.min(along.len());
    if !along[(steps / 2).min(done - 1)..]
        .iter()
        .all(|&(s, _)| lane_beside(s))
    {
        return None;
    }
    let end = start + drift.signum() * drift.abs().max(LANE_MOVE_M);
    let steps = steps as f32;
    Some(
        along
            .iter()
            .enumerate()
            .map(|(i, &(s, _))| {
                let u = ((i + 1) as f32 / steps).min(1.0);
                let w = 0.5 * (1.0 - (std::f32::consts::PI * u).cos());
                place(s, start + (end - start) * w)
            })
            .collect(),
    )
}

/// What a lane move may ask of a follower in its new lane ([`leaves_room`]): to brake at most
/// `braking_mps2` after `reaction_s`.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
pub struct FollowerRoom {
    /// The hardest braking asked of the follower, m/s².
    pub braking_mps2: f32,
    /// The follower's reaction time before it brakes, seconds.
    pub reaction_s: f32,
}

impl FollowerRoom {
    /// MOBIL's safe deceleration (Kesting, Treiber and Helbing 2007), 4 m/s² after 1 s: a
    /// polite driver's limit, and the check of every serialised label config without the
    /// field: it drops the boldest cut-ins, which are the discourteous end of what B does.
    pub const MOBIL_SAFE: Self = Self {
        braking_mps2: 4.0,
        reaction_s: 1.0,
    };

    /// Hard braking, 7 m/s² after 0.5 s: the most a cut-in of the least courteous driver asks
    /// of the follower. It is the synthetic world's own least courteous B
    /// (`scbg_synth::LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2`, `CUT_IN_REACTION_S`; a test of the
    /// application library keeps the two equal) and the closed loop's gap acceptance, so a
    /// move it keeps is one a real (if rude) driver makes; what it drops is a crash.
    pub const HARD_BRAKING: Self = Self {
        braking_mps2: 7.0,
        reaction_s: 0.5,
    };

    /// The room itself if it is one: a finite braking above 0 and a finite reaction time of at
    /// least 0; otherwise what is wrong.
    pub fn checked(self) -> Result<Self, String> {
        if !(self.braking_mps2.is_finite() && self.braking_mps2 > 0.0) {
            return Err(format!(
                "braking_mps2 {}: expected a finite number of m/s² above 0",
                self.braking_mps2
            ));
        }
        if !(self.reaction_s.is_finite() && self.reaction_s >= 0.0) {
            return Err(format!(
                "reaction_s {}: expected a finite number of seconds >= 0",
                self.reaction_s
            ));
        }
        Ok(self)
    }
}

/// A move has entered another vehicle's lane when their centres are less than this apart
/// sideways: two boxes about 2 m wide are then less than half a metre apart, and one passing
/// the other touches it at the slightest swerve.
const SAME_LANE_M: f32 = 2.5;

/// Centre to centre, bumper to bumper is zero at about a car's length, metres.
const CAR_LENGTH_M: f32 = 5.0;

/// Whether a future `mine` (positions at 0.1 s steps from step 1, in a frame whose origin is
/// the current position) leaves room to another vehicle at `other_xy` driving at constant
/// velocity `other_velocity_mps` (same frame) when it enters that vehicle's lane: at the first
/// step it moves from outside the other's lane into it, it must not be beside it (within a
/// car's length), and if it is ahead, the other must be able to stay behind by braking at
/// most `room.braking_mps2` after `room.reaction_s` (from the closing speed Δv it needs
/// `Δv · t_r + Δv² / 2b` of gap). MOBIL's safety criterion at the moment of the lane
/// change, asked of a completed lane move toward the one vehicle the labels know (A): a move
/// that cuts in slowly just ahead of a fast A is not a driver's choice but a crash. What
/// happens after the move is the follower's to handle; a future that never enters the other's
/// lane (or is in it already at the current step) always leaves room.
pub fn leaves_room(
    mine: &[[f32; 2]],
    other_xy: [f32; 2],
    other_velocity_mps: [f32; 2],
    room: FollowerRoom,
) -> bool {
    const STEP_S: f32 = 0.1;
    let speed = other_velocity_mps[0].hypot(other_velocity_mps[1]);
    // A standing vehicle's heading is unknown here: take the frame's x axis.
    let u = if speed > 0.5 {
        [other_velocity_mps[0] / speed, other_velocity_mps[1] / speed]
    } else {
        [1.0, 0.0]
    };
    // (along, beside) of my position `p` relative to the other at time `t`.
    let relative = |p: [f32; 2], t: f32| {
        let d = [
            p[0] - other_xy[0] - other_velocity_mps[0] * t,
            p[1] - other_xy[1] - other_velocity_mps[1] * t,
        ];
        (d[0] * u[0] + d[1] * u[1], (u[0] * d[1] - u[1] * d[0]).abs())
    };
    let mut previous = [0.0f32, 0.0];
    let mut in_lane = relative(previous, 0.0).1 < SAME_LANE_M;
    for (i, &p) in mine.iter().enumerate() {
        let (along, beside) = relative(p, (i + 1) as f32 * STEP_S);
        let my_speed = ((p[0] - previous[0]) * u[0] + (p[1] - previous[1]) * u[1]) / STEP_S;
        previous = p;
        let entering = !in_lane && beside < SAME_LANE_M;
        in_lane = beside < SAME_LANE_M;
        if !entering {
            continue;
        }
        if along.abs() < CAR_LENGTH_M {
            return false;
        }
        if along > 0.0 && speed > my_speed {
            let closing = speed - my_speed;
            let needed = closing * room.reaction_s + closing * closing / (2.0 * room.braking_mps2);
            if along - CAR_LENGTH_M < needed {
                return false;
            }
        }
        // Entered with room: what follows is the follower's to handle.
        return true;
    }
    true
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A lane path curving left at 1/200 m⁻¹ (points every 5 m from 20 m behind), and the
    /// point `offset` metres left of it at arc length `s`.
    fn curved_lane() -> (LanePath, impl Fn(f32, f32) -> [f32; 2]) {
        let kappa = 1.0f32 / 200.0;
        let at = move |s: f32, offset: f32| {
            let (r, a) = (1.0 / kappa - offset, s * kappa);
            [r * a.sin(), 1.0 / kappa - r * a.cos()]
        };
        let path = LanePath {
            points: (0..80).map(|k| at(k as f32 * 5.0 - 20.0, 0.0)).collect(),
            beside: vec![[true, true]; 80],
        };
        (path, at)
    }

    /// A lane move just ahead of a faster follower in its new lane leaves it no room; the same
    /// move far enough ahead, or with the follower slower, does. Hard braking leaves room to
    /// a bolder cut-in than MOBIL's safe deceleration.
    #[test]
    fn a_lane_move_must_leave_the_follower_room() {
        // Mine: 10 m/s along x, moving 3.5 m left over 3 s (into the follower's lane).
        let mine: Vec<[f32; 2]> = (1..=80)
            .map(|i| {
                let u = (i as f32 / 30.0).min(1.0);
                let w = 0.5 * (1.0 - (std::f32::consts::PI * u).cos());
                [i as f32, LANE_MOVE_M * w]
            })
            .collect();
        for room in [FollowerRoom::MOBIL_SAFE, FollowerRoom::HARD_BRAKING] {
            let leaves = |xy, v| leaves_room(&mine, xy, v, room);
            // A follower in the left lane 40 m behind at 25 m/s: when the move enters its
            // lane (1.1 s, 2.5 m beside it) the gap is 18.5 m, and closing at 15 m/s it needs
            // 43 m (MOBIL) or 23.6 m (hard braking).
            assert!(!leaves([-40.0, LANE_MOVE_M], [25.0, 0.0]));
            // 150 m behind at 25 m/s: it has time.
            assert!(leaves([-150.0, LANE_MOVE_M], [25.0, 0.0]));
            // 15 m behind at 10 m/s: no closing speed, and 15 m apart.
            assert!(leaves([-15.0, LANE_MOVE_M], [10.0, 0.0]));
            // Alongside at my speed: the move runs into it.
            assert!(!leaves([0.0, LANE_MOVE_M], [10.0, 0.0]));
            // In the lane to the right, whatever it does, it is not in my way.
            assert!(leaves([-15.0, -LANE_MOVE_M], [25.0, 0.0]));
            // Leaving the follower's lane (starting in it, 10 m ahead) is no entry.
            let leaving: Vec<[f32; 2]> = mine.iter().map(|p| [p[0], -p[1]]).collect();
            assert!(leaves_room(&leaving, [-10.0, 0.0], [25.0, 0.0], room));
        }
        // 50 m behind at 25 m/s: a 28.5 m gap, room for a follower that brakes hard, not for
        // MOBIL's polite one.
        let follower = ([-50.0, LANE_MOVE_M], [25.0, 0.0]);
        assert!(!leaves_room(
            &mine,
            follower.0,
            follower.1,
            FollowerRoom::MOBIL_SAFE
        ));
        assert!(leaves_room(
            &mine,
            follower.0,
            follower.1,
            FollowerRoom::HARD_BRAKING
        ));
        // A room that is none is named.
        assert!(FollowerRoom::HARD_BRAKING.checked().is_ok());
        let no_braking = FollowerRoom {
            braking_mps2: 0.0,
            ..FollowerRoom::HARD_BRAKING
        };
        assert!(no_braking.checked().unwrap_err().contains("braking_mps2 0"));
        let no_time = FollowerRoom {
            reaction_s: f32::NAN,
            ..FollowerRoom::HARD_BRAKING
        };
        assert!(no_time.checked().unwrap_err().contains("reaction_s NaN"));
    }

    /// A mode that drifts 1.5 m right along a curved lane comes out of `lane_move` a full
    /// lane over within the given steps, on the lane's curve, at the mode's own progress;
    /// a mode that keeps its lane, or a missing path, gives none.
    #[test]
    fn a_lane_move_completes_the_drift_along_the_lanes_curve() {
        let (path, at) = curved_lane();
        let progress = |t: usize| 2.0 * (t + 1) as f32;
        let drifting: Vec<[f32; 2]> = (0..80)
            .map(|t| at(progress(t), -1.5 * ((t + 1) as f32 / 40.0).min(1.0)))
            .collect();
        let moved = lane_move(&drifting, &path, 30).expect("the mode leaves its lane");
        assert_eq!(moved.len(), 80);
        for (t, p) in moved.iter().enumerate() {
            let u = ((t + 1) as f32 / 30.0).min(1.0);
            let offset = -LANE_MOVE_M * 0.5 * (1.0 - (std::f32::consts::PI * u).cos());
            let want = at(progress(t), offset);
            let err = (p[0] - want[0]).hypot(p[1] - want[1]);
            // The path is a polyline of 5 m chords: within its sagitta of the arc.
            assert!(err < 0.05, "step {t}: {p:?} against {want:?}");
        }
        // On the curve 3.5 m right of the lane at the horizon, far from B's frame's
        // straight line (the lane has turned by 0.8 rad there).
        assert!(moved[79][1] > 20.0, "{:?}", moved[79]);
        let keeping: Vec<[f32; 2]> = (0..80).map(|t| at(progress(t), 0.3)).collect();
        assert_eq!(lane_move(&keeping, &path, 30), None);
        let turning: Vec<[f32; 2]> = (0..80).map(|t| at(progress(t), -0.2 * t as f32)).collect();
        assert_eq!(lane_move(&turning, &path, 30), None);
        let one_point = LanePath {
            points: path.points[..1].to_vec(),
            beside: path.beside[..1].to_vec(),
        };
        assert_eq!(lane_move(&drifting, &one_point, 30), None);
    }

    /// A move ends on a lane: none toward a side without one, none where the lane beside ends
    /// within the horizon, and one where the lane beside starts before it is half done.
    #[test]
    fn a_lane_move_needs_a_lane_beside_it() {
        let (path, at) = curved_lane();
        // 2 m per step: half done (step 15) at 32 m, done (step 30) at 60 m: path points 10
        // and 16 (the path starts 20 m behind).
        let progress = |t: usize| 2.0 * (t + 1) as f32;
        let drifting = |side: f32| -> Vec<[f32; 2]> {
            (0..80)
                .map(|t| at(progress(t), side * 1.5 * ((t + 1) as f32 / 40.0).min(1.0)))
                .collect()
        };
        let with_beside = |f: &dyn Fn(usize) -> [bool; 2]| LanePath {
            points: path.points.clone(),
            beside: (0..80).map(f).collect(),
        };
        // Only a lane on the left: the left drift moves, the right one does not.
        let left_only = with_beside(&|_| [true, false]);
        assert!(lane_move(&drifting(1.0), &left_only, 30).is_some());
        assert_eq!(lane_move(&drifting(-1.0), &left_only, 30), None);
        // The lane on the right ends at 50 m (point 14): an acceleration lane, a lane drop.
        let ends = with_beside(&|k| [false, k <= 14]);
        assert_eq!(lane_move(&drifting(-1.0), &ends, 30), None);
        // Ending at 100 m (point 24), after the move is done but before the mode's last point
        // (160 m, point 36): the copy would run on off its end.
        let ends_later = with_beside(&|k| [false, k <= 24]);
        assert_eq!(lane_move(&drifting(-1.0), &ends_later, 30), None);
        // Running to the horizon, it takes the move.
        let to_horizon = with_beside(&|k| [false, k <= 36]);
        assert!(lane_move(&drifting(-1.0), &to_horizon, 30).is_some());
        let short = with_beside(&|k| [false, k <= 35]);
        assert_eq!(lane_move(&drifting(-1.0), &short, 30), None);
        // ... or starts at 25 m (point 9) beyond a gore: the move ends on it.
        let starts = with_beside(&|k| [false, k >= 9]);
        assert!(lane_move(&drifting(-1.0), &starts, 30).is_some());
        let later = with_beside(&|k| [false, k >= 12]);
        assert_eq!(lane_move(&drifting(-1.0), &later, 30), None);
    }
}
