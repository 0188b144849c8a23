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

use crate::audience::{STEP_SECS, audience_courtesy};
use crate::courtesy::{Courtesy, Policy};
use crate::data::Example;
use crate::eval::{generate_and_measure, predicted_ranges};
use crate::model::Generator;
use crate::range::{RangePredictor, psi_for_quantile, quantile_for_psi};
use crate::ranked::{measure_futures, ranked_choice};
use crate::tensors::to_vec;

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
        check_request(scene, a_id, b_id)?;
        let ctx = self.pair_context(scene, window, a_id, b_id, device)?;
        self.generate_in(&ctx, courtesy, device)
    }

    /// The pair's samples and the labels of B's logged and sampled futures, as training
    /// labelled them (E[r(Y_A) | x] from B's sampled futures with a fixed seed, toward the
    /// audience the generator was trained for); without `label`, the same samples and audience
    /// and no label at all ([`scbg_courtesy::label::unlabelled_role`], no forward).
    pub(crate) fn labelled_role(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        label: bool,
        device: &Device,
    ) -> Result<LabelledRole, GenerateError> {
        let (ia, ib) = check_request(scene, a_id, b_id)?;
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
                step_secs: STEP_SECS,
            })
            .collect())
    }
}

/// Checks a request (distinct tracks that exist): the track indices of A and B.
pub(crate) fn check_request(
    scene: &PreparedScene,
    a_id: i64,
    b_id: i64,
) -> Result<(usize, usize), GenerateError> {
    if a_id == b_id {
        return Err(GenerateError::SameTrack(a_id));
    }
    let index = |id: i64| {
        scene
            .track_index(id)
            .ok_or_else(|| GenerateError::NoSuchTrack(id, scene.scenario_id.clone()))
    };
    Ok((index(a_id)?, index(b_id)?))
}

/// Points in the frame of `pose`'s agent, in the world frame.
pub(crate) fn world_xy(pose: &scbg_scene::Pose2, xy: &[[f32; 2]]) -> Vec<[f64; 2]> {
    xy.iter()
        .map(|p| {
            let (x, y) = pose.world_from_agent(f64::from(p[0]), f64::from(p[1]));
            [x, y]
        })
        .collect()
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
        let (psi, e_cond) = audience_courtesy(
            &self.predictor,
            future,
            &[&ctx.example],
            1,
            self.labels.reward,
            device,
        );
        let (psi, e_cond) = (to_vec(psi)[0], to_vec(e_cond)[0]);
        Ok(CourtesyOf {
            psi,
            a_expected_reward_conditional: e_cond,
            a_expected_reward_marginal: e_marg,
        })
    }
}
