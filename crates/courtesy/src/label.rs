//! Auto-labelling (paper Sec. III-C): ψ of the logged future of B and of M futures sampled from
//! B's marginal prediction (the data augmentation of Sec. III-D).

use burn::tensor::{Device, Tensor, TensorData};
use rand::Rng;
use scbg_features::{
    AgentSample, FeatureConfig, FeatureStats, PreparedScene, SampleBuilder, Window,
};
use scbg_model::{Batch, Mixture, Mode, Multipath};

use crate::{Audience, expected_reward, expected_reward_shared};

mod options;
mod sampling;

pub use options::{LabelOptions, MarginalEstimate};
pub use sampling::{SampleMixture, change_frame, marginal_mixtures};

/// ψ and both expectations for several futures of B, for one target A (or B's audience).
#[derive(Debug, Clone, PartialEq)]
pub struct PairLabels {
    /// `[1 + M + L]`: index 0 is the logged future, 1..=M the sampled ones, then the L lane
    /// moves of the sampled ones ([`LabelOptions::lane_move_steps`]; none by default). With an audience
    /// ([`crate::Audience::Neighbours`]), the weighted sum over its members.
    pub psi: Vec<f32>,
    /// `[1 + M + L]` E[r(Y_A) | x, y_B] of each future (weighted sum over the audience).
    pub e_cond: Vec<f32>,
    /// E[r(Y_A) | x] as estimated (weighted sum over the audience).
    pub e_marg: f32,
    /// The futures of B in A's frame (`[1 + M + L][T]`; the logged one has its invalid steps at 0).
    pub futures_in_a: Vec<Vec<[f32; 2]>>,
    /// Each audience member's weight and E[r(Y_j) | x]: entry 0 is A, then the role's
    /// [`LabelledRole::others`] in order (one entry, weight 1, for the paper's pair).
    pub terms: Vec<AudienceTerm>,
}

impl PairLabels {
    /// The labels of an equal-weight ensemble: the mean of each member's ψ, expectations and
    /// audience terms, for the same futures (the first member's `futures_in_a` are kept).
    ///
    /// # Panics
    /// If `members` is empty or their futures or audiences differ in number.
    pub fn mean(members: Vec<PairLabels>) -> PairLabels {
        let n = members.len() as f32;
        let mut it = members.into_iter();
        let mut sum = it.next().expect("at least one member");
        for m in it {
            assert_eq!(m.psi.len(), sum.psi.len(), "the same futures");
            assert_eq!(m.terms.len(), sum.terms.len(), "the same audience");
            for (s, x) in sum.psi.iter_mut().zip(&m.psi) {
                *s += x;
            }
            for (s, x) in sum.e_cond.iter_mut().zip(&m.e_cond) {
                *s += x;
            }
            sum.e_marg += m.e_marg;
            for (s, x) in sum.terms.iter_mut().zip(&m.terms) {
                s.e_marg += x.e_marg;
            }
        }
        sum.psi
            .iter_mut()
            .chain(&mut sum.e_cond)
            .for_each(|x| *x /= n);
        sum.e_marg /= n;
        sum.terms.iter_mut().for_each(|t| t.e_marg /= n);
        sum
    }
}

/// One audience member's part of ψ: `weight · (E[r(Y_j) | x, y_B] − e_marg)`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AudienceTerm {
    /// The member's weight.
    pub weight: f32,
    /// E[r(Y_j) | x] as estimated.
    pub e_marg: f32,
}

/// A member of B's audience besides A, with its sample conditioned on B's logged future.
#[derive(Debug, Clone)]
pub struct AudienceMember {
    /// Track index in the prepared scene.
    pub index: usize,
    /// Track id.
    pub id: i64,
    /// The member's standardised sample, conditioned on B's logged future.
    pub sample: AgentSample,
    /// Its weight ([`Audience::weight`]).
    pub weight: f32,
}

/// The members of B's audience besides A ([`Audience::others`]) with their standardised
/// samples conditioned on B; a member whose sample cannot be built is left out.
pub fn audience_members(
    builder: &mut SampleBuilder<'_>,
    scene: &PreparedScene,
    stats: &FeatureStats,
    window: &Window,
    a: usize,
    b: usize,
    audience: Audience,
) -> Vec<AudienceMember> {
    audience
        .others(scene, window, a, b)
        .into_iter()
        .filter_map(|(index, distance)| {
            let mut sample = builder.sample(window, index, Some(b)).ok()?;
            stats.normalize(&mut sample);
            Some(AudienceMember {
                index,
                id: scene.tracks[index].id,
                sample,
                weight: audience.weight(distance),
            })
        })
        .collect()
}

/// Labels one ordered pair. `a` is A's standardised sample conditioned on B's logged future;
/// `b` is B's standardised marginal sample; `b_mixture` is B's marginal prediction.
pub fn label_pair(
    model: &Multipath,
    a: &AgentSample,
    b: &AgentSample,
    b_mixture: &Mixture,
    options: LabelOptions,
    rng: &mut impl Rng,
    device: &Device,
) -> PairLabels {
    label_role(model, (a, 1.0), &[], b, b_mixture, options, rng, device)
}

/// Labels one ordered pair toward B's audience: A (`(sample, weight)`, conditioned on B's
/// logged future) and `others`. B's futures are drawn once; each member's conditional
/// expectations come from one batched forward, and ψ is the weighted sum of the members' ψ
/// (see [`crate::audience`]). Without `others` and with weight 1 this is the paper's ψ toward
/// A, bit for bit.
#[allow(clippy::too_many_arguments)]
pub fn label_role(
    model: &Multipath,
    a: (&AgentSample, f32),
    others: &[AudienceMember],
    b: &AgentSample,
    b_mixture: &Mixture,
    options: LabelOptions,
    rng: &mut impl Rng,
    device: &Device,
) -> PairLabels {
    let LabelOptions {
        samples,
        reward,
        marginal,
        ..
    } = options;
    let members: Vec<(&AgentSample, f32)> = std::iter::once(a)
        .chain(others.iter().map(|m| (&m.sample, m.weight)))
        .collect();
    let t = a.0.condition_future_valid.len();
    let mut sampled = b_mixture.sample(samples, 1.0, rng);
    // The baseline's futures are drawn after the labelled ones either way (the same draws);
    // kept, they are labelled futures like the first `samples` (and `baseline` is left empty).
    let mut baseline = b_mixture.sample(options.baseline_futures(), 1.0, rng);
    if options.keep_baseline {
        sampled.append(&mut baseline);
    }
    let moves: Vec<Vec<[f32; 2]>> = if options.lane_move_steps > 0 {
        let path = scbg_features::sample_lane_path(b);
        // A at the current step in B's frame, driving on at its current velocity: a move must
        // leave A room when it enters A's lane.
        let a_pose = &a.0.world_from_agent;
        let v = a.0.current_velocity_mps;
        let a_now = change_frame(&[[0.0, 0.0], v], a_pose, &b.world_from_agent);
        let a_velocity = [a_now[1][0] - a_now[0][0], a_now[1][1] - a_now[0][1]];
        sampled
            .iter()
            .filter_map(|f| scbg_features::lane_move(f, &path, options.lane_move_steps))
            .filter(|m| scbg_features::leaves_room(m, a_now[0], a_velocity, options.lane_move_room))
            .collect()
    } else {
        Vec::new()
    };
    // B's futures in scoring order: the sampled ones and their lane moves (the first `n`
    // futures, with the logged one, are labelled and kept), then the baseline's extra samples.
    let n_sampled = sampled.len();
    let n = 1 + n_sampled + moves.len();
    sampled.extend(moves);
    sampled.extend(baseline);
    // Every future scored.
    let n_all = 1 + sampled.len();
    let mut cond = Vec::with_capacity(members.len() * n_all * t * 3);
    let mut futures_in_a = Vec::new();
    for (j, &(s, _)) in members.iter().enumerate() {
        let logged: Vec<[f32; 2]> = (0..t)
            .map(|i| {
                [
                    s.condition_future_xy_m[2 * i],
                    s.condition_future_xy_m[2 * i + 1],
                ]
            })
            .collect();
        let mut futures = vec![logged];
        futures.extend(
            sampled
                .iter()
                .map(|tr| change_frame(tr, &b.world_from_agent, &s.world_from_agent)),
        );
        for (i, f) in futures.iter().enumerate() {
            for (k, p) in f.iter().enumerate() {
                let valid = i > 0 || s.condition_future_valid[k];
                cond.extend([
                    if valid { p[0] } else { 0.0 },
                    if valid { p[1] } else { 0.0 },
                    f32::from(u8::from(valid)),
                ]);
            }
        }
        if j == 0 {
            futures.truncate(n);
            futures_in_a = futures;
        }
    }
    let rows = members.len() * n_all;
    // Every member's scene is encoded once for all its futures of B.
    let samples: Vec<&AgentSample> = members.iter().map(|&(s, _)| s).collect();
    let base = Batch::for_mode(&samples, Mode::Conditional, device);
    let member_of_row: Vec<usize> = (0..members.len())
        .flat_map(|j| std::iter::repeat_n(j, n_all))
        .collect();
    let condition = Tensor::<3>::from_data(TensorData::new(cond, [rows, t, 3]), device);
    let e_cond_all: Vec<f32> =
        expected_reward_shared(model, &base, &member_of_row, condition, reward, 0.1)
            .into_data()
            .try_to_vec::<f32>()
            .expect("f32");
    // The samples of B's marginal: the labelled ones and the baseline's, not the lane moves.
    let n_marginal = n_sampled + (n_all - n);
    let e_marg_members: Vec<f32> =
        if marginal == MarginalEstimate::ConditionalAverage && n_marginal > 0 {
            e_cond_all
                .chunks(n_all)
                .map(|e| e[1..=n_sampled].iter().chain(&e[n..]).sum::<f32>() / n_marginal as f32)
                .collect()
        } else {
            expected_reward(model, &base, None, reward, 0.1)
                .into_data()
                .try_to_vec::<f32>()
                .expect("f32")
        };
    let mut psi = vec![0.0f32; n];
    let mut e_cond = vec![0.0f32; n];
    let mut e_marg = 0.0f32;
    let mut terms = Vec::with_capacity(members.len());
    for (j, &(_, weight)) in members.iter().enumerate() {
        let ej = &e_cond_all[j * n_all..j * n_all + n];
        for k in 0..n {
            psi[k] += weight * (ej[k] - e_marg_members[j]);
            e_cond[k] += weight * ej[k];
        }
        e_marg += weight * e_marg_members[j];
        terms.push(AudienceTerm {
            weight,
            e_marg: e_marg_members[j],
        });
    }
    PairLabels {
        psi,
        e_cond,
        e_marg,
        futures_in_a,
        terms,
    }
}

/// One labelled pair role: A (whose expected reward counts) and B (whose futures are labelled)
/// in one window of a prepared scene.
#[derive(Debug, Clone)]
pub struct LabelledRole {
    /// The window's current step.
    pub window_step: usize,
    /// Track index of A in the prepared scene.
    pub a_index: usize,
    /// Track index of B.
    pub b_index: usize,
    /// Track id of A.
    pub a_id: i64,
    /// Track id of B.
    pub b_id: i64,
    /// A's standardised sample, conditioned on B's logged future.
    pub a: AgentSample,
    /// B's standardised marginal sample.
    pub b: AgentSample,
    /// The members of B's audience besides A (empty for the paper's pair).
    pub others: Vec<AudienceMember>,
    /// ψ of B's logged and sampled futures.
    pub labels: PairLabels,
}

/// Labels the role (A = track `ia`, B = track `ib`) of `window` from its standardised samples
/// (A's conditioned on B, B's marginal): B's marginal mixture, B's audience
/// ([`LabelOptions::audience`]) and ψ of B's logged and sampled futures. The one path of
/// [`label_scene`] and of the generator's pair context at inference.
#[allow(clippy::too_many_arguments)]
pub fn label_built_role(
    model: &Multipath,
    builder: &mut SampleBuilder<'_>,
    stats: &FeatureStats,
    window: &Window,
    (ia, a): (usize, AgentSample),
    (ib, b): (usize, AgentSample),
    options: LabelOptions,
    rng: &mut impl Rng,
    device: &Device,
) -> LabelledRole {
    let mixture = marginal_mixtures(model, &[&b], device).remove(0);
    let mut role = unlabelled_role(builder, stats, window, (ia, a), (ib, b), options.audience);
    let a_weight = role.labels.terms[0].weight;
    role.labels = label_role(
        model,
        (&role.a, a_weight),
        &role.others,
        &role.b,
        &mixture,
        options,
        rng,
        device,
    );
    role
}

/// The role's samples and B's audience exactly as [`label_built_role`] builds them, without
/// labelling any future of B: for a caller that scores its own futures of B against each
/// other (the generator's modes of B, `scbg_generator::mode_courtesy`), which needs neither B's
/// sampled futures nor E[r(Y_j) | x] (0 in every [`AudienceTerm`] here; `psi`, `e_cond` and
/// `futures_in_a` are empty). No predictor forward.
pub fn unlabelled_role(
    builder: &mut SampleBuilder<'_>,
    stats: &FeatureStats,
    window: &Window,
    (ia, a): (usize, AgentSample),
    (ib, b): (usize, AgentSample),
    audience: Audience,
) -> LabelledRole {
    let scene = builder.scene();
    let others = audience_members(builder, scene, stats, window, ia, ib, audience);
    let a_weight = audience.weight(Audience::distance_between(scene, window, ia, ib));
    let terms = std::iter::once(a_weight)
        .chain(others.iter().map(|m| m.weight))
        .map(|weight| AudienceTerm {
            weight,
            e_marg: 0.0,
        })
        .collect();
    LabelledRole {
        window_step: window.current_step,
        a_index: ia,
        b_index: ib,
        a_id: scene.tracks[ia].id,
        b_id: scene.tracks[ib].id,
        a,
        b,
        others,
        labels: PairLabels {
            psi: Vec::new(),
            e_cond: Vec::new(),
            e_marg: 0.0,
            futures_in_a: Vec::new(),
            terms,
        },
    }
}

/// The labelling stream of scene `index` under `seed` (the project's one seed mixer): every
/// front end labels scene `i` with a generator seeded by this, so its labels do not depend on
/// which command labels it, or which other scenes it labels.
pub fn scene_seed(seed: u64, index: u64) -> u64 {
    scbg_base::seed::mix(seed, index)
}

/// Labels every ordered pair role (both directions of every interacting pair of every window)
/// of a prepared scene: the one labelling loop of the project. Roles whose samples cannot be
/// built (e.g. B not valid at the current step) are skipped. Pass a predictor on a plain
/// (non-autodiff) device: nothing here needs gradients.
pub fn label_scene(
    model: &Multipath,
    scene: &PreparedScene,
    stats: &FeatureStats,
    features: &FeatureConfig,
    options: LabelOptions,
    rng: &mut (impl Rng + Clone),
    device: &Device,
) -> Vec<LabelledRole> {
    label_scene_ensemble(&[(model, stats)], scene, features, options, rng, device)
}

/// [`label_scene`] with ψ averaged over an ensemble of predictors (each with the feature
/// statistics it was trained with): a deep ensemble, whose predictive distribution is the
/// equal-weight mixture of the members', so its `E[r(Y_A) | …]` — and ψ, both expectations and
/// each audience term — is the mean of the members'. B's futures are drawn once, from the
/// first member's marginal, and every member scores the same futures; the role's samples and
/// audience are the first member's, and the random stream advances as with the first member
/// alone (so the futures do not depend on the ensemble's size). [`label_scene`] is this with
/// one member.
///
/// # Panics
/// If `members` is empty.
pub fn label_scene_ensemble(
    members: &[(&Multipath, &FeatureStats)],
    scene: &PreparedScene,
    features: &FeatureConfig,
    options: LabelOptions,
    rng: &mut (impl Rng + Clone),
    device: &Device,
) -> Vec<LabelledRole> {
    let (&(model, stats), rest) = members.split_first().expect("at least one predictor");
    let mut out = Vec::new();
    let mut builder = SampleBuilder::new(scene, features);
    for (w, pairs) in scene.windows.iter().zip(&scene.pairs) {
        for p in pairs {
            for (ia, ib) in [(p.first, p.second), (p.second, p.first)] {
                let (Ok(a_raw), Ok(b_raw)) =
                    (builder.sample(w, ia, Some(ib)), builder.sample(w, ib, None))
                else {
                    continue;
                };
                let normalized = |stats: &FeatureStats| {
                    let (mut a, mut b) = (a_raw.clone(), b_raw.clone());
                    stats.normalize(&mut a);
                    stats.normalize(&mut b);
                    (a, b)
                };
                let (a, b) = normalized(stats);
                let draws = rng.clone();
                let mut role = label_built_role(
                    model,
                    &mut builder,
                    stats,
                    w,
                    (ia, a),
                    (ib, b),
                    options,
                    rng,
                    device,
                );
                if !rest.is_empty() {
                    let a_weight = options
                        .audience
                        .weight(Audience::distance_between(scene, w, ia, ib));
                    // The first member's mixture and the same draws: the same futures.
                    let mixture = marginal_mixtures(model, &[&role.b], device).remove(0);
                    let mut each = vec![role.labels.clone()];
                    for &(model_m, stats_m) in rest {
                        let (a_m, b_m) = normalized(stats_m);
                        let others = audience_members(
                            &mut builder,
                            scene,
                            stats_m,
                            w,
                            ia,
                            ib,
                            options.audience,
                        );
                        each.push(label_role(
                            model_m,
                            (&a_m, a_weight),
                            &others,
                            &b_m,
                            &mixture,
                            options,
                            &mut draws.clone(),
                            device,
                        ));
                    }
                    role.labels = PairLabels::mean(each);
                }
                out.push(role);
            }
        }
    }
    out
}
