//! The zipper at a lane drop: A's lane ends, and B, in the lane beside it that goes on, lets A
//! in ahead of it or not.
//!
//! The road is a two-lane arterial or freeway (limit 11–22 m/s) whose right lane ends in a 40–80 m
//! taper; A drives in it, B beside it in the through lane, with a slower car ahead of B
//! (the queue the zipper forms) and another behind. The manoeuvres are the let-in family's
//! ([`super::simulate_letin`]) under [`ZIPPER_RULE`]: B lets A in when A's lead at the merge
//! exceeds `0.6 − 0.8c` s, then drops back behind an A beside it and keeps behind A at a 1.8 s
//! headway, else presses on; A merges ahead of B only into an accepted lag, looked for over the
//! last 40–80 m of its lane, and otherwise waits at the taper for B to pass. What differs is the road (a lane beside the through lane from the
//! start, lane neighbours, the line between them), the speeds and the shorter taper: a road
//! class and a situation the let-in family does not show.

use rand::Rng;
use rand_pcg::Pcg64Mcg;

use super::letin::{LetInRule, LetinParams};
use super::merge::Ramp;
use super::{idm, vehicle_size};

/// The zipper's rule for letting A in, `0.6 − 0.8c` s of A's lead at the merge: spread over
/// the leads a zipper draws (−0.1 … 0.6 s), so that every courtesy decides some scenes. A B
/// that lets A in drops back behind an A beside it, braking at up to 3 m/s²: at a lane drop
/// one car in turn from each lane is the norm.
pub const ZIPPER_RULE: LetInRule = LetInRule {
    least_courteous_s: 0.6,
    span_s: 0.8,
    drop_back_mps2: Some(3.0),
};

/// Draws the parameters of a zipper scene.
pub fn zipper_params(rng: &mut Pcg64Mcg) -> LetinParams {
    let speed_limit_mps = rng.random_range(11.0..22.0);
    let lane_width_m = rng.random_range(3.0..3.7);
    let taper_m = rng.random_range(40.0..80.0);
    // B in the through lane, reaching the middle of the taper 5.5–8 s after the current step:
    // late enough that A, who brakes for the taper's start when it has no gap, has not begun
    // to before B decides.
    let b_v_des = speed_limit_mps * rng.random_range(0.9..1.05);
    let b_v0 = b_v_des * rng.random_range(0.85..1.0);
    let b_s0 = rng.random_range(20.0..40.0);
    let tau_b = rng.random_range(5.5..8.0) + crate::CURRENT_STEP as f64 * 0.1;
    let merge_mid = b_s0 + tau_b * b_v0;
    // A in the lane that ends; its lead over B at the merge (positive: A arrives first), spread
    // around the accepted lead so that B's choice decides.
    let a_v_des = speed_limit_mps * rng.random_range(0.85..1.0);
    let a_v0 = a_v_des * rng.random_range(0.85..1.0);
    let lead_s: f64 = rng.random_range(-0.1..0.6);
    let a_s0 = (merge_mid - (tau_b - lead_s) * a_v0).max(5.0);
    let accepted_lag_s = rng.random_range(0.6..1.2);
    let mut background = Vec::new();
    if rng.random_bool(0.7) {
        // The queue ahead of B: slower than the limit.
        let size = vehicle_size(rng);
        let v = speed_limit_mps * rng.random_range(0.8..0.95);
        background.push((b_s0 + rng.random_range(30.0..60.0), v, size, idm(rng, v)));
    }
    if rng.random_bool(0.5) {
        let size = vehicle_size(rng);
        let v = speed_limit_mps * rng.random_range(0.9..1.05);
        background.push((
            (b_s0 - rng.random_range(20.0..35.0)).max(-30.0),
            v * 0.95,
            size,
            idm(rng, v),
        ));
    }
    let ramp = Ramp {
        curvature: rng.random_range(-1.0 / 900.0..1.0 / 900.0),
        lane_width_m,
        merge_end_s: merge_mid + taper_m * 0.5,
        taper_m,
        // The stretch before the taper over which A looks for its gap.
        accel_lane_m: rng.random_range(40.0..80.0),
        ramp_angle_rad: 0.0,
        lane_drop: Some(speed_limit_mps),
    };
    let a = (a_v_des, a_s0, a_v0);
    let b = (b_v_des, b_s0, b_v0);
    LetinParams::draw_pair(rng, ramp, accepted_lag_s, (a, b), background, ZIPPER_RULE)
}

#[cfg(test)]
mod tests {
    use rand::SeedableRng;
    use rand_pcg::Pcg64Mcg;

    use super::zipper_params;
    use crate::families::{BPlan, NUM_STEPS, letin_paths, simulate_letin};
    use crate::sim::Agent;

    /// The lane drop's map: the dropped lane (3) runs beside the through lane (1) as its right
    /// neighbour up to the taper and both lead into the lane after the drop (2); A starts in the
    /// dropped lane; at any courtesy of B no vehicle touches another.
    #[test]
    fn the_dropped_lane_joins_the_through_lane_and_no_one_touches() {
        for seed in 0..60 {
            let p = zipper_params(&mut Pcg64Mcg::seed_from_u64(seed));
            for c in [0.0, 0.5, 1.0] {
                let paths = letin_paths(&p);
                let plan = BPlan::Simulated {
                    history: c,
                    future: c,
                };
                let run = simulate_letin(&p, paths.clone(), plan, true);
                let lane = |id| run.map.lanes.iter().find(|l| l.id == id).expect("lane");
                let (through, after, dropped) = (lane(1), lane(2), lane(3));
                assert_eq!(after.entry_lanes, vec![1, 3]);
                assert_eq!(
                    (through.exit_lanes.clone(), dropped.exit_lanes.clone()),
                    (vec![2], vec![2])
                );
                assert_eq!(through.right_neighbors[0].feature_id, 3);
                assert_eq!(dropped.left_neighbors[0].feature_id, 1);
                let a = &run.agents[0];
                assert!(
                    a.history[0].1 < -2.9,
                    "seed {seed}: A starts beside the through lane"
                );
                let state =
                    |agent: &Agent, t| crate::sim::recorded_state(agent, &paths, NUM_STEPS, t);
                for (i, x) in run.agents.iter().enumerate() {
                    for y in &run.agents[i + 1..] {
                        assert!(
                            (0..NUM_STEPS)
                                .all(|t| !crate::sim::boxes_overlap(&state(x, t), &state(y, t))),
                            "seed {seed}, c {c}: {} and {} touch",
                            x.id,
                            y.id
                        );
                    }
                }
            }
        }
    }

    /// A courteous B lets A in ahead of it far more often than one that is not.
    #[test]
    fn a_courteous_b_lets_a_in_ahead() {
        let ahead = |c: f64| {
            (0..200)
                .filter(|&seed| {
                    let p = zipper_params(&mut Pcg64Mcg::seed_from_u64(seed));
                    let plan = BPlan::Simulated {
                        history: 0.5,
                        future: c,
                    };
                    let run = simulate_letin(&p, letin_paths(&p), plan, false);
                    run.agents[0].s > run.agents[1].s
                })
                .count()
        };
        let (low, high) = (ahead(0.1), ahead(0.9));
        assert!(
            high >= low + 40,
            "A ahead of B: {low} of 200 at c 0.1, {high} at c 0.9"
        );
    }
}
