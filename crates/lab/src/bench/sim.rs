//! `scbg bench sim`: the closed loop's cost on one core.

use std::time::Instant;

use anyhow::Context;

use super::run_in_pool;

/// `scbg bench sim`: closed-loop cost on one core.
#[derive(Debug, Clone, PartialEq, serde::Serialize)]
pub struct SimBench {
    /// Scenes simulated (synthetic, seed 0, one per family in turn).
    pub scenes: usize,
    /// Steps between plans.
    pub replan_every: usize,
    /// What drives the agent: `generator` or `ranked` (the model's [`scbg_generator::Policy`]).
    pub policy: &'static str,
    /// One 80-step rollout with one controlled agent (B at quantile 0.5, driven by
    /// [`Self::policy`]), A and the others reactive (the synthetic rule): best and mean over
    /// the scenes, ms.
    pub rollout_ms_best: f64,
    /// Mean, ms.
    pub rollout_ms_mean: f64,
    /// The same rollout with B replaying its log (no generator): the world's share, ms.
    pub world_only_ms_mean: f64,
    /// WOSAC metrics of one scenario × 32 scbg rollouts: best and mean, ms.
    pub wosac_ms_best: f64,
    /// Mean, ms.
    pub wosac_ms_mean: f64,
    /// On the shared genuine WOMD scenario (when present): its agents, and the mean time of
    /// one rollout (B = its first track to predict at quantile 0.5, A = the SDC, everyone else
    /// IDM along the logged paths), ms.
    pub real: Option<(usize, f64)>,
}

impl SimBench {
    /// Human-readable lines.
    pub fn to_text(&self) -> String {
        format!(
            "closed loop, 1 thread, {} synthetic scenes, re-plan every {} steps\n\
             one 80-step rollout, 1 agent driven by the {}: best {:.2} ms, mean {:.2} ms (target ≤ 20 ms for the generator re-planning every 10 steps)\n\
             world only (B replays its log):        mean {:.2} ms\n\
             WOSAC metrics, 1 scenario × 32 rollouts: best {:.1} ms, mean {:.1} ms (target ≤ 1000 ms){}",
            self.scenes,
            self.replan_every,
            match self.policy {
                "ranked" => "ranked policy",
                _ => "generator",
            },
            self.rollout_ms_best,
            self.rollout_ms_mean,
            self.world_only_ms_mean,
            self.wosac_ms_best,
            self.wosac_ms_mean,
            self.real.map_or(String::new(), |(n, ms)| format!(
                "\ngenuine WOMD scenario ({n} agents, IDM world): one rollout, mean {ms:.2} ms"
            ))
        )
    }
}

/// Times closed-loop rollouts and their WOSAC metrics with `model` on one thread, its policy
/// re-planning every `replan_every` steps (`None`: its default cadence,
/// [`scbg::sim::default_replan_every`]).
pub fn sim(
    model: &crate::generator::LoadedScbg,
    scenes: usize,
    replan_every: Option<usize>,
) -> anyhow::Result<SimBench> {
    use scbg::sim::{ControlledAgent, OthersMode, rollout, rollout_quantiles, wosac_rollouts};
    run_in_pool(1, || {
        let config = scbg_sim::SimConfig {
            others: OthersMode::Reactive,
            replan_every: replan_every
                .unwrap_or_else(|| scbg::sim::default_replan_every(model.scbg.policy)),
            ..scbg_sim::SimConfig::default()
        };
        let scenes = scenes.max(1);
        let (mut gen_ms, mut world_ms, mut wosac_ms) = (Vec::new(), Vec::new(), Vec::new());
        for k in 0..scenes {
            let g = scbg_synth::generate(0, k as u64, &scbg_synth::Family::DEFAULT);
            let (scene, truth) = (g.scene, g.truth);
            let controlled = |q: f32| {
                [ControlledAgent::new(
                    truth.b_id,
                    scbg::Courtesy::quantile(q).expect("a rollout quantile is in [0, 1]"),
                )]
            };
            // Warm-up on the first scene (allocations, lazily built tables).
            if k == 0 {
                rollout(
                    model,
                    &scene,
                    Some(truth.a_id),
                    &controlled(0.5),
                    config,
                    Some(&truth),
                )?;
            }
            let t = Instant::now();
            rollout(
                model,
                &scene,
                Some(truth.a_id),
                &controlled(0.5),
                config,
                Some(&truth),
            )?;
            gen_ms.push(t.elapsed().as_secs_f64() * 1e3);
            // The world alone: B follows its log through the same loop.
            let t = Instant::now();
            let mut sim = scbg::sim::start(&scene, Some(truth.a_id), &[], config, Some(&truth))?;
            struct Idle;
            impl scbg_sim::Planner for Idle {
                fn plan(
                    &mut self,
                    _: &scbg_scene::Scene,
                    id: i64,
                ) -> Result<Vec<[f64; 2]>, scbg_sim::PlanError> {
                    Err(scbg_sim::PlanError(format!("{id} is not controlled")))
                }
            }
            sim.run(&mut Idle)?;
            world_ms.push(t.elapsed().as_secs_f64() * 1e3);
            if k < 3 {
                let rolled = rollout_quantiles(0.5, 32, 0.2)
                    .into_iter()
                    .map(|q| {
                        rollout(
                            model,
                            &scene,
                            Some(truth.a_id),
                            &controlled(q),
                            config,
                            Some(&truth),
                        )
                    })
                    .collect::<anyhow::Result<Vec<_>>>()?;
                let r = wosac_rollouts(&scene, &rolled);
                let t = Instant::now();
                scbg_metrics::wosac::scenario_metrics(
                    &scene,
                    &r,
                    scbg_metrics::wosac::WosacConfig::V2025,
                )?;
                wosac_ms.push(t.elapsed().as_secs_f64() * 1e3);
            }
        }
        let best = |v: &[f64]| v.iter().copied().fold(f64::INFINITY, f64::min);
        let mean = |v: &[f64]| v.iter().sum::<f64>() / v.len() as f64;
        let real = match scbg_womd::fixtures::real_data_dir() {
            None => None,
            Some(dir) => {
                let file = dir.join("womd/motion_data_one_scenario.tfrecord");
                let womd = scbg_womd::WomdFile::open(&file)?;
                let scene = womd
                    .scenes()
                    .next()
                    .with_context(|| format!("{}: no scenario", file.display()))??;
                let a = scene.sdc_track_index.map(|i| scene.tracks[i].id);
                let b = scene
                    .tracks_to_predict
                    .iter()
                    .map(|t| scene.tracks[t.track_index].id)
                    .find(|&id| Some(id) != a)
                    .context("the genuine scenario has no track to predict")?;
                let controlled = [ControlledAgent::new(b, scbg::Courtesy::quantile(0.5)?)];
                rollout(model, &scene, a, &controlled, config, None)?;
                let mut times = Vec::new();
                for _ in 0..5 {
                    let t = Instant::now();
                    rollout(model, &scene, a, &controlled, config, None)?;
                    times.push(t.elapsed().as_secs_f64() * 1e3);
                }
                Some((scene.tracks.len(), mean(&times)))
            }
        };
        Ok(SimBench {
            real,
            scenes,
            replan_every: config.replan_every,
            policy: model.scbg.policy.name(),
            rollout_ms_best: best(&gen_ms),
            rollout_ms_mean: mean(&gen_ms),
            world_only_ms_mean: mean(&world_ms),
            wosac_ms_best: best(&wosac_ms),
            wosac_ms_mean: mean(&wosac_ms),
        })
    })?
}
