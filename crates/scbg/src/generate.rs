//! Generation (paper Sec. III-E): B's future in the world frame for a pair (A, B) of a WOMD
//! scenario, at a courtesy quantile or an explicit ψ.

use std::path::Path;

use scbg_scene::Scene;
use serde::Serialize;

use crate::artefact::LoadedScbg;
use crate::{Courtesy, InvalidRequest, ROAD_SUBSAMPLE};

/// One generated future of B and what the model expects of it.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Generated {
    /// The quantile asked for, or the one an explicit ψ corresponds to (linear between the
    /// predicted 0.1 and 0.9 quantiles, extended beyond them).
    pub quantile: f32,
    /// The ψ the quantile maps to (m/s for the default reward); with sample and rank and a
    /// quantile, the label of the chosen sampled future.
    pub psi: f32,
    /// The predicted 0.1 quantile of ψ for this scene and pair.
    pub psi_low: f32,
    /// The predicted 0.9 quantile.
    pub psi_high: f32,
    /// J_φ of the generated future: what the predictor expects it does to A.
    pub achieved_psi: f32,
    /// E[r(Y_A) | x, ŷ_B] (toward the model's audience).
    pub a_expected_reward_conditional: f32,
    /// E[r(Y_A) | x].
    pub a_expected_reward_marginal: f32,
    /// B's future, world frame, metres, at `step_secs` intervals after the current step.
    pub world_xy_m: Vec<[f64; 2]>,
    /// Time between points, seconds.
    pub step_secs: f32,
}

impl From<scbg_generator::Generated> for Generated {
    fn from(g: scbg_generator::Generated) -> Self {
        Self {
            quantile: g.quantile,
            psi: g.psi,
            psi_low: g.psi_low,
            psi_high: g.psi_high,
            achieved_psi: g.achieved_psi,
            a_expected_reward_conditional: g.a_expected_reward_conditional,
            a_expected_reward_marginal: g.a_expected_reward_marginal,
            world_xy_m: g.world_xy_m,
            step_secs: g.step_secs,
        }
    }
}

/// ψ of a given future of B toward A (paper eq. 2), with both expectations.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CourtesyOf {
    /// ψ = E[r(Y_A) | x, y_B] − E[r(Y_A) | x].
    pub psi: f32,
    /// E[r(Y_A) | x, y_B] (toward the model's audience).
    pub a_expected_reward_conditional: f32,
    /// E[r(Y_A) | x], estimated as in the labels.
    pub a_expected_reward_marginal: f32,
}

/// B's generated futures for one pair of one scenario (the `scbg generate` JSON).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Generation {
    /// The scenario.
    pub scenario_id: String,
    /// Track id of A.
    pub a_id: i64,
    /// Track id of B.
    pub b_id: i64,
    /// The step the futures start after.
    pub current_step: usize,
    /// The generator variant.
    pub variant: scbg_generator::Variant,
    /// One future per requested courtesy, in the order asked.
    pub trajectories: Vec<Generated>,
}

/// The first scenario of `file` with id `scenario_id`, or (without an id) the first that has
/// both tracks `a` and `b`: `(record index, scene)`.
pub fn find_scene(
    file: &Path,
    scenario_id: Option<&str>,
    a: i64,
    b: i64,
) -> anyhow::Result<(usize, Scene)> {
    let womd = scbg_womd::WomdFile::open(file)?;
    for (index, scene) in womd.scenes().enumerate() {
        let scene = scene?;
        let wanted = match scenario_id {
            Some(id) => scene.scenario_id == id,
            None => scene.track_index(a).is_some() && scene.track_index(b).is_some(),
        };
        if wanted {
            return Ok((index, scene));
        }
    }
    Err(anyhow::Error::new(InvalidRequest(match scenario_id {
        Some(id) => format!("{}: no scenario {id:?}", file.display()),
        None => format!(
            "{}: no scenario has both track {a} and track {b}",
            file.display()
        ),
    })))
}

/// The scene's inference features, checked to hold one window (11 history steps).
fn prepare(scene: &Scene) -> anyhow::Result<scbg_features::PreparedScene> {
    let prepared = scbg_features::PreparedScene::for_inference(
        scene,
        &scbg_features::WindowConfig::default(),
        ROAD_SUBSAMPLE,
    );
    if prepared.windows.is_empty() {
        return Err(anyhow::Error::new(InvalidRequest(format!(
            "scenario {}: too short for one window (11 history steps)",
            scene.scenario_id
        ))));
    }
    Ok(prepared)
}

/// Whether a world-frame future of B leaves `scene`'s road: a point beyond the map's road
/// edge (WOSAC's off-road rule, which the closed loop counts), at B's height now. `None` for a
/// map without road edges.
fn road_leaver(scene: &Scene, b: i64) -> Option<impl Fn(&[[f64; 2]]) -> bool> {
    let edges = scbg_metrics::wosac::RoadEdges::new(&scene.map)?;
    let z = scene.track_index(b).map_or(0.0, |i| {
        scene.tracks[i].states[scene.current_step].z_m as f32
    });
    let scratch = std::cell::RefCell::new(Vec::new());
    Some(move |future: &[[f64; 2]]| {
        future.iter().any(|p| {
            edges.signed_distance([p[0] as f32, p[1] as f32, z], &mut scratch.borrow_mut()) > 0.0
        })
    })
}

/// With sample and rank, the rule that takes B's candidates out of its choice
/// (`scbg_generator::PlanBasis::drop_candidates`): leaving the road ([`road_leaver`]). A
/// predictor's sample now and then drifts across a gore or off a lane's end, and ranked by J_φ
/// alone it can be the one a quantile takes. `None` for the learned generator (it chooses
/// otherwise) and for maps without road edges.
fn off_road_rule(
    model: &LoadedScbg,
    scene: &Scene,
    b: i64,
) -> Option<impl Fn(&[[f64; 2]]) -> bool> {
    (model.scbg.policy == scbg_generator::Policy::Ranked)
        .then(|| road_leaver(scene, b))
        .flatten()
}

/// The context every generation for (scene, A, B) shares: each member's generator context
/// (samples, B's embedding, E[r(Y_A) | x], the predicted range) and the scene's lane segments
/// that keep each future in lane. Keep it to generate at many courtesies cheaply
/// ([`generate_in`]).
#[derive(Debug)]
pub struct PairContext {
    /// One per member of the model ([`LoadedScbg::members`]), in order.
    members: Vec<scbg_generator::PairContext>,
    lanes: scbg_sim::lanes::LaneSegments,
    /// B's heading at the current step (world frame), where its futures start.
    b_heading_rad: Option<f64>,
}

/// The context of the pair (A = `a`, B = `b`) of `scene` ([`PairContext`]).
pub fn pair_context(
    model: &LoadedScbg,
    scene: &Scene,
    a: i64,
    b: i64,
) -> anyhow::Result<PairContext> {
    let members = per_member(
        model,
        scene,
        b,
        |m, prepared, window| m.scbg.pair_context(prepared, window, a, b, &m.device),
        |generator, leaves| generator.drop_candidates(leaves),
    )?;
    Ok(PairContext {
        members,
        lanes: scbg_sim::lanes::LaneSegments::new(&scene.map),
        b_heading_rad: scene.current_state(b).map(|s| f64::from(s.heading_rad)),
    })
}

/// One value per member of `model` for (scene, B): `build` from the scene's features, then,
/// with sample and rank, `drop` applied with the off-road rule ([`off_road_rule`]). Requests
/// the scene cannot answer are [`InvalidRequest`]s.
fn per_member<T: Send>(
    model: &LoadedScbg,
    scene: &Scene,
    b: i64,
    build: impl Fn(
        &LoadedScbg,
        &scbg_features::PreparedScene,
        &scbg_features::Window,
    ) -> Result<T, scbg_generator::GenerateError>
    + Sync,
    drop: impl Fn(&mut T, &dyn Fn(&[[f64; 2]]) -> bool) -> usize,
) -> anyhow::Result<Vec<T>> {
    let prepared = prepare(scene)?;
    let window = &prepared.windows[0];
    // Members share their policy (`LoadedScbg::set_policy`), so one rule serves them all.
    let leaves = off_road_rule(model, scene, b);
    let mut values = each_member(model, |_, m| build(m, &prepared, window).map_err(invalid))?;
    if let Some(leaves) = &leaves {
        for value in &mut values {
            drop(value, leaves);
        }
    }
    Ok(values)
}

/// `f(k, member)` of every member of `model` (`k` its index in [`LoadedScbg::members`]), in
/// member order, the members in parallel on the rayon pool: an ensemble's request costs about
/// one member's time per free core instead of the sum. One member runs on the caller's thread.
fn each_member<T: Send>(
    model: &LoadedScbg,
    f: impl Fn(usize, &LoadedScbg) -> anyhow::Result<T> + Sync,
) -> anyhow::Result<Vec<T>> {
    use rayon::prelude::*;
    let members: Vec<&LoadedScbg> = model.members().collect();
    if let [only] = members[..] {
        return Ok(vec![f(0, only)?]);
    }
    members
        .into_par_iter()
        .enumerate()
        .map(|(k, m)| f(k, m))
        .collect()
}

/// A generator error caused by the request, as an [`InvalidRequest`].
fn invalid(e: scbg_generator::GenerateError) -> anyhow::Error {
    anyhow::Error::new(InvalidRequest(e.to_string()))
}

/// Which of an ensemble's futures for one courtesy is B's: the medoid, the future whose mean
/// distance to the others' (point by point, over the points all share) is least, the earlier
/// member on a tie. Averaging the futures instead blends a member that yields with one that
/// goes into a B that does neither (docs/findings.md, *A seed ensemble*). One future is its
/// own medoid; a future with a non-finite point counts for none, and is chosen only if all
/// have one.
pub fn medoid(futures: &[&[[f64; 2]]]) -> usize {
    let distance = |p: &[[f64; 2]], q: &[[f64; 2]]| {
        let n = p.len().min(q.len());
        if n == 0 {
            return 0.0;
        }
        let sum: f64 = p
            .iter()
            .zip(q)
            .map(|(u, v)| (u[0] - v[0]).hypot(u[1] - v[1]))
            .sum();
        sum / n as f64
    };
    // A future with a non-finite point is nobody's medoid and no one's neighbour.
    let finite: Vec<bool> = futures
        .iter()
        .map(|f| f.iter().all(|p| p[0].is_finite() && p[1].is_finite()))
        .collect();
    let spread = |k: usize| -> f64 {
        if !finite[k] {
            return f64::INFINITY;
        }
        (0..futures.len())
            .filter(|&j| finite[j])
            .map(|j| distance(futures[k], futures[j]))
            .sum()
    };
    (0..futures.len())
        .map(|k| (k, spread(k)))
        .fold(None, |best: Option<(usize, f64)>, (k, d)| match best {
            Some((_, best_d)) if best_d <= d => best,
            _ => Some((k, d)),
        })
        .map_or(0, |(k, _)| k)
}

/// B's futures at each courtesy for a pair whose context is known ([`pair_context`]), each
/// kept in lane as the closed loop keeps every plan it follows (`scbg_sim::lanes`,
/// [`crate::DEFAULT_LANE_KEEPING_M`]) before J_φ measures it. The generator is trained open
/// loop and its futures drift sideways (1–2 m in 8 s on a straight road, inside curves on
/// bends; docs/findings.md, *Map detail*), so what a front end receives is the future B can
/// drive, and the ψ reported is that future's. An ensemble returns, per courtesy, the
/// [`medoid`] of its members' kept futures with that member's `psi` and range; its
/// `achieved_psi` and expected rewards are the ensemble's measure of it ([`courtesy_in`]).
pub fn generate_in(
    model: &LoadedScbg,
    context: &PairContext,
    courtesy: &[Courtesy],
) -> anyhow::Result<Vec<Generated>> {
    same_members(model, context.members.len())?;
    let courtesy: Vec<scbg_generator::Courtesy> = courtesy.iter().map(|c| c.get()).collect();
    let keep = |future: &mut [[f64; 2]]| {
        context
            .lanes
            .keep_near_from(future, crate::DEFAULT_LANE_KEEPING_M, context.b_heading_rad);
    };
    if model.others.is_empty() {
        return model
            .scbg
            .generate_in_adjusted(&context.members[0], &courtesy, Some(&keep), &model.device)
            .map(|g| g.into_iter().map(Generated::from).collect())
            .map_err(invalid);
    }
    // Each member's kept futures, unmeasured: only the one kept is measured, by all of them.
    let per_member = each_member(model, |k, m| {
        m.scbg
            .choose_in_adjusted(&context.members[k], &courtesy, Some(&keep), &m.device)
            .map_err(invalid)
    })?;
    (0..courtesy.len())
        .map(|k| {
            let futures: Vec<&[[f64; 2]]> = per_member
                .iter()
                .map(|g| g[k].world_xy_m.as_slice())
                .collect();
            let chosen = per_member[medoid(&futures)][k].clone();
            let measured = courtesy_in(model, context, &chosen.world_xy_m)?;
            Ok(Generated {
                quantile: chosen.quantile,
                psi: chosen.psi,
                psi_low: chosen.psi_low,
                psi_high: chosen.psi_high,
                achieved_psi: measured.psi,
                a_expected_reward_conditional: measured.a_expected_reward_conditional,
                a_expected_reward_marginal: measured.a_expected_reward_marginal,
                world_xy_m: chosen.world_xy_m,
                step_secs: chosen.step_secs,
            })
        })
        .collect()
}

/// Checks that a context or basis of `members` members was made for `model` (the caches that
/// hold them are keyed without the model).
fn same_members(model: &LoadedScbg, members: usize) -> anyhow::Result<()> {
    let expected = model.members().count();
    anyhow::ensure!(
        members == expected,
        "a pair context of {members} member(s) used with a model of {expected}"
    );
    Ok(())
}

/// B's futures for each requested courtesy (a quantile in [0, 1] of the predicted range, or
/// an explicit ψ), starting at the scene's current step, in the world frame, kept in lane.
pub fn generate(
    model: &LoadedScbg,
    scene: &Scene,
    a: i64,
    b: i64,
    courtesy: &[Courtesy],
) -> anyhow::Result<Generation> {
    let context = pair_context(model, scene, a, b)?;
    let trajectories = generate_in(model, &context, courtesy)?;
    Ok(Generation {
        scenario_id: scene.scenario_id.clone(),
        a_id: a,
        b_id: b,
        current_step: scene.current_step,
        variant: model.checkpoint.variant,
        trajectories,
    })
}

/// B's future only (80 world-frame points after the scene's current step) at one courtesy:
/// what a closed-loop planner needs, without measuring the achieved ψ (see
/// `scbg_generator::Scbg::plan`), and before lane keeping: the closed loop keeps it in lane as
/// it keeps every plan, which makes it the future [`generate`] returns. An ensemble plans with
/// every member and follows the [`medoid`] of their raw plans ([`generate`] takes that of the
/// kept futures, so the two may choose different members).
pub fn plan(
    model: &LoadedScbg,
    scene: &Scene,
    a: i64,
    b: i64,
    courtesy: Courtesy,
) -> anyhow::Result<Vec<[f64; 2]>> {
    plan_from(model, &plan_basis(model, scene, a, b)?, courtesy)
}

/// The courtesy-free part of [`plan`] (`scbg_generator::Scbg::plan_basis`), one per member.
#[derive(Debug)]
pub struct PlanBasis(Vec<scbg_generator::PlanBasis>);

/// The courtesy-free part of [`plan`].
pub fn plan_basis(model: &LoadedScbg, scene: &Scene, a: i64, b: i64) -> anyhow::Result<PlanBasis> {
    per_member(
        model,
        scene,
        b,
        |m, prepared, window| m.scbg.plan_basis(prepared, window, a, b, &m.device),
        |basis, leaves| basis.drop_candidates(leaves),
    )
    .map(PlanBasis)
}

/// [`plan`] from its [`plan_basis`]: the same future.
pub fn plan_from(
    model: &LoadedScbg,
    basis: &PlanBasis,
    courtesy: Courtesy,
) -> anyhow::Result<Vec<[f64; 2]>> {
    same_members(model, basis.0.len())?;
    let mut plans = each_member(model, |k, m| {
        m.scbg
            .plan_from(&basis.0[k], courtesy.get(), &m.device)
            .map_err(invalid)
    })?;
    let futures: Vec<&[[f64; 2]]> = plans.iter().map(Vec::as_slice).collect();
    let chosen = medoid(&futures);
    Ok(plans.swap_remove(chosen))
}

/// ψ of a given world-frame future of B (80 points after the scene's current step) toward A,
/// with both expectations (paper eq. 2).
pub fn courtesy(
    model: &LoadedScbg,
    scene: &Scene,
    a: i64,
    b: i64,
    future_world: &[[f64; 2]],
) -> anyhow::Result<CourtesyOf> {
    courtesy_in(model, &pair_context(model, scene, a, b)?, future_world)
}

/// [`courtesy`] for a pair whose context is known ([`pair_context`]); an ensemble's is the
/// mean of its members' (each J_φ measures with its own predictor).
pub fn courtesy_in(
    model: &LoadedScbg,
    context: &PairContext,
    future_world: &[[f64; 2]],
) -> anyhow::Result<CourtesyOf> {
    same_members(model, context.members.len())?;
    let measured = each_member(model, |k, m| {
        m.scbg
            .courtesy_in(&context.members[k], future_world, &m.device)
            .map(|c| CourtesyOf {
                psi: c.psi,
                a_expected_reward_conditional: c.a_expected_reward_conditional,
                a_expected_reward_marginal: c.a_expected_reward_marginal,
            })
            .map_err(invalid)
    })?;
    if let [only] = measured[..] {
        return Ok(only);
    }
    let n = measured.len() as f32;
    let mean = |f: fn(&CourtesyOf) -> f32| measured.iter().map(f).sum::<f32>() / n;
    Ok(CourtesyOf {
        psi: mean(|c| c.psi),
        a_expected_reward_conditional: mean(|c| c.a_expected_reward_conditional),
        a_expected_reward_marginal: mean(|c| c.a_expected_reward_marginal),
    })
}

/// Draws the scene with B's generated futures (A and B highlighted) as a PNG.
pub fn render_generation(scene: &Scene, generation: &Generation, png: &Path) -> anyhow::Result<()> {
    let index = |id: i64| {
        scene.track_index(id).ok_or_else(|| {
            anyhow::Error::new(InvalidRequest(format!(
                "no track {id} in scenario {}",
                scene.scenario_id
            )))
        })
    };
    let pair = (index(generation.a_id)?, index(generation.b_id)?);
    let overlays = generation
        .trajectories
        .iter()
        .map(|g| {
            (
                format!("B q={:.1}", g.quantile),
                g.world_xy_m.iter().map(|p| (p[0], p[1])).collect(),
            )
        })
        .collect();
    scbg_plot::render_scene(
        scene,
        png,
        &scbg_plot::RenderOptions {
            size_px: 900,
            pair: Some(pair),
            overlays,
            title: format!("{}: B generated at quantiles", scene.scenario_id),
        },
    )?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;
    use scbg_scene::{Map, MapPoint, RoadEdge, RoadEdgeType};

    #[test]
    fn the_medoid_is_the_future_nearest_the_others() {
        let line = |y_m: f64| -> Vec<[f64; 2]> { (0..5).map(|k| [f64::from(k), y_m]).collect() };
        let (a, b, c) = (line(0.0), line(1.0), line(5.0));
        assert_eq!(medoid(&[&a]), 0);
        // Summed mean distances: a 6 m, b 5 m, c 9 m.
        assert_eq!(medoid(&[&a, &b, &c]), 1);
        assert_eq!(medoid(&[&c, &a, &b]), 2);
        // Two futures tie: the earlier member's.
        assert_eq!(medoid(&[&b, &a]), 0);
        assert_eq!(medoid(&[]), 0);
        // A future with a NaN point counts for none, though it lies between the others.
        let mut broken = line(2.5);
        broken[2][0] = f64::NAN;
        assert_eq!(medoid(&[&c, &b, &broken, &a]), 1);
    }

    #[test]
    fn a_future_beyond_the_road_edge_leaves_the_road() {
        let edge = |y_m: f64, forward: bool| RoadEdge {
            id: 1,
            edge_type: RoadEdgeType::Boundary,
            polyline: (0..=10)
                .map(|k| {
                    let x_m = 10.0 * f64::from(if forward { k } else { 10 - k });
                    MapPoint { x_m, y_m, z_m: 0.0 }
                })
                .collect(),
        };
        // A road between y = −4 and y = 4 (WOMD's side convention: the road on each edge's left).
        let scene = Scene {
            map: Map {
                road_edges: vec![edge(-4.0, true), edge(4.0, false)],
                ..Default::default()
            },
            ..Default::default()
        };
        let leaves = road_leaver(&scene, 2).unwrap();
        let along =
            |y: f64| -> Vec<[f64; 2]> { (0..8).map(|k| [10.0 * f64::from(k), y]).collect() };
        assert!(!leaves(&along(0.0)));
        assert!(!leaves(&along(3.5)));
        assert!(leaves(&along(4.5)));
        let mut drifting = along(0.0);
        drifting[7][1] = -5.0;
        assert!(leaves(&drifting));
        // No road edges: nothing to leave.
        assert!(road_leaver(&Scene::default(), 2).is_none());
    }
}
