//! The one inference path: B's future toward A for a requested courtesy. [`Scbg::plan_basis`]
//! computes what every courtesy shares once, [`Scbg::plan_from`] makes the choice; the
//! open-loop [`Scbg::generate`] is the same choice followed by J_φ's measurement of the
//! achieved ψ ([`crate::infer`]).

use burn::tensor::{Device, Tensor, TensorData};
use scbg_courtesy::label::{LabelledRole, change_frame};
use scbg_features::{PreparedScene, SampleError, Window};

use crate::candidates::b_modes_with;
use crate::courtesy::{Courtesy, Policy};
use crate::data::Example;
use crate::infer::{GenerateError, Scbg, check_request, world_xy};
use crate::modes::BModes;
use crate::range::{psi_for_quantile, stored_embeddings};
use crate::ranked::ranked_choice;
use crate::tensors::{repeat_rows, to_vec};

/// What a plan of B toward A shares across requested courtesies ([`Scbg::plan_basis`]):
/// everything but the choice. With [`Policy::Generator`], B's embedding, pose, candidates
/// (scored by J_φ) and predicted range of ψ; with [`Policy::Ranked`], B's labelled sampled
/// futures. Rollouts of one scene at different quantiles start from the same view, so their
/// first plans can share it ([`Scbg::plan_from`]).
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
    embedding: Tensor<2>,
    pose: scbg_scene::Pose2,
    modes: BModes,
    low: f32,
    high: f32,
}

impl PlanBasis {
    /// The predicted 0.1 and 0.9 quantiles of ψ, when the basis holds them (the generator's).
    pub(crate) fn range(&self) -> Option<(f32, f32)> {
        match &self.0 {
            Basis::Generator(g) => Some((g.low, g.high)),
            Basis::Ranked { .. } => None,
        }
    }

    /// Takes sample and rank's candidates that `leaves` rejects (given each candidate's
    /// world-frame future) out of the choice: their labels become NaN, which no request
    /// chooses, and the ranks of a quantile count the rest. A front end that knows the road
    /// passes "leaves the road" here. When `leaves` would reject every candidate, none is
    /// taken out. Returns how many were; the generator's basis has no candidates to take
    /// out (0).
    pub fn drop_candidates(&mut self, leaves: impl Fn(&[[f64; 2]]) -> bool) -> usize {
        let Basis::Ranked {
            psi,
            futures_in_a,
            a_pose,
            b_pose,
        } = &mut self.0
        else {
            return 0;
        };
        // Each candidate as the choice gives it ([`Scbg::choose`], [`Scbg::plan_from`]).
        let world =
            |k: usize| world_xy(b_pose, &change_frame(&futures_in_a[1 + k], a_pose, b_pose));
        let dropped: Vec<usize> = (0..psi.len())
            .filter(|&k| !psi[k].is_nan() && leaves(&world(k)))
            .collect();
        if dropped.len() == psi.iter().filter(|v| !v.is_nan()).count() {
            return 0;
        }
        for &k in &dropped {
            psi[k] = f32::NAN;
        }
        dropped.len()
    }
}

/// B's futures (B's frame) for requested courtesies, and the ψ each stands for
/// ([`Scbg::choose`]).
pub(crate) struct Choices {
    /// The requested ψ, or with [`Policy::Ranked`] and a quantile the chosen future's label.
    pub psi: Vec<f32>,
    /// `[courtesy][T]` B's futures in B's frame.
    pub futures_b: Vec<Vec<[f32; 2]>>,
    /// B's frame.
    pub b_pose: scbg_scene::Pose2,
}

impl Scbg {
    /// B's future only (world frame, 80 points at 10 Hz), for closed-loop planning:
    /// [`Scbg::plan_basis`] then [`Scbg::plan_from`]. A must be a track valid at the window's
    /// current step. [`Scbg::generate`] makes the same choice and measures it.
    pub fn plan(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        courtesy: Courtesy,
        device: &Device,
    ) -> Result<Vec<[f64; 2]>, GenerateError> {
        let basis = self.plan_basis(scene, window, a_id, b_id, device)?;
        self.plan_from(&basis, courtesy, device)
    }

    /// The part of [`Scbg::plan`] that does not depend on the requested courtesy: all of its
    /// cost but the choice (the selector's MLPs, or a sort of the labels). The generator
    /// needs A's and B's samples and no label of B's sampled futures (its candidates' courtesy
    /// is measured against their own mean); sample and rank needs the labels.
    pub fn plan_basis(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        device: &Device,
    ) -> Result<PlanBasis, GenerateError> {
        let label = self.policy == Policy::Ranked;
        Ok(self
            .basis_and_example(scene, window, a_id, b_id, label, device)?
            .0)
    }

    /// The plan's basis and the pair's example (A's and B's samples, B's audience and, with
    /// `label`, the labels of B's futures and E[r(Y_A) | x], which J_φ's measurement of a
    /// generated future needs).
    pub(crate) fn basis_and_example(
        &self,
        scene: &PreparedScene,
        window: &Window,
        a_id: i64,
        b_id: i64,
        label: bool,
        device: &Device,
    ) -> Result<(PlanBasis, Example), GenerateError> {
        let (ia, _) = check_request(scene, a_id, b_id)?;
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
        let role = self.labelled_role(scene, window, a_id, b_id, label, device)?;
        let id = scene.scenario_id.clone();
        Ok(match self.policy {
            Policy::Ranked => {
                let basis = Basis::Ranked {
                    psi: role.labels.psi.get(1..).unwrap_or_default().to_vec(),
                    futures_in_a: role.labels.futures_in_a.clone(),
                    a_pose: role.a.world_from_agent,
                    b_pose: role.b.world_from_agent,
                };
                // B's embedding is left to whoever needs the range ([`Scbg::pair_context`]).
                (
                    PlanBasis(basis),
                    Example::from_role_embedded(id, role, Vec::new()),
                )
            }
            Policy::Generator => self.generator_basis(id, role, device),
        })
    }

    /// The generator's basis: B's and A's scenes in one encoder pass (the framework's cost per
    /// operation, most of a plan's, paid once for both), B's marginal embedding, its
    /// candidates scored by J_φ toward the audience, and the predicted range of ψ.
    fn generator_basis(
        &self,
        scenario_id: String,
        role: LabelledRole,
        device: &Device,
    ) -> (PlanBasis, Example) {
        let batch =
            scbg_model::Batch::for_mode(&[&role.b, &role.a], scbg_model::Mode::Marginal, device);
        let encoded = self.predictor.encode_scene(&batch);
        let b_embedding = to_vec(self.predictor.encode_marginal(encoded.clone().narrow(0, 1)));
        let a_lane_path = batch
            .lane_path
            .as_ref()
            .map(|(p, m)| (p.clone().narrow(0, 1, 1), m.clone().narrow(0, 1, 1)));
        let example = Example::from_role_embedded(scenario_id, role, b_embedding);
        let embedding = stored_embeddings(&[&example], device);
        let modes = b_modes_with(
            &self.generator,
            &self.predictor,
            &[&example],
            self.labels.reward,
            Some((encoded.narrow(1, 1), a_lane_path)),
            device,
        );
        let (low, high) = self.range.forward(embedding.clone());
        let basis = GeneratorBasis {
            embedding,
            pose: example.b.world_from_agent,
            modes,
            low: to_vec(low)[0],
            high: to_vec(high)[0],
        };
        (PlanBasis(Basis::Generator(Box::new(basis))), example)
    }

    /// B's future (world frame) for `courtesy` from a [`Scbg::plan_basis`] of this model: the
    /// same points as [`Scbg::plan`] gives for the same scene and request.
    pub fn plan_from(
        &self,
        basis: &PlanBasis,
        courtesy: Courtesy,
        device: &Device,
    ) -> Result<Vec<[f64; 2]>, GenerateError> {
        let choices = self.choose(basis, &[courtesy], device)?;
        Ok(world_xy(&choices.b_pose, &choices.futures_b[0]))
    }

    /// The choice for each requested courtesy (in one forward of the generator): the
    /// quantile becomes a ψ through the predicted range ([`psi_for_quantile`]) and the
    /// generator turns ψ into B's future; sample and rank takes the labelled future of that
    /// rank, or nearest that ψ ([`ranked_choice`]).
    pub(crate) fn choose(
        &self,
        basis: &PlanBasis,
        courtesy: &[Courtesy],
        device: &Device,
    ) -> Result<Choices, GenerateError> {
        match &basis.0 {
            Basis::Ranked {
                psi,
                futures_in_a,
                a_pose,
                b_pose,
            } => {
                let mut out = Choices {
                    psi: Vec::with_capacity(courtesy.len()),
                    futures_b: Vec::with_capacity(courtesy.len()),
                    b_pose: *b_pose,
                };
                for &c in courtesy {
                    let k = ranked_choice(psi, c)
                        .ok_or(GenerateError::NoCandidates(self.labels.labelled_samples()))?;
                    out.psi.push(match c {
                        // The ψ the rank stands for: the chosen future's label.
                        Courtesy::Quantile(_) => psi[k],
                        Courtesy::Psi(p) => p,
                    });
                    out.futures_b
                        .push(change_frame(&futures_in_a[1 + k], a_pose, b_pose));
                }
                Ok(out)
            }
            Basis::Generator(g) => {
                let n = courtesy.len();
                let psi: Vec<f32> = courtesy
                    .iter()
                    .map(|&c| match c {
                        Courtesy::Psi(p) => p,
                        Courtesy::Quantile(q) => psi_for_quantile(q, g.low, g.high),
                    })
                    .collect();
                if n == 0 {
                    return Ok(Choices {
                        psi,
                        futures_b: Vec::new(),
                        b_pose: g.pose,
                    });
                }
                let future = self.generator.forward(
                    repeat_rows(g.embedding.clone(), n),
                    Tensor::from_data(TensorData::new(psi.clone(), [n]), device),
                    g.modes.clone().repeat_rows(n),
                );
                let xy = to_vec(future);
                let t = xy.len() / (2 * n);
                let futures_b = xy
                    .chunks_exact(2 * t)
                    .map(|f| f.chunks_exact(2).map(|p| [p[0], p[1]]).collect())
                    .collect();
                Ok(Choices {
                    psi,
                    futures_b,
                    b_pose: g.pose,
                })
            }
        }
    }
}
