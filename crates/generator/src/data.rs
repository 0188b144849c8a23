//! Training examples of the generator: one ordered pair (A, B) in one window, with B's logged
//! and sampled futures and their courtesy labels.

use burn::tensor::Device;
use rand::SeedableRng;
use scbg_courtesy::label::{
    AudienceTerm, LabelOptions, LabelledRole, change_frame, label_scene, scene_seed,
};
use scbg_features::{AgentSample, FeatureConfig, FeatureStats, PreparedScene};
use scbg_model::Multipath;

/// One pair role with its labelled futures.
#[derive(Debug, Clone)]
pub struct Example {
    /// The scenario the pair comes from.
    pub scenario_id: String,
    /// A (the agent whose reward counts), standardised, conditioned on B's logged future.
    pub a: AgentSample,
    /// B (the generated agent), standardised, marginal.
    pub b: AgentSample,
    /// B's frame in A's frame: heading difference and B's origin in A's frame.
    pub a_from_b: [f32; 3],
    /// `[1 + M][T]` futures of B in B's frame: 0 = logged, then the sampled ones.
    pub futures_b: Vec<Vec<[f32; 2]>>,
    /// `[T]` validity of the logged future (sampled ones are complete).
    pub logged_valid: Vec<bool>,
    /// `[1 + M]` ψ labels.
    pub psi: Vec<f32>,
    /// E[r(Y_A) | x] as the labels estimated it (ψ = E[r(Y_A) | x, y_B] − this).
    pub e_marg: f32,
    /// B's scene embedding from the frozen predictor encoder (marginal mode).
    pub b_embedding: Vec<f32>,
    /// Each audience member's weight and E[r(Y_j) | x]: entry 0 is A, then [`Self::others`]
    /// (one entry of weight 1 for the paper's pair; `e_marg` is their weighted sum).
    pub terms: Vec<AudienceTerm>,
    /// The members of B's audience besides A: each one's standardised sample (conditioned on
    /// B's logged future) and B's frame in its frame (as [`Self::a_from_b`]).
    pub others: Vec<(AgentSample, [f32; 3])>,
    /// `[K]` the courtesy ψ_k of each of B's marginal modes ([`mode_courtesy`](crate::mode_courtesy)), stored
    /// by [`fill_mode_courtesy`](crate::fill_mode_courtesy) for a generator that scores them;
    /// empty when not computed ([`b_modes_for`](crate::b_modes_for) then computes it on the fly).
    pub mode_psi: Vec<f32>,
}

impl Example {
    /// The training example of a labelled pair role: B's futures moved into B's frame, the
    /// B→A frame change and B's frozen embedding (computed here, on the plain device).
    pub fn from_role(
        scenario_id: String,
        role: LabelledRole,
        predictor: &Multipath,
        device: &Device,
    ) -> Self {
        let b_embedding = marginal_embedding(predictor, &role.b, device);
        Self::from_role_embedded(scenario_id, role, b_embedding)
    }

    /// [`Self::from_role`] with B's marginal embedding already computed.
    pub(crate) fn from_role_embedded(
        scenario_id: String,
        role: LabelledRole,
        b_embedding: Vec<f32>,
    ) -> Self {
        let LabelledRole {
            a,
            b,
            labels,
            others,
            ..
        } = role;
        let futures_b = labels
            .futures_in_a
            .iter()
            .map(|f| change_frame(f, &a.world_from_agent, &b.world_from_agent))
            .collect();
        Self {
            scenario_id,
            logged_valid: a.condition_future_valid.clone(),
            a_from_b: a_from_b(&a, &b),
            b_embedding,
            mode_psi: Vec::new(),
            futures_b,
            psi: labels.psi,
            e_marg: labels.e_marg,
            terms: labels.terms,
            others: others
                .into_iter()
                .map(|m| {
                    let frame = a_from_b(&m.sample, &b);
                    (m.sample, frame)
                })
                .collect(),
            a,
            b,
        }
    }
}

/// Labels every pair role of `scenes` through the one labelling path
/// ([`scbg_courtesy::label::label_scene`], scene `i` on stream [`scene_seed`]`(seed, i)`) and
/// keeps what training needs, including B's frozen embedding.
///
/// Pass a predictor on a plain (non-autodiff) device: nothing here needs gradients, and burn's
/// autodiff graph keeps the nodes of every forward that is never back-propagated.
pub fn build_examples(
    predictor: &Multipath,
    scenes: &[PreparedScene],
    stats: &FeatureStats,
    features: &FeatureConfig,
    options: LabelOptions,
    seed: u64,
    device: &Device,
) -> Vec<Example> {
    let mut out = Vec::new();
    for (i, scene) in scenes.iter().enumerate() {
        let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(scene_seed(seed, i as u64));
        for role in label_scene(predictor, scene, stats, features, options, &mut rng, device) {
            out.push(Example::from_role(
                scene.scenario_id.clone(),
                role,
                predictor,
                device,
            ));
        }
    }
    out
}

/// B's frame in A's frame: `[heading difference (rad), B's origin x, y in A's frame (m)]`
/// (for any agent A).
pub fn a_from_b(a: &AgentSample, b: &AgentSample) -> [f32; 3] {
    let (pa, pb) = (a.world_from_agent, b.world_from_agent);
    let (tx, ty) = pa.agent_from_world(pb.x_m, pb.y_m);
    [
        scbg_scene::wrap_angle_rad(pb.heading_rad - pa.heading_rad) as f32,
        tx as f32,
        ty as f32,
    ]
}

/// The frozen predictor's scene embedding of a (standardised) sample in marginal mode.
pub fn marginal_embedding(
    predictor: &Multipath,
    sample: &AgentSample,
    device: &Device,
) -> Vec<f32> {
    let batch = scbg_model::Batch::for_mode(&[sample], scbg_model::Mode::Marginal, device);
    predictor
        .encode_marginal(predictor.encode_scene(&batch))
        .into_data()
        .try_to_vec::<f32>()
        .expect("f32 tensor")
}
