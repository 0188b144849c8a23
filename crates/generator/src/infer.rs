//! Inference: `generate(scene, a, b, quantile) → B's future in the world frame` (paper Sec.
//! III-E). The user's quantile `q ∈ [0, 1]` becomes a ψ through the range predictor's 0.1 and
//! 0.9 quantiles ([`psi_for_quantile`]), the generator turns ψ into B's future, and J_φ reports
//! the courtesy the future actually achieves.

use burn::tensor::Device;
use rand::SeedableRng;
use scbg_courtesy::label::{LabelOptions, LabelledRole, label_built_role};
use scbg_features::{
    FeatureConfig, FeatureStats, PreparedScene, SampleBuilder, SampleError, Window,
};
use scbg_model::Multipath;
use serde::Serialize;

use crate::data::{Example, a_context, marginal_embedding};
use crate::eval::{generate_and_measure, predicted_ranges};
use crate::model::Generator;
use crate::range::{RangePredictor, psi_for_quantile, quantile_for_psi};
use crate::ranked::{measure_futures, ranked_choice};

/// The courtesy asked of a generated future.
#[derive(Debug, Clone, Copy, PartialEq, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Courtesy {
    /// A quantile in [0, 1] of the predicted range (0.1 and 0.9 are its ends).
    Quantile(f32),
    /// An explicit ψ (m/s for the default reward).
    Psi(f32),
}

/// How a [`Scbg`] turns a requested courtesy into B's future.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[serde(rename_all = "snake_case")]
#[cfg_attr(feature = "clap", derive(clap::ValueEnum))]
pub enum Policy {
    /// The learned generator g(x, ψ) (the paper).
    #[default]
    Generator,
    /// Sample and rank: B's sampled future whose ψ label has the requested rank, or is nearest
    /// the requested ψ (no generator).
    Ranked,
}

impl Policy {
    /// Both policies.
    pub const ALL: [Policy; 2] = [Policy::Generator, Policy::Ranked];

    /// The policy's name (`generator`, `ranked`).
    pub fn name(self) -> &'static str {
        match self {
            Self::Generator => "generator",
            Self::Ranked => "ranked",
        }
    }
}

impl std::str::FromStr for Policy {
    type Err = String;
    fn from_str(s: &str) -> Result<Self, String> {
        Self::ALL
            .into_iter()
            .find(|p| p.name() == s)
            .ok_or_else(|| format!("unknown policy {s:?} (generator or ranked)"))
    }
}

/// The trained models and the feature settings they were trained with, on one plain device.
#[derive(Debug)]
pub struct Scbg {
    /// The frozen predictor (encoder and J_φ).
    pub predictor: Multipath,
    /// g(x, ψ).
    pub generator: Generator,
    /// The range predictor (ψ quantiles 0.1 and 0.9 of a scene and pair).
    pub range: RangePredictor,
    /// Feature standardisation.
    pub stats: FeatureStats,
    /// Feature settings.
    pub features: FeatureConfig,
    /// Reward, number of sampled futures of B and marginal estimator: as in training, so ψ
    /// means the same thing.
    pub labels: LabelOptions,
    /// How a courtesy becomes B's future (the generator by default).
    pub policy: Policy,
}

/// What every generation for one (scene, A, B) shares ([`Scbg::pair_context`]).
#[derive(Debug, Clone)]
pub struct PairContext {
    example: Example,
    low: f32,
    high: f32,
    /// B's sampled futures (B's frame) and their ψ labels: the candidates of
    /// [`Policy::Ranked`].
    candidates: Vec<Vec<[f32; 2]>>,
    candidate_psi: Vec<f32>,
}

impl PairContext {
    /// The predicted 0.1 and 0.9 quantiles of ψ.
    pub fn range(&self) -> (f32, f32) {
        (self.low, self.high)
    }
}

/// Why a trajectory could not be generated.
#[derive(Debug, thiserror::Error)]
pub enum GenerateError {
    /// No track with this id (`.0`) in the scenario (`.1`, its id).
    #[error("no track with id {0} in scenario {1}")]
    NoSuchTrack(i64, String),
    /// A requested quantile outside `[0, 1]`.
    #[error("quantile {0} is outside [0, 1]")]
    Quantile(f32),
    /// A requested ψ that is NaN or infinite.
    #[error("ψ {0} is not a finite number")]
    Psi(f32),
    /// A and B are the same track (its id).
    #[error("A and B are the same track ({0})")]
    SameTrack(i64),
    /// [`Policy::Ranked`] without candidates: no sampled future of B with a finite ψ label
    /// (the labels keep `.0` sampled futures).
    #[error(
        "the ranked policy found no sampled future of B with a finite ψ label (the labels keep {0})"
    )]
    NoCandidates(usize),
    /// A given future of B is malformed (what is wrong).
    #[error("B's future: {0}")]
    Future(String),
    /// The sample of A or B could not be built (e.g. the track is not valid at the window's
    /// current step).
    #[error("track {id}: {error}")]
    Sample {
        /// The track id.
        id: i64,
        /// Why its sample could not be built.
        error: SampleError,
    },
}

/// One generated future of B.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct Generated {
    /// The quantile asked for, or the one an explicit ψ corresponds to (linear between the
    /// predicted 0.1 and 0.9 quantiles, extended beyond them).
    pub quantile: f32,
    /// The ψ the quantile maps to (m/s for the default reward); with [`Policy::Ranked`] and a
    /// quantile, the label of the chosen sampled future.
    pub psi: f32,
    /// The predicted 0.1 quantile of ψ for this scene and pair.
    pub psi_low: f32,
    /// The predicted 0.9 quantile.
    pub psi_high: f32,
    /// J_φ of the generated future: what the predictor expects it does to A.
    pub achieved_psi: f32,
    /// E[r(Y_A) | x, ŷ_B] (toward the model's audience: the weighted sum over B's neighbours
    /// for a model labelled with [`scbg_courtesy::Audience::Neighbours`]).
    pub a_expected_reward_conditional: f32,
    /// E[r(Y_A) | x].
    pub a_expected_reward_marginal: f32,
    /// B's future, world frame, metres, at `step_secs` intervals after the current step.
    pub world_xy_m: Vec<[f64; 2]>,
    /// Time between points, seconds.
    pub step_secs: f32,
}

impl Scbg {
    /// B's futures for each requested courtesy, for the pair (A = `a_id`, B = `b_id`) at
    /// `window`: [`Scbg::pair_context`] then [`Scbg::generate_in`].
    pub fn generate(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        courtesy: &[Courtesy],
        device: &Device,
    ) -> Result<Vec<Generated>, GenerateError> {
        check_request(scene, a_id, b_id, courtesy)?;
        let ctx = self.pair_context(scene, window, a_id, b_id, device)?;
        self.generate_in(&ctx, courtesy, device)
    }

    /// The pair's samples and the labels of B's logged and sampled futures, as training
    /// labelled them (E[r(Y_A) | x] from B's sampled futures with a fixed seed, toward the
    /// audience the generator was trained for); without `label`, the same samples and audience
    /// and no label at all ([`scbg_courtesy::label::unlabelled_role`], no forward).
    fn labelled_role(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        label: bool,
        device: &Device,
    ) -> Result<LabelledRole, GenerateError> {
        let (ia, ib) = check_request(scene, a_id, b_id, &[])?;
        let mut builder = SampleBuilder::new(scene, &self.features);
        let mut a = builder
            .sample(window, ia, Some(ib))
            .map_err(|error| GenerateError::Sample { id: a_id, error })?;
        let mut b = builder
            .sample(window, ib, None)
            .map_err(|error| GenerateError::Sample { id: b_id, error })?;
        self.stats.normalize(&mut a);
        self.stats.normalize(&mut b);
        if !label {
            return Ok(scbg_courtesy::label::unlabelled_role(
                &mut builder,
                &self.stats,
                window,
                (ia, a),
                (ib, b),
                self.labels.audience,
            ));
        }
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(0x5cb6);
        Ok(label_built_role(
            &self.predictor,
            &mut builder,
            &self.stats,
            window,
            (ia, a),
            (ib, b),
            self.labels,
            &mut rng,
            device,
        ))
    }

    /// What every generation for one pair shares (its samples, B's frozen embedding,
    /// E[r(Y_A) | x] and the predicted range of ψ): computed once, a front end can keep it
    /// and generate at many courtesies for the cost of the generator and J_φ alone.
    pub fn pair_context(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        device: &Device,
    ) -> Result<PairContext, GenerateError> {
        let role = self.labelled_role(scene, window, a_id, b_id, true, device)?;
        let mut example =
            Example::from_role(scene.scenario_id.clone(), role, &self.predictor, device);
        // Index 0 is B's logged future (whatever the scene holds after its current step):
        // never a candidate.
        let candidates = example.futures_b.split_off(1.min(example.futures_b.len()));
        let candidate_psi = example.psi.split_off(1.min(example.psi.len()));
        example.futures_b.clear();
        example.psi.clear();
        if self.generator.a_context_width == 0 {
            example.a_context.clear();
        }
        let (low, high) = predicted_ranges(&self.range, &[&example], device)[0];
        Ok(PairContext {
            example,
            low,
            high,
            candidates,
            candidate_psi,
        })
    }

    /// B's futures for each requested courtesy of a pair whose context is known.
    pub fn generate_in(
        &self,
        ctx: &PairContext,
        courtesy: &[Courtesy],
        device: &Device,
    ) -> Result<Vec<Generated>, GenerateError> {
        check_courtesy(courtesy)?;
        let (example, low, high) = (&ctx.example, ctx.low, ctx.high);
        let (mut psi, quantiles): (Vec<f32>, Vec<f32>) = courtesy
            .iter()
            .map(|c| match *c {
                Courtesy::Quantile(q) => (psi_for_quantile(q, low, high), q),
                Courtesy::Psi(p) => (p, quantile_for_psi(p, low, high)),
            })
            .unzip();
        let measured = match self.policy {
            Policy::Generator => generate_and_measure(
                &self.generator,
                &self.predictor,
                &[example],
                std::slice::from_ref(&psi),
                self.labels.reward,
                device,
            ),
            Policy::Ranked => {
                let chosen = courtesy
                    .iter()
                    .map(|&c| ranked_choice(&ctx.candidate_psi, c))
                    .collect::<Option<Vec<usize>>>()
                    .ok_or(GenerateError::NoCandidates(self.labels.labelled_samples()))?;
                for (p, (c, &k)) in psi.iter_mut().zip(courtesy.iter().zip(&chosen)) {
                    if let Courtesy::Quantile(_) = c {
                        // The ψ the rank stands for: the chosen candidate's label.
                        *p = ctx.candidate_psi[k];
                    }
                }
                let futures: Vec<Vec<[f32; 2]>> =
                    chosen.iter().map(|&k| ctx.candidates[k].clone()).collect();
                measure_futures(
                    &self.predictor,
                    &[example],
                    &[futures],
                    self.labels.reward,
                    device,
                )
            }
        };
        let pose = example.b.world_from_agent;
        Ok(quantiles
            .iter()
            .enumerate()
            .map(|(j, &q)| Generated {
                quantile: q,
                psi: psi[j],
                psi_low: low,
                psi_high: high,
                achieved_psi: measured.psi[0][j],
                a_expected_reward_conditional: measured.e_cond[0][j],
                a_expected_reward_marginal: measured.e_marg[0],
                world_xy_m: world_xy(&pose, &measured.futures_b[0][j]),
                step_secs: crate::train::STEP_SECS,
            })
            .collect())
    }
}

/// Quantiles in [0, 1], finite ψ.
fn check_courtesy(courtesy: &[Courtesy]) -> Result<(), GenerateError> {
    for c in courtesy {
        match *c {
            Courtesy::Quantile(q) if !(0.0..=1.0).contains(&q) => {
                return Err(GenerateError::Quantile(q));
            }
            Courtesy::Psi(p) if !p.is_finite() => return Err(GenerateError::Psi(p)),
            _ => {}
        }
    }
    Ok(())
}

/// Checks a request (distinct tracks that exist, quantiles in [0, 1], finite ψ): the track
/// indices of A and B.
fn check_request(
    scene: &PreparedScene,
    a_id: i64,
    b_id: i64,
    courtesy: &[Courtesy],
) -> Result<(usize, usize), GenerateError> {
    if a_id == b_id {
        return Err(GenerateError::SameTrack(a_id));
    }
    check_courtesy(courtesy)?;
    let index = |id: i64| {
        scene
            .track_index(id)
            .ok_or_else(|| GenerateError::NoSuchTrack(id, scene.scenario_id.clone()))
    };
    Ok((index(a_id)?, index(b_id)?))
}

/// Points in the frame of `pose`'s agent, in the world frame.
fn world_xy(pose: &scbg_scene::Pose2, xy: &[[f32; 2]]) -> Vec<[f64; 2]> {
    xy.iter()
        .map(|p| {
            let (x, y) = pose.world_from_agent(f64::from(p[0]), f64::from(p[1]));
            [x, y]
        })
        .collect()
}

/// What a closed-loop plan of B toward A shares across requested courtesies
/// ([`Scbg::plan_basis`]): everything but the choice. With [`Policy::Generator`], B's
/// embedding, pose, choices (scored by J_φ) and predicted range of ψ; with [`Policy::Ranked`],
/// B's labelled sampled futures. Rollouts of one scene at different quantiles start from the
/// same view, so their first plans can share it ([`Scbg::plan_from`]).
#[derive(Debug, Clone)]
pub struct PlanBasis(Basis);

#[derive(Debug, Clone)]
enum Basis {
    Generator(Box<GeneratorBasis>),
    Ranked {
        /// ψ labels of B's sampled futures (the logged one left out).
        psi: Vec<f32>,
        /// The sampled futures in A's frame (index 0: B's logged future, not a candidate).
        futures_in_a: Vec<Vec<[f32; 2]>>,
        a_pose: scbg_scene::Pose2,
        b_pose: scbg_scene::Pose2,
    },
}

#[derive(Debug, Clone)]
struct GeneratorBasis {
    embedding: burn::tensor::Tensor<2>,
    pose: scbg_scene::Pose2,
    modes: Option<crate::BModes>,
    low: f32,
    high: f32,
}

impl Scbg {
    /// B's future only (world frame, 80 points at 10 Hz), for closed-loop planning: the
    /// encoder, the range predictor and the generator, without J_φ's measurement of the
    /// achieved ψ (which [`Scbg::generate`] adds); with [`Policy::Ranked`], the labelling of
    /// B's sampled futures and the choice among them. A must be a track valid at the window's
    /// current step; the same future as `generate` gives for the same request.
    /// [`Scbg::plan_basis`] then [`Scbg::plan_from`].
    pub fn plan(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        courtesy: Courtesy,
        device: &Device,
    ) -> Result<Vec<[f64; 2]>, GenerateError> {
        // Checked before the basis is paid for (`plan_from` checks again, for its own callers).
        check_courtesy(&[courtesy])?;
        let basis = self.plan_basis(scene, window, a_id, b_id, device)?;
        self.plan_from(&basis, courtesy, device)
    }

    /// The part of [`Scbg::plan`] that does not depend on the requested courtesy: all of its
    /// cost but the choice (the selector's MLPs, or a sort of the labels).
    pub fn plan_basis(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        device: &Device,
    ) -> Result<PlanBasis, GenerateError> {
        let (ia, ib) = check_request(scene, a_id, b_id, &[])?;
        let now = window.current_step;
        if !scene.tracks[ia].valid_at(now as isize) {
            return Err(GenerateError::Sample {
                id: a_id,
                error: SampleError::TargetInvalidNow {
                    track_id: a_id,
                    step: now,
                },
            });
        }
        if self.policy == Policy::Ranked {
            // The labels alone, no embedding of B and no range: the choice `generate_in` makes
            // (its candidates are these futures, in B's frame).
            let role = self.labelled_role(scene, window, a_id, b_id, true, device)?;
            return Ok(PlanBasis(Basis::Ranked {
                psi: role.labels.psi.get(1..).unwrap_or_default().to_vec(),
                futures_in_a: role.labels.futures_in_a,
                a_pose: role.a.world_from_agent,
                b_pose: role.b.world_from_agent,
            }));
        }
        // B's embedding (and A's context when the generator is told who A is), B's pose, and
        // the choices of a mode-selecting generator (scored by J_φ, from the pair's example,
        // for a generator scoring its modes' courtesy).
        let (embedding, pose, modes) = if self.generator.scores_mode_courtesy() {
            // A's and B's samples and B's audience, no label: the modes' courtesy is measured
            // against their own mean, so no E[r(Y_A) | x] from B's samples is needed.
            let role = self.labelled_role(scene, window, a_id, b_id, false, device)?;
            // B's and A's scenes in one encoder pass (the framework's cost per operation,
            // most of a plan's, paid once for both): B's marginal embedding, then A's scene
            // for J_φ of B's modes below.
            let batch = scbg_model::Batch::for_mode(
                &[&role.b, &role.a],
                scbg_model::Mode::Marginal,
                device,
            );
            let encoded = self.predictor.encode_scene(&batch);
            let b_embedding =
                crate::eval::to_vec(self.predictor.encode_marginal(encoded.clone().narrow(0, 1)));
            let a_lane_path = batch
                .lane_path
                .as_ref()
                .map(|(p, m)| (p.clone().narrow(0, 1, 1), m.clone().narrow(0, 1, 1)));
            let mut example =
                Example::from_role_embedded(scene.scenario_id.clone(), role, b_embedding);
            if self.generator.a_context_width == 0 {
                example.a_context.clear();
            }
            let embedding = crate::stored_embeddings(&[&example], device);
            let modes = crate::data::b_modes_with(
                &self.generator,
                &self.predictor,
                &[&example],
                self.labels.reward,
                Some((encoded.narrow(1, 1), a_lane_path)),
                device,
            );
            (embedding, example.b.world_from_agent, modes)
        } else {
            let mut b = SampleBuilder::new(scene, &self.features)
                .sample(window, ib, None)
                .map_err(|error| GenerateError::Sample { id: b_id, error })?;
            self.stats.normalize(&mut b);
            let mut embedding = marginal_embedding(&self.predictor, &b, device);
            if self.generator.a_context_width > 0 {
                // A's pose and velocity at the current step, from its track (no sample needed).
                let t = &scene.tracks[ia];
                let o = scene.origin_xy_m;
                let a_pose = scbg_scene::Pose2::new(
                    f64::from(t.x_m[now]) + o[0],
                    f64::from(t.y_m[now]) + o[1],
                    f64::from(t.heading_rad[now]),
                );
                let v = [f64::from(t.vx_mps[now]), f64::from(t.vy_mps[now])];
                embedding.extend(a_context(a_pose, v, b.world_from_agent));
            }
            let e = embedding.len();
            let embedding = burn::tensor::Tensor::from_data(
                burn::tensor::TensorData::new(embedding, [1, e]),
                device,
            );
            let modes = self.generator.selects_modes().then(|| {
                let b_width = embedding.dims()[1] - self.generator.a_context_width;
                self.generator.candidates_of(
                    crate::b_modes_of(&self.predictor, embedding.clone().narrow(1, 0, b_width)),
                    &[crate::lane_path_points(&b)],
                )
            });
            (embedding, b.world_from_agent, modes)
        };
        let (low, high) = self.range.forward(embedding.clone());
        Ok(PlanBasis(Basis::Generator(Box::new(GeneratorBasis {
            embedding,
            pose,
            modes,
            low: crate::eval::to_vec(low)[0],
            high: crate::eval::to_vec(high)[0],
        }))))
    }

    /// B's future (world frame) for `courtesy` from a [`Scbg::plan_basis`] of this model: the
    /// same points as [`Scbg::plan`] gives for the same scene and request.
    pub fn plan_from(
        &self,
        basis: &PlanBasis,
        courtesy: Courtesy,
        device: &Device,
    ) -> Result<Vec<[f64; 2]>, GenerateError> {
        check_courtesy(&[courtesy])?;
        match &basis.0 {
            Basis::Ranked {
                psi,
                futures_in_a,
                a_pose,
                b_pose,
            } => {
                let k = ranked_choice(psi, courtesy)
                    .ok_or(GenerateError::NoCandidates(self.labels.labelled_samples()))?;
                // Through B's frame, as `generate_in`'s candidates are: the same numbers.
                let in_b = scbg_courtesy::label::change_frame(&futures_in_a[1 + k], a_pose, b_pose);
                Ok(world_xy(b_pose, &in_b))
            }
            Basis::Generator(g) => {
                let GeneratorBasis {
                    embedding,
                    pose,
                    modes,
                    low,
                    high,
                } = g.as_ref();
                let psi = match courtesy {
                    Courtesy::Psi(p) => p,
                    Courtesy::Quantile(q) => psi_for_quantile(q, *low, *high),
                };
                let future = self.generator.forward(
                    embedding.clone(),
                    burn::tensor::Tensor::from_data(
                        burn::tensor::TensorData::new(vec![psi], [1]),
                        device,
                    ),
                    modes.clone(),
                );
                let xy: Vec<[f32; 2]> = crate::eval::to_vec(future)
                    .chunks_exact(2)
                    .map(|p| [p[0], p[1]])
                    .collect();
                Ok(world_xy(pose, &xy))
            }
        }
    }
}

/// ψ of a given future of B (paper eq. 2), as `scbg generate` reports it for its own futures.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct CourtesyOf {
    /// ψ = E[r(Y_A) | x, y_B] − E[r(Y_A) | x].
    pub psi: f32,
    /// E[r(Y_A) | x, y_B] (toward the model's audience, as [`Generated`]).
    pub a_expected_reward_conditional: f32,
    /// E[r(Y_A) | x], estimated as in the labels.
    pub a_expected_reward_marginal: f32,
}

impl Scbg {
    /// ψ of `future_world` (B's world-frame positions at the 80 steps after the window's
    /// current step) toward A.
    pub fn courtesy_of(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        future_world: &[[f64; 2]],
        device: &Device,
    ) -> Result<CourtesyOf, GenerateError> {
        // The same samples and E[r(Y_A) | x] as every generation for this pair.
        let ctx = self.pair_context(scene, window, a_id, b_id, device)?;
        let (a, e_marg) = (&ctx.example.a, ctx.example.e_marg);
        let t = a.condition_future_valid.len();
        if future_world.len() != t {
            return Err(GenerateError::Future(format!(
                "{} points, expected {t}",
                future_world.len()
            )));
        }
        if let Some(k) = future_world
            .iter()
            .position(|p| !(p[0].is_finite() && p[1].is_finite()))
        {
            return Err(GenerateError::Future(format!("point {k} is not finite")));
        }
        // B's frame, then J_φ toward the audience exactly as for a generated future.
        let pose = ctx.example.b.world_from_agent;
        let xy: Vec<f32> = future_world
            .iter()
            .flat_map(|p| {
                let (x, y) = pose.agent_from_world(p[0], p[1]);
                [x as f32, y as f32]
            })
            .collect();
        let future = burn::tensor::Tensor::<3>::from_data(
            burn::tensor::TensorData::new(xy, [1, t, 2]),
            device,
        );
        let (psi, e_cond) = crate::train::audience_courtesy(
            &self.predictor,
            future,
            &[&ctx.example],
            1,
            self.labels.reward,
            device,
        );
        let (psi, e_cond) = (crate::eval::to_vec(psi)[0], crate::eval::to_vec(e_cond)[0]);
        Ok(CourtesyOf {
            psi,
            a_expected_reward_conditional: e_cond,
            a_expected_reward_marginal: e_marg,
        })
    }
}
