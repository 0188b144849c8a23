//! B on the main lane lets A, merging from an on-ramp, in ahead of it: the merge with the roles
//! turned round.

use rand::Rng;
use rand_pcg::Pcg64Mcg;
use scbg_scene::{Map, ObjectType};

use super::merge::{Ramp, main_lane_traffic};
use super::{BPlan, Background, NUM_STEPS, PairSetup, Run, merging_into_lane, noise_track};
use crate::CURRENT_STEP;
use crate::RefPath;
use crate::sim::{Agent, STEP_SECS, closer};

/// How far behind B (m) a merging A still makes a B adjust its speed: an A farther back merges
/// behind B whatever B does.
const NOTICE_BEHIND_M: f64 = 15.0;

/// The random draws of one let-in or zipper scene (geometry, A and B, background traffic, noise).
#[derive(Debug, Clone)]
pub struct LetinParams {
    ramp: Ramp,
    /// The lag (s) behind A's rear at which B's front must be, at B's speed, for A on the ramp
    /// to merge ahead of it.
    accepted_lag_s: f64,
    pair: PairSetup,
    background: Vec<Background>,
    noise: Vec<Vec<f64>>,
    /// B's rule for letting A in.
    rule: LetInRule,
}

/// Draws the parameters of a let-in scene.
pub fn letin_params(rng: &mut Pcg64Mcg) -> LetinParams {
    let lane_width_m = rng.random_range(3.4..3.9);
    let merge_end_s = rng.random_range(260.0..300.0);
    let taper_m = rng.random_range(100.0..140.0);
    let merge_mid = merge_end_s - taper_m * 0.5;
    // B on the main lane, A on the ramp.
    let b_v_des = rng.random_range(22.0..27.0);
    let b_v0 = b_v_des * rng.random_range(0.95..1.0);
    let b_s0 = rng.random_range(20.0..40.0);
    let a_v_des = rng.random_range(20.0..26.0);
    let a_v0 = a_v_des * rng.random_range(0.85..1.0);
    // A's lead time over B at the merge (positive: A arrives first), spread around the
    // accepted lead so that B's speed decides.
    let lead_s: f64 = rng.random_range(-0.8..0.4);
    let tau_b = (merge_mid - b_s0) / b_v0;
    let a_s0 = (merge_mid - (tau_b - lead_s) * a_v0).max(5.0);
    let accepted_lag_s = rng.random_range(0.8..1.6);
    let background = main_lane_traffic(rng, b_s0);
    let ramp = Ramp {
        curvature: rng.random_range(-1.0 / 900.0..1.0 / 900.0),
        lane_width_m,
        merge_end_s,
        taper_m,
        accel_lane_m: rng.random_range(20.0..60.0),
        ramp_angle_rad: rng.random_range(5f64..15.0).to_radians(),
        lane_drop: None,
    };
    let a = (a_v_des, a_s0, a_v0);
    let b = (b_v_des, b_s0, b_v0);
    LetinParams::draw_pair(rng, ramp, accepted_lag_s, (a, b), background, LETIN_RULE)
}

impl LetinParams {
    /// A let-in scene on `ramp` with B's `rule`: draws A and B (`(v_des, s0, v0)` each, see
    /// [`PairSetup::draw`]) and every agent's noise, in that order.
    pub(super) fn draw_pair(
        rng: &mut Pcg64Mcg,
        ramp: Ramp,
        accepted_lag_s: f64,
        (a, b): ((f64, f64, f64), (f64, f64, f64)),
        background: Vec<Background>,
        rule: LetInRule,
    ) -> Self {
        let pair = PairSetup::draw(rng, a, b);
        let n_agents = 2 + background.len();
        Self {
            ramp,
            accepted_lag_s,
            pair,
            background,
            noise: (0..n_agents).map(|_| noise_track(rng, NUM_STEPS)).collect(),
            rule,
        }
    }
}

/// The reference path of a let-in scene (every agent moves along it, A at the ramp's offset).
pub fn letin_paths(p: &LetinParams) -> Vec<RefPath> {
    p.ramp.paths()
}

/// B's decision, from the current step on, whether to let A in ahead of it: when A's lead over
/// B at the merge (each at its speed then) exceeds `least_courteous_s − span_s · c`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct LetInRule {
    /// The lead (s) above which the least courteous B (c = 0) lets A in.
    pub least_courteous_s: f64,
    /// How much less lead (s) the most courteous B (c = 1) asks for.
    pub span_s: f64,
    /// How firmly (m/s², at most) a B that lets A in drops back behind an A beside it or just
    /// behind it; `None`: it only keeps behind an A already ahead of it.
    pub drop_back_mps2: Option<f64>,
}

impl LetInRule {
    /// Whether B with courtesy `courtesy` lets in an A with lead `lead_s` at the merge.
    pub fn lets_in(&self, lead_s: f64, courtesy: f64) -> bool {
        lead_s > self.least_courteous_s - self.span_s * courtesy
    }
}

/// The let-in family's rule, `1.5 − 4c` s: a courteous B lets in an A that would arrive up to
/// 2.5 s after it; one that is not, only an A already 1.5 s ahead. B does not brake for an A
/// that is not yet ahead of it.
pub const LETIN_RULE: LetInRule = LetInRule {
    least_courteous_s: 1.5,
    span_s: 4.0,
    drop_back_mps2: None,
};

/// The time headway (s) at which a B that lets A in keeps behind a merging A ahead of it (or
/// its own, when longer): more than any A's accepted lag.
pub const LETIN_HEADWAY_S: f64 = 1.8;
/// The deceleration (m/s²) at which A, on the ramp without a gap, brakes for the end of the
/// acceleration lane: it keeps going until it must.
pub const WAIT_BRAKE_MPS2: f64 = 3.5;
/// A B that does not let A in drives at this share of its desired speed while A is beside or
/// ahead of it and not yet in its lane: it presses on to pass.
pub const PRESS_ON_SHARE: f64 = 1.05;

/// Simulates a let-in scene on its `paths` ([`letin_paths`]) with B as `b` says; the map is
/// built only when `with_map`.
///
/// A, in the acceleration lane, merges ahead of B when, seen with its reaction delay, B's
/// front will be an accepted 0.8–1.6 s (at B's speed) behind A's rear when A reaches the taper
/// (both at their speeds now); otherwise it waits at the end of the acceleration lane until B
/// has passed, and merges behind it. A decides on B's
/// observable motion alone, so a replayed B gets the same reaction as a simulated one.
pub fn simulate_letin(p: &LetinParams, paths: Vec<RefPath>, b: BPlan<'_>, with_map: bool) -> Run {
    let with_b = b.present();
    let path = &paths[0];
    let ramp = &p.ramp;
    let w = ramp.lane_width_m;
    let taper_start = ramp.taper_start();
    let merge_mid = ramp.merge_end_s - ramp.taper_m * 0.5;
    let mut agents = vec![Agent::new(
        super::A_ID,
        ObjectType::Vehicle,
        0,
        p.pair.a_size,
        p.pair.a_idm,
        p.pair.a_s0,
        ramp.ramp_d(p.pair.a_s0),
        p.pair.a_v0,
    )];
    if with_b {
        agents.push(Agent::new(
            super::B_ID,
            ObjectType::Vehicle,
            0,
            p.pair.b_size,
            p.pair.b_idm,
            p.pair.b_s0,
            0.0,
            p.pair.b_v0,
        ));
    }
    agents.extend(super::background_agents(&p.background, 0));
    // Whether A may merge: it has decided to go ahead of B, or B has passed it (latched once
    // A is in the taper).
    let mut a_may_merge = !with_b;
    // B's decision whether to let A in (from the current step on).
    let mut lets_in: Option<bool> = None;
    for t in 0..b.steps() - 1 {
        let mut cmds = vec![0.0; agents.len()];
        let a_in_lane = agents[0].d.abs() < 0.75 * w;
        if with_b && lets_in.is_none() && t >= CURRENT_STEP {
            let (a, me) = (&agents[0], &agents[1]);
            let lead = (merge_mid - me.s) / me.v.max(1.0) - (merge_mid - a.s) / a.v.max(1.0);
            lets_in = Some(p.rule.lets_in(lead, b.courtesy(t)));
        }
        let parallel_start = taper_start - ramp.accel_lane_m;
        if with_b && !a_may_merge && (parallel_start..taper_start).contains(&agents[0].s) {
            // A's gap acceptance, in the acceleration lane: B's front, where it will be when
            // A reaches the taper (both at their speeds now), far enough behind A's rear in
            // time at B's speed.
            let (a, b_len) = (&agents[0], agents[1].length_m);
            let (s_b, _, v_b) = agents[1].delayed(p.pair.reaction_steps);
            let to_taper_s = (taper_start - a.s) / a.v.max(1.0);
            let lag_m = (a.s - 0.5 * a.length_m) - (s_b + 0.5 * b_len) + (a.v - v_b) * to_taper_s;
            a_may_merge = lag_m / v_b.max(1.0) > p.accepted_lag_s;
        }
        for i in 0..agents.len() {
            let me = &agents[i];
            let mut leader = None;
            for (j, other) in agents.iter().enumerate() {
                if j == i {
                    continue;
                }
                // Everyone sees B with a reaction delay (A its own, the others the same).
                let delay = if with_b && j == 1 {
                    p.pair.reaction_steps
                } else {
                    0
                };
                let (s_j, d_j, v_j) = other.delayed(delay);
                let relevant = if j == 0 {
                    // A matters to main-lane traffic once it is (about to be) in the lane.
                    merging_into_lane(d_j, other.delayed_lateral_rate(delay), w)
                } else if i == 0 {
                    // A on the ramp: main-lane agents matter once A is in the taper.
                    d_j.abs() < 0.75 * w && (me.s > taper_start || a_in_lane)
                } else {
                    true
                };
                if relevant && s_j > me.s {
                    leader = closer(leader, Some((me.gap_to(s_j, other.length_m), v_j)));
                }
            }
            // A waits at the end of the acceleration lane until B has passed: it keeps going
            // while a gap may still open, and brakes for the line once it is within its
            // stopping distance at a firm 3.5 m/s² of it.
            let to_line_m = taper_start - me.s - me.length_m * 0.5;
            let stopping_m = me.v * me.v / (2.0 * WAIT_BRAKE_MPS2);
            if i == 0
                && with_b
                && !a_may_merge
                && me.s < taper_start + 1.0
                && to_line_m < stopping_m
            {
                let (s_b, _, _) = agents[1].delayed(p.pair.reaction_steps);
                let b_passed = s_b - agents[1].length_m > me.s + 2.0;
                if !b_passed {
                    leader = closer(leader, Some((to_line_m, 0.0)));
                }
            }
            let mut idm = me.idm;
            // The firmest braking B's command may ask for (only a B dropping back has one).
            let mut firmest_mps2 = f64::INFINITY;
            let a = &agents[0];
            if i == 1 && !a_in_lane && a.s < ramp.merge_end_s {
                match lets_in {
                    // B lets A in: it keeps behind a merging A ahead of it, at a long headway.
                    Some(true) if a.s > me.s => {
                        idm.time_headway_s = idm.time_headway_s.max(LETIN_HEADWAY_S);
                        leader = closer(leader, Some((me.gap_to(a.s, a.length_m), a.v)));
                    }
                    // B lets in an A beside it or just behind: where the rule says so, it drops
                    // back behind A.
                    Some(true) if a.s > me.s - NOTICE_BEHIND_M => {
                        if let Some(brake) = p.rule.drop_back_mps2 {
                            idm.time_headway_s = idm.time_headway_s.max(LETIN_HEADWAY_S);
                            leader = closer(leader, Some((me.gap_to(a.s, a.length_m), a.v)));
                            firmest_mps2 = brake;
                        }
                    }
                    // B presses on past an A beside or ahead of it.
                    Some(false) if a.s > me.s - NOTICE_BEHIND_M => {
                        idm.desired_speed_mps *= PRESS_ON_SHARE;
                    }
                    _ => {}
                }
            }
            cmds[i] = idm.accel(me.v, leader).max(-firmest_mps2) + p.noise[i][t];
        }
        for (i, a) in agents.iter_mut().enumerate() {
            let d_next = if i == 0 {
                ramp.ramp_d(a.s + a.v * STEP_SECS)
            } else {
                0.0
            };
            a.step(cmds[i], d_next);
        }
        b.after_step(&mut agents, t);
        if with_b && agents[0].s >= taper_start && !a_may_merge {
            // Past the wait line A merges, behind B.
            a_may_merge = agents[1].s - agents[1].length_m > agents[0].s;
        }
    }
    let map = if with_map {
        let ramp_start = (p.pair.a_s0 - 30.0)
            .min(taper_start - ramp.accel_lane_m - 20.0)
            .max(-50.0);
        ramp.map(path, ramp_start)
    } else {
        Map::default()
    };
    Run { paths, agents, map }
}
