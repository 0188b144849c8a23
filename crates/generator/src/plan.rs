//! Closed-loop planning: B's future toward A for a requested courtesy, without J_φ's
//! measurement of the achieved ψ. [`Scbg::plan_basis`] computes what every courtesy shares
//! once, [`Scbg::plan_from`] makes the choice.

use burn::tensor::Device;
use scbg_features::{PreparedScene, SampleBuilder, SampleError, Window, lane_path_points};

use crate::candidates::{b_modes_of, b_modes_with};
use crate::courtesy::{Courtesy, Policy};
use crate::data::{Example, a_context, marginal_embedding};
use crate::infer::{GenerateError, Scbg, check_request, world_xy};
use crate::modes::BModes;
use crate::range::{psi_for_quantile, stored_embeddings};
use crate::ranked::ranked_choice;
use crate::tensors::to_vec;

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
    modes: Option<BModes>,
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
        let (ia, ib) = check_request(scene, a_id, b_id)?;
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
            let b_embedding = to_vec(self.predictor.encode_marginal(encoded.clone().narrow(0, 1)));
            let a_lane_path = batch
                .lane_path
                .as_ref()
                .map(|(p, m)| (p.clone().narrow(0, 1, 1), m.clone().narrow(0, 1, 1)));
            let mut example =
                Example::from_role_embedded(scene.scenario_id.clone(), role, b_embedding);
            if self.generator.a_context_width == 0 {
                example.a_context.clear();
            }
            let embedding = stored_embeddings(&[&example], device);
            let modes = b_modes_with(
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
                    b_modes_of(&self.predictor, embedding.clone().narrow(1, 0, b_width)),
                    &[lane_path_points(&b)],
                )
            });
            (embedding, b.world_from_agent, modes)
        };
        let (low, high) = self.range.forward(embedding.clone());
        Ok(PlanBasis(Basis::Generator(Box::new(GeneratorBasis {
            embedding,
            pose,
            modes,
            low: to_vec(low)[0],
            high: to_vec(high)[0],
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
                let xy: Vec<[f32; 2]> = to_vec(future)
                    .chunks_exact(2)
                    .map(|p| [p[0], p[1]])
                    .collect();
                Ok(world_xy(pose, &xy))
            }
        }
    }
}
