//! Inference: `generate(scene, a, b, quantile) → B's future in the world frame` (paper Sec.
//! III-E). The choice is the closed-loop plan's ([`Scbg::plan_from`]: the user's quantile
//! `q ∈ [0, 1]` becomes a ψ through the range predictor's 0.1 and 0.9 quantiles and the
//! generator turns ψ into B's future), and J_φ reports the courtesy the future actually
//! achieves.

use burn::tensor::Device;
use scbg_features::{PreparedScene, Window};
use serde::Serialize;

use crate::audience::{STEP_SECS, audience_courtesy};
use crate::courtesy::Courtesy;
use crate::data::{Example, marginal_embedding};
use crate::eval::predicted_ranges;
use crate::infer::{GenerateError, Scbg, world_xy};
use crate::plan::PlanBasis;
use crate::range::quantile_for_psi;
use crate::ranked::measure_futures;
use crate::tensors::to_vec;

/// Chosen futures as returned (world frame), and the same in B's frame (what J_φ measures).
type ChosenWithBFrame = (Vec<ChosenFuture>, Vec<Vec<[f32; 2]>>);

/// What every generation for one (scene, A, B) shares ([`Scbg::pair_context`]): the plan's
/// basis, the pair's example for J_φ and the predicted range of ψ.
#[derive(Debug, Clone)]
pub struct PairContext {
    basis: PlanBasis,
    example: Example,
    low: f32,
    high: f32,
}

impl PairContext {
    /// The predicted 0.1 and 0.9 quantiles of ψ.
    pub fn range(&self) -> (f32, f32) {
        (self.low, self.high)
    }

    /// [`PlanBasis::drop_candidates`] on the context's basis.
    pub fn drop_candidates(&mut self, leaves: impl Fn(&[[f64; 2]]) -> bool) -> usize {
        self.basis.drop_candidates(leaves)
    }
}

/// A change made to each chosen world-frame future before J_φ measures it
/// ([`Scbg::generate_in_adjusted`]).
pub type AdjustFuture<'a> = &'a dyn Fn(&mut [[f64; 2]]);

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
        let ctx = self.pair_context(scene, window, a_id, b_id, device)?;
        self.generate_in(&ctx, courtesy, device)
    }

    /// What every generation for one pair shares: the plan's basis ([`Scbg::plan_basis`]),
    /// the pair's samples with E[r(Y_A) | x] as training labelled it, and the predicted range
    /// of ψ. Computed once, a front end can keep it and generate at many courtesies for the
    /// cost of the choice and J_φ alone.
    pub fn pair_context(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        device: &Device,
    ) -> Result<PairContext, GenerateError> {
        let (basis, mut example) =
            self.basis_and_example(scene, window, a_id, b_id, true, device)?;
        let (low, high) = match basis.range() {
            Some(range) => range,
            None => {
                example.b_embedding = marginal_embedding(&self.predictor, &example.b, device);
                predicted_ranges(&self.range, &[&example], device)[0]
            }
        };
        // The labels live on in the basis where a choice needs them.
        example.futures_b.clear();
        example.psi.clear();
        Ok(PairContext {
            basis,
            example,
            low,
            high,
        })
    }

    /// B's futures for each requested courtesy of a pair whose context is known: the plan's
    /// choice ([`Scbg::plan_from`]), then J_φ of each future.
    pub fn generate_in(
        &self,
        ctx: &PairContext,
        courtesy: &[Courtesy],
        device: &Device,
    ) -> Result<Vec<Generated>, GenerateError> {
        self.generate_in_adjusted(ctx, courtesy, None, device)
    }

    /// [`Scbg::generate_in`] with each chosen future changed by `adjust` (world frame) before
    /// J_φ measures it, so that the ψ reported is that of the future returned. The runtime
    /// keeps futures in lane this way; the generator knows nothing of lanes.
    pub fn generate_in_adjusted(
        &self,
        ctx: &PairContext,
        courtesy: &[Courtesy],
        adjust: Option<AdjustFuture<'_>>,
        device: &Device,
    ) -> Result<Vec<Generated>, GenerateError> {
        let (chosen, futures_b) = self.chosen_in_adjusted(ctx, courtesy, adjust, device)?;
        let measured = measure_futures(
            &self.predictor,
            &[&ctx.example],
            std::slice::from_ref(&futures_b),
            self.labels.reward,
            device,
        );
        Ok(chosen
            .into_iter()
            .enumerate()
            .map(|(j, c)| Generated {
                quantile: c.quantile,
                psi: c.psi,
                psi_low: c.psi_low,
                psi_high: c.psi_high,
                achieved_psi: measured.psi[0][j],
                a_expected_reward_conditional: measured.e_cond[0][j],
                a_expected_reward_marginal: measured.e_marg[0],
                world_xy_m: c.world_xy_m,
                step_secs: c.step_secs,
            })
            .collect())
    }

    /// The futures [`Scbg::generate_in_adjusted`] returns, without J_φ's measure of them: for
    /// a caller that measures them otherwise (an ensemble measures only the future it keeps).
    pub fn choose_in_adjusted(
        &self,
        ctx: &PairContext,
        courtesy: &[Courtesy],
        adjust: Option<AdjustFuture<'_>>,
        device: &Device,
    ) -> Result<Vec<ChosenFuture>, GenerateError> {
        self.chosen_in_adjusted(ctx, courtesy, adjust, device)
            .map(|(chosen, _)| chosen)
    }

    /// The chosen futures, adjusted, and the same in B's frame (what J_φ measures).
    fn chosen_in_adjusted(
        &self,
        ctx: &PairContext,
        courtesy: &[Courtesy],
        adjust: Option<AdjustFuture<'_>>,
        device: &Device,
    ) -> Result<ChosenWithBFrame, GenerateError> {
        let (low, high) = (ctx.low, ctx.high);
        let mut choices = self.choose(&ctx.basis, courtesy, device)?;
        // The futures as returned (world frame); with `adjust`, J_φ measures them in B's frame.
        let pose = choices.b_pose;
        let mut world: Vec<Vec<[f64; 2]>> = choices
            .futures_b
            .iter()
            .map(|f| world_xy(&pose, f))
            .collect();
        if let Some(adjust) = adjust {
            for (future, world) in choices.futures_b.iter_mut().zip(&mut world) {
                adjust(world);
                *future = world
                    .iter()
                    .map(|p| {
                        let (x, y) = pose.agent_from_world(p[0], p[1]);
                        [x as f32, y as f32]
                    })
                    .collect();
            }
        }
        let chosen = courtesy
            .iter()
            .zip(world)
            .enumerate()
            .map(|(j, (c, world_xy_m))| ChosenFuture {
                quantile: match *c {
                    Courtesy::Quantile(q) => q,
                    Courtesy::Psi(p) => quantile_for_psi(p, low, high),
                },
                psi: choices.psi[j],
                psi_low: low,
                psi_high: high,
                world_xy_m,
                step_secs: STEP_SECS,
            })
            .collect();
        Ok((chosen, choices.futures_b))
    }
}

/// One future of B chosen for a courtesy, before J_φ measures it
/// ([`Scbg::choose_in_adjusted`]); the fields mean what [`Generated`]'s do.
#[derive(Debug, Clone, PartialEq)]
pub struct ChosenFuture {
    /// The quantile asked for, or the one an explicit ψ corresponds to.
    pub quantile: f32,
    /// The ψ the quantile maps to; with [`Policy::Ranked`] and a quantile, the chosen label.
    pub psi: f32,
    /// The predicted 0.1 quantile of ψ.
    pub psi_low: f32,
    /// The predicted 0.9 quantile.
    pub psi_high: f32,
    /// B's future, world frame, metres, at `step_secs` intervals after the current step.
    pub world_xy_m: Vec<[f64; 2]>,
    /// Time between points, seconds.
    pub step_secs: f32,
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
        self.courtesy_in(&ctx, future_world, device)
    }

    /// [`Self::courtesy_of`] for a pair whose context is known ([`Self::pair_context`]): one
    /// conditional forward of the predictor.
    pub fn courtesy_in(
        &self,
        ctx: &PairContext,
        future_world: &[[f64; 2]],
        device: &Device,
    ) -> Result<CourtesyOf, GenerateError> {
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
