//! A single-lane roundabout where A and B meet at one entry: either B circulates and A enters
//! ahead of or after it, or B enters ahead of or after a circulating A.

use std::f64::consts::TAU;

use rand::Rng;
use rand_pcg::Pcg64Mcg;
use scbg_scene::Map;

use super::{
    BPlan, Background, NUM_STEPS, PairSetup, Run, committed_to_cross, curve_limit, curve_speeds,
    idm, noise_track, vehicle_size,
};
use crate::CURRENT_STEP;
use crate::RefPath;
use crate::sim::{Agent, closer};

mod map;
mod ring;

use ring::Ring;

/// The deceleration (m/s²) at which an entering vehicle without a gap brakes for the yield
/// line: it keeps going until it must.
const YIELD_BRAKE_MPS2: f64 = 3.0;
/// A circulating B that does not let A in drives at this share of its desired speed while A,
/// not yet on the ring, is beside or ahead of it.
const PRESS_ON_SHARE: f64 = 1.05;
/// The firmest braking (m/s²) with which a circulating B that lets A in stops before the entry.
const LET_IN_BRAKE_MPS2: f64 = 3.5;
/// The time headway (s) at which a circulating B that lets A in keeps behind A.
const LET_IN_HEADWAY_S: f64 = 1.8;
/// How far behind B (m, in the merge coordinate) an entering A still makes B adjust its speed.
const NOTICE_BEHIND_M: f64 = 5.0;
/// Seconds to cover `d` m from speed `v`, speeding up at `accel` up to `v_max` (m/s).
fn time_to_cover(d: f64, v: f64, accel: f64, v_max: f64) -> f64 {
    let v_max = v_max.max(v).max(0.5);
    let ramp_s = (v_max - v) / accel;
    let ramp_m = (v + v_max) / 2.0 * ramp_s;
    if d >= ramp_m {
        ramp_s + (d - ramp_m) / v_max
    } else {
        (-v + (v * v + 2.0 * accel * d).sqrt()) / accel
    }
}

/// Where (arclength) and how fast to start on `path` so as to reach arclength `to_s` after
/// `secs` at speed `v` where its curves (`speeds`, [`curve_speeds`]) allow it.
fn start_before(speeds: &[f64], to_s: f64, secs: f64, v: f64) -> (f64, f64) {
    let (mut s, mut left) = (to_s, secs);
    while left > 0.0 && s > 1.0 {
        let step_v = v.min(curve_limit(speeds, s - 1.0, v)).max(1.0);
        left -= 1.0 / step_v;
        s -= 1.0;
    }
    (s, v.min(curve_limit(speeds, s, v)))
}

/// The random draws of one roundabout scene (geometry, A and B, circulating traffic, noise).
#[derive(Debug, Clone)]
pub struct RoundaboutParams {
    ring: Ring,
    /// A's route and B's.
    paths: Vec<RefPath>,
    /// The speed each metre of each route is driven at for its curves ([`curve_speeds`]).
    curves: [Vec<f64>; 2],
    /// B circulates and A enters at arm 0; else B enters there and A circulates.
    b_circulates: bool,
    /// Arclength of the merge point at arm 0 along paths 0 (A's) and 1 (B's).
    merge_s: [f64; 2],
    /// The ring from the merge point on that both routes share, m.
    common_m: f64,
    /// The entering vehicle's yield line, in the merge coordinate.
    yield_m: f64,
    /// The time (s) a circulating vehicle's front must reach the merge point after the
    /// entering vehicle's rear has passed it (speeding up as it may) for the entering vehicle
    /// to go ahead of it.
    accepted_lag_s: f64,
    pair: PairSetup,
    /// Other vehicles circulating on the circulating vehicle's route: `(s, v, size, idm)`.
    background: Vec<Background>,
    noise: Vec<Vec<f64>>,
}

/// Draws the parameters of a roundabout scene.
pub fn roundabout_params(rng: &mut Pcg64Mcg) -> RoundaboutParams {
    let radius_m = rng.random_range(15.0..30.0);
    let lane_width_m = rng.random_range(3.6..4.4);
    let n_arms = if rng.random_bool(0.5) { 3 } else { 4 };
    let rotation = rng.random_range(0.0..TAU);
    let spacing = TAU / n_arms as f64;
    let arms_rad = (0..n_arms)
        .map(|k| rotation + spacing * (k as f64 + rng.random_range(-0.1..0.1)))
        .collect();
    let ring = Ring {
        radius_m,
        lane_width_m,
        arms_rad,
        deflection_m: radius_m * rng.random_range(0.6..0.9),
    };
    let b_circulates = rng.random_bool(0.5);
    let circulating_exit = rng.random_range(1..n_arms - 1);
    let entering_exit = rng.random_range(1..n_arms);
    // A comfortable speed on the ring (2.2–3.2 m/s² lateral), each vehicle about it.
    let v_ring = (radius_m * rng.random_range(2.2..3.2)).sqrt();
    let (a_v_des, b_v_des) = (
        v_ring * rng.random_range(0.9..1.1),
        v_ring * rng.random_range(0.9..1.1),
    );
    let (a_v0, b_v0) = (
        a_v_des * rng.random_range(0.9..1.0),
        b_v_des * rng.random_range(0.9..1.0),
    );
    // Times to the merge point after the current step: the entering vehicle's, and its lead
    // over the circulating one (positive: it arrives first), spread so that B's courtesy decides.
    let tau_entering: f64 = rng.random_range(3.0..5.5);
    let lead_s: f64 = if b_circulates {
        rng.random_range(-2.0..1.5)
    } else {
        rng.random_range(-1.0..3.5)
    };
    let tau_circulating = (tau_entering + lead_s).max(1.5);
    let accepted_lag_s = rng.random_range(0.8..1.6);
    let [a_route, b_route] = routes(b_circulates, n_arms, entering_exit, circulating_exit);
    let merge_s = [a_route.0, b_route.0].map(|i| ring.s_at(i, ring.join(0)));
    let entry = ring.entry_points(0);
    let yield_m = ring.yield_m(&entry);
    let common_m = ring
        .common_to(circulating_exit)
        .min(ring.common_to(entering_exit));
    let history_s = CURRENT_STEP as f64 * 0.1;
    let (a_tau, b_tau) = if b_circulates {
        (tau_entering, tau_circulating)
    } else {
        (tau_circulating, tau_entering)
    };
    let paths = [a_route, b_route].map(|(i, o)| RefPath::from_points(&ring.route(i, o), 1.0));
    let curves = paths.each_ref().map(curve_speeds);
    let (a_s0, a_v0) = start_before(&curves[0], merge_s[0], a_tau + history_s, a_v0);
    let (b_s0, b_v0) = start_before(&curves[1], merge_s[1], b_tau + history_s, b_v0);
    // (The draws in between take nothing from `rng`, so the pair's draws keep their place.)
    let pair = PairSetup::draw(rng, (a_v_des, a_s0, a_v0), (b_v_des, b_s0, b_v0));
    let circ_s0 = if b_circulates { b_s0 } else { a_s0 };
    let mut background = Vec::new();
    if rng.random_bool(0.4) {
        let v = v_ring * rng.random_range(0.9..1.1);
        let size = vehicle_size(rng);
        background.push((circ_s0 + rng.random_range(25.0..45.0), v, size, idm(rng, v)));
    }
    // A follower only behind a circulating A: behind a circulating B, one held up by B's
    // courtesy would let A in too, and A alone would meet it.
    if !b_circulates && rng.random_bool(0.5) {
        let v = v_ring * rng.random_range(0.9..1.1);
        let size = vehicle_size(rng);
        let s = (circ_s0 - rng.random_range(15.0..30.0)).max(0.0);
        background.push((s, v * 0.95, size, idm(rng, v)));
    }
    let n_agents = 2 + background.len();
    RoundaboutParams {
        ring,
        paths: paths.to_vec(),
        curves,
        b_circulates,
        merge_s,
        common_m,
        yield_m,
        accepted_lag_s,
        pair,
        background,
        noise: (0..n_agents).map(|_| noise_track(rng, NUM_STEPS)).collect(),
    }
}

impl RoundaboutParams {
    /// Whether B circulates (and A enters), rather than B entering ahead of or after A.
    pub fn b_circulates(&self) -> bool {
        self.b_circulates
    }
}

/// The routes (entry arm, exit arm) of A and B: the entering vehicle's from arm 0, the
/// circulating vehicle's from the arm before it.
fn routes(
    b_circulates: bool,
    n_arms: usize,
    entering_exit: usize,
    circulating_exit: usize,
) -> [(usize, usize); 2] {
    let (entering, circulating) = ((0, entering_exit), (n_arms - 1, circulating_exit));
    if b_circulates {
        [entering, circulating]
    } else {
        [circulating, entering]
    }
}

/// The reference paths of a roundabout scene: A's route, then B's (circulating traffic on the
/// circulating vehicle's).
pub fn roundabout_paths(p: &RoundaboutParams) -> Vec<RefPath> {
    p.paths.clone()
}

/// B's decision, when it circulates, whether to let A in ahead of it: when A's lead over B at
/// the merge point (each at its speed then) exceeds `1.2 − 3.5c` s.
pub fn roundabout_lets_in(lead_s: f64, courtesy: f64) -> bool {
    lead_s > 1.2 - 3.5 * courtesy
}

/// B's decision, when it enters, whether to go ahead of the circulating A: when its lead over
/// A at the merge point exceeds `0.3 + 2.7c` s.
pub fn roundabout_enters_first(lead_s: f64, courtesy: f64) -> bool {
    lead_s > 0.3 + 2.7 * courtesy
}

/// Simulates a roundabout scene on its `paths` ([`roundabout_paths`]) with B as `b` says; the
/// map is built only when `with_map`.
///
/// Positions compare in the *merge coordinate* `m` (arclength past the merge point at arm 0 on
/// each vehicle's own path). The entering vehicle yields at its yield line to every
/// circulating vehicle that has not passed the merge point unless that one's front (at its
/// speed now) will reach the merge point an accepted 0.8–1.6 s after the entering vehicle's rear
/// has passed it (speeding up as it may); circulating vehicles treat it as a vehicle ahead once
/// it is committed to enter ([`committed_to_cross`] at the yield line), seeing B with a reaction
/// delay; on the shared ring everyone follows whoever is ahead. Only B's observable motion counts, so a replayed B gets the same reactions.
pub fn simulate_roundabout(
    p: &RoundaboutParams,
    paths: Vec<RefPath>,
    b: BPlan<'_>,
    with_map: bool,
) -> Run {
    let with_b = b.present();
    let mut agents = p.pair.agents(1, 0.0, with_b);
    let circ_path = usize::from(p.b_circulates);
    agents.extend(super::background_agents(&p.background, circ_path));
    let noise_of = |i: usize| if with_b || i == 0 { i } else { i + 1 };
    // The entering vehicle's index (none when it is an absent B).
    let entering = match (p.b_circulates, with_b) {
        (true, _) => 0,
        (false, true) => 1,
        (false, false) => usize::MAX,
    };
    let has_entering = entering != usize::MAX;
    // Everyone sees B with its reaction delay.
    let delay = |j: usize| {
        if with_b && j == 1 {
            p.pair.reaction_steps
        } else {
            0
        }
    };
    let (common, yield_m) = (p.common_m, p.yield_m);
    let mut may_enter = false;
    let mut b_choice: Option<bool> = None;
    for t in 0..b.steps() - 1 {
        let m_of = |a: &Agent, delay: usize| a.delayed(delay).0 - p.merge_s[a.path];
        let mut cmds = vec![0.0; agents.len()];
        // Whether circulating vehicle `j` has passed the merge point (its rear 1 m beyond).
        let passed = |agents: &[Agent], j: usize| {
            m_of(&agents[j], delay(j)) - agents[j].length_m / 2.0 > 1.0
        };
        if with_b && b_choice.is_none() && t >= CURRENT_STEP {
            let (ma, mb) = (m_of(&agents[0], 0), m_of(&agents[1], 0));
            let (to_a, to_b) = (-ma / agents[0].v.max(1.0), -mb / agents[1].v.max(1.0));
            let c = b.courtesy(t);
            if p.b_circulates {
                b_choice = Some(roundabout_lets_in(to_b - to_a, c));
            } else if mb > yield_m - 25.0 {
                let a_passed = passed(&agents, 0);
                let go = a_passed || roundabout_enters_first(to_a - to_b, c);
                if go && !a_passed {
                    agents[1].idm.desired_speed_mps *= 1.0 + 0.15 * c;
                }
                b_choice = Some(go);
            }
        }
        if has_entering && !may_enter {
            let e = &agents[entering];
            let me = m_of(e, 0);
            // When its rear will be past the merge point, speeding up as it may.
            let clear_s = time_to_cover(
                (e.length_m / 2.0 - me).max(0.0),
                e.v,
                e.idm.max_accel_mps2,
                e.idm.desired_speed_mps,
            );
            // B entering waits for A unless it chose to go first (and always in its history).
            let waits_for_a = entering == 1 && b_choice != Some(true) && !passed(&agents, 0);
            let gaps_ok = (0..agents.len())
                .filter(|&j| j != entering && agents[j].path != agents[entering].path)
                .all(|j| {
                    if passed(&agents, j) || (entering == 1 && j == 0 && b_choice == Some(true)) {
                        return true;
                    }
                    let (s_j, _, v_j) = agents[j].delayed(delay(j));
                    let m_j = s_j - p.merge_s[agents[j].path];
                    let j_arrives_s = (-m_j - agents[j].length_m / 2.0) / v_j.max(1.0);
                    j_arrives_s - clear_s > p.accepted_lag_s
                });
            if me > yield_m - 25.0 && !waits_for_a && gaps_ok {
                may_enter = true;
            }
            if me > yield_m + 0.5 {
                // Beyond the line without a gap (it could not stop): it goes.
                may_enter = true;
            }
        }
        for i in 0..agents.len() {
            let me = &agents[i];
            let m_i = m_of(me, 0);
            let mut leader = None;
            for (j, other) in agents.iter().enumerate() {
                if j == i {
                    continue;
                }
                let (s_j, _, v_j) = other.delayed(delay(j));
                if other.path == me.path {
                    if s_j > me.s {
                        leader = closer(leader, Some((me.gap_to(s_j, other.length_m), v_j)));
                    }
                    continue;
                }
                let m_j = s_j - p.merge_s[other.path];
                let gap = m_j - m_i - 0.5 * (me.length_m + other.length_m);
                let on_common = m_j > m_i && m_j < common && m_i < common;
                let counts = if j == entering {
                    // The entering vehicle, for circulating traffic: once committed, nearby.
                    m_j > yield_m - 25.0 && committed_to_cross(m_j, v_j, yield_m, 0.0)
                } else {
                    // Circulating traffic, for the entering vehicle: once past the merge point.
                    m_j > 0.0
                };
                if on_common && counts {
                    leader = closer(leader, Some((gap, v_j)));
                }
            }
            let mut idm = me.idm;
            idm.desired_speed_mps =
                idm.desired_speed_mps
                    .min(curve_limit(&p.curves[me.path], me.s, me.v));
            if i == entering && !may_enter {
                // Waits at the yield line: keeps going until it must brake for it.
                // (The line as a standing obstacle, at IDM's standstill gap beyond it.)
                let to_line_m = yield_m - m_i;
                if to_line_m < me.v * me.v / (2.0 * YIELD_BRAKE_MPS2) + 1.0 {
                    leader = closer(leader, Some((to_line_m.max(0.0) + idm.min_gap_m, 0.0)));
                }
            }
            if i == 1 && p.b_circulates && has_entering {
                let a = &agents[0];
                let m_a = m_of(a, 0);
                if m_a < 0.0 && m_i < common {
                    match b_choice {
                        // B lets A in: it keeps behind an A ahead of it, at a long headway, and
                        // waits before the entry for an A about to enter, if it can stop there.
                        Some(true) => {
                            if m_a > m_i {
                                idm.time_headway_s = idm.time_headway_s.max(LET_IN_HEADWAY_S);
                                let gap = m_a - m_i - 0.5 * (me.length_m + a.length_m);
                                leader = closer(leader, Some((gap, a.v)));
                            }
                            let to_wait_m = yield_m - 1.0 - m_i - me.length_m / 2.0;
                            let can_stop = to_wait_m > 0.0
                                && me.v * me.v / (2.0 * to_wait_m) <= LET_IN_BRAKE_MPS2;
                            if m_a > yield_m - 30.0 && can_stop {
                                leader = closer(leader, Some((to_wait_m + idm.min_gap_m, 0.0)));
                            }
                        }
                        // B presses on past an A beside or ahead of it.
                        Some(false) if m_a > m_i - NOTICE_BEHIND_M => {
                            idm.desired_speed_mps *= PRESS_ON_SHARE;
                        }
                        _ => {}
                    }
                }
            }
            cmds[i] = idm.accel(me.v, leader) + p.noise[noise_of(i)][t];
        }
        for (i, a) in agents.iter_mut().enumerate() {
            a.step(cmds[i], 0.0);
        }
        b.after_step(&mut agents, t);
    }
    let map = if with_map {
        p.ring.map()
    } else {
        Map::default()
    };
    Run { paths, agents, map }
}
