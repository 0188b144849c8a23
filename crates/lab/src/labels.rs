//! Courtesy labels (paper eq. (2), Sec. III-C, Fig. 3): one labelling path for every pair role
//! of a prepared cache — used by `scbg label`, the generator's training and evaluation sets and
//! the demo — and the label table (Parquet) it is stored in.

use std::path::{Path, PathBuf};

use anyhow::Context;
use burn::tensor::Device;
use rand::SeedableRng;
use scbg_courtesy::Reward;
use scbg_courtesy::label::{LabelOptions, LabelledRole, label_scene_ensemble, scene_seed};
use scbg_features::cache::PreparedDataset;
use scbg_features::{FeatureConfig, PreparedScene};
use scbg_model::Multipath;
use scbg_synth::GroundTruth;
use scbg_train::Checkpoint;

pub use crate::label_table::{
    LabelRow, label_table_from_bytes, read_label_table, write_label_table,
};
use crate::{Progress, ensure_request};

mod folder;
mod summary;
pub use folder::LABEL_OPTIONS_FILE;
use folder::claim_label_folder;
pub use summary::{FamilyRho, LabelSummary, PsiAll, Spread, spearman_latent, within_pair_std};

/// The labelled pair roles of one scene of a cache.
#[derive(Debug, Clone)]
pub struct SceneLabels {
    /// Index of the scene in the cache (its labelling stream).
    pub index: usize,
    /// The scenario id.
    pub scenario_id: String,
    /// Every ordered pair role of every window, labelled.
    pub roles: Vec<LabelledRole>,
}

impl SceneLabels {
    /// The label-table rows of these roles: one per future of B. With the scene's synthetic
    /// ground truth, the futures of the role it describes get ψ_true from the oracle
    /// ([`crate::fidelity::psi_true_of_futures`]).
    pub fn rows(&self, truth: Option<&GroundTruth>) -> Vec<LabelRow> {
        let mut rows = Vec::new();
        for role in &self.roles {
            let psi_true = truth
                .map(|t| crate::fidelity::psi_true_of_role(t, role))
                .unwrap_or_default();
            for (k, psi) in role.labels.psi.iter().enumerate() {
                rows.push(LabelRow {
                    scenario_id: self.scenario_id.clone(),
                    window_step: role.window_step as u32,
                    a_id: role.a_id,
                    b_id: role.b_id,
                    sample: k as u32,
                    psi: *psi,
                    e_marg: role.labels.e_marg,
                    e_cond: role.labels.e_cond[k],
                    psi_true: psi_true.get(k).copied().flatten(),
                    audience_size: role.labels.terms.len() as u32,
                });
            }
        }
        rows
    }
}

/// The labelling path: every pair role of the cache scenes `range` for which `keep` holds,
/// labelled with the predictor of `ckpt` (standardised by its statistics, its feature
/// settings). Scene `i` draws B's sampled futures from its own stream
/// ([`scene_seed`]`(seed, i)`), so a scene's labels do not depend on which other scenes are
/// labelled, in which order, or by which command. Run on a plain (non-autodiff) device.
#[allow(clippy::too_many_arguments)]
pub fn label_scenes(
    predictor: &Multipath,
    ckpt: &Checkpoint,
    device: &Device,
    dataset: &PreparedDataset,
    range: std::ops::Range<usize>,
    keep: &(dyn Fn(&PreparedScene) -> bool + Sync),
    options: LabelOptions,
    seed: u64,
    progress: &dyn Progress,
) -> anyhow::Result<Vec<SceneLabels>> {
    label_scenes_ensemble(
        &[(predictor, ckpt)],
        device,
        dataset,
        range,
        keep,
        options,
        seed,
        progress,
    )
}

/// The feature settings that serve every member of an ensemble: the members' own, which must
/// agree except for the lane path (built when any member reads it; a model that does not
/// read it ignores it).
pub fn ensemble_features(members: &[&Checkpoint]) -> anyhow::Result<FeatureConfig> {
    let first = members
        .first()
        .context("an ensemble needs at least one predictor")?;
    let mut features = first.train_config.feature_config();
    for (i, m) in members.iter().enumerate().skip(1) {
        let mine = m.train_config.feature_config();
        let comparable = FeatureConfig {
            lane_path: features.lane_path,
            ..mine.clone()
        };
        ensure_request!(
            comparable == features,
            "predictor {} of the ensemble was trained with other feature settings than the first \
             ({mine:?} against {features:?}); an ensemble's members must read the same features",
            i + 1
        );
        features.lane_path |= mine.lane_path;
    }
    Ok(features)
}

/// [`label_scenes`] with ψ averaged over an ensemble of predictors (each standardised by its
/// own statistics; B's sampled futures drawn from the first member's marginal and scored by
/// every member; see [`scbg_courtesy::label::label_scene_ensemble`]). [`label_scenes`] is this
/// with one member.
#[allow(clippy::too_many_arguments)]
pub fn label_scenes_ensemble(
    members: &[(&Multipath, &Checkpoint)],
    device: &Device,
    dataset: &PreparedDataset,
    range: std::ops::Range<usize>,
    keep: &(dyn Fn(&PreparedScene) -> bool + Sync),
    options: LabelOptions,
    seed: u64,
    progress: &dyn Progress,
) -> anyhow::Result<Vec<SceneLabels>> {
    let ckpts: Vec<&Checkpoint> = members.iter().map(|&(_, c)| c).collect();
    let features = ensemble_features(&ckpts)?;
    let scorers: Vec<(&Multipath, &scbg_features::FeatureStats)> =
        members.iter().map(|&(m, c)| (m, &c.stats)).collect();
    let pb = progress.bar("label", range.len() as u64);
    // Scenes in parallel (each with its own seed, so the result does not depend on the
    // threads), collected in index order.
    use rayon::prelude::*;
    let labelled: Vec<Option<SceneLabels>> = range
        .into_par_iter()
        .map(|i| {
            let scene = dataset.scene(i)?;
            pb.inc(1);
            if !keep(&scene) {
                return Ok(None);
            }
            let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(scene_seed(seed, i as u64));
            let roles =
                label_scene_ensemble(&scorers, &scene, &features, options, &mut rng, device);
            Ok(Some(SceneLabels {
                index: i,
                scenario_id: scene.scenario_id,
                roles,
            }))
        })
        .collect::<anyhow::Result<_>>()?;
    Ok(labelled.into_iter().flatten().collect())
}

/// A `scbg label` run.
#[derive(Debug, Clone)]
pub struct LabelRun {
    /// Predictor checkpoint folder (B's sampled futures come from its marginal).
    pub model: PathBuf,
    /// Further predictor checkpoint folders: ψ is averaged over `model` and these (a deep
    /// ensemble, [`label_scenes_ensemble`]); empty for one predictor.
    pub ensemble: Vec<PathBuf>,
    /// Prepared cache folder.
    pub data: PathBuf,
    /// Output folder: `labels-NNNNN.parquet` per cache shard, `psi_histogram.png`,
    /// `summary.json`.
    pub out: PathBuf,
    /// Futures to sample, reward, estimator, noise.
    pub options: LabelOptions,
    /// Seed of the sampled futures.
    pub seed: u64,
    /// A synthetic `ground_truth.jsonl` for the latent-courtesy check.
    pub ground_truth: Option<PathBuf>,
    /// Label only the cache shards with `shard % num_shards == shard_index` (several workers
    /// sharing `out`). Such a run writes its shards' tables and no summary; a run with
    /// `num_shards = 1` afterwards reads every table back and writes the summary (the merge).
    pub shard_index: usize,
    /// Number of workers sharing the cache (1: everything, with the summary).
    pub num_shards: usize,
    /// With a ground truth: also write reaction siblings
    /// ([`crate::fidelity::reaction_scenes`]) of this many sampled futures per ground-truth
    /// role, as `reaction-NNNNN.tfrecord` per cache shard in this folder (for a training
    /// config's `reaction_cache`; siblings of held-out scenes are ignored by training). A
    /// shard counts as done on a re-run only when its siblings are there too.
    pub reaction_siblings: Option<(PathBuf, usize)>,
}

/// The paper's labelling: `samples` futures of B per pair role, each labelled, `marginal`'s
/// estimate of E[r(Y_A) | x] over them, toward A alone; no further futures, no lane moves.
pub fn label_options(
    samples: usize,
    reward: Reward,
    marginal: scbg_courtesy::label::MarginalEstimate,
) -> LabelOptions {
    LabelOptions {
        samples,
        reward,
        marginal,
        audience: Default::default(),
        baseline_samples: 0,
        lane_move_steps: 0,
        keep_baseline: false,
        lane_move_room: DEFAULT_LANE_MOVE_ROOM,
    }
}

/// More futures of B that `scbg label` and the demo sample by default for the estimate of
/// E[r(Y_A) | x], labelled and kept too ([`LabelOptions::baseline_samples`]).
pub const DEFAULT_BASELINE_SAMPLES: usize = 24;

/// The labelling of `scbg label` and the demo by default: the conditional average over the
/// `samples` futures plus [`DEFAULT_BASELINE_SAMPLES`] more, all labelled and kept, and lane
/// moves within [`DEFAULT_LABEL_LANE_MOVE_STEPS`] (docs/findings.md, "Labels").
pub fn default_label_options(samples: usize, reward: Reward) -> LabelOptions {
    LabelOptions {
        baseline_samples: DEFAULT_BASELINE_SAMPLES,
        keep_baseline: true,
        lane_move_steps: DEFAULT_LABEL_LANE_MOVE_STEPS,
        ..label_options(
            samples,
            reward,
            scbg_courtesy::label::MarginalEstimate::ConditionalAverage,
        )
    }
}

/// An audience as a command line or settings file names it: `pair`, or
/// `neighbours[:RADIUS_M[:sum|proximity]]` (30 m and `sum` when left out).
pub fn parse_audience(text: &str) -> Result<scbg_courtesy::Audience, String> {
    let mut parts = text.split(':');
    let kind = parts.next().unwrap_or_default().trim();
    let radius_m = match parts.next() {
        None => 30.0,
        Some(r) => r
            .trim()
            .parse::<f32>()
            .map_err(|_| format!("audience {text:?}: radius {r:?} is not a number"))?,
    };
    let weighting = match parts.next().map(str::trim) {
        None | Some("sum") => scbg_courtesy::Weighting::Sum,
        Some("proximity") => scbg_courtesy::Weighting::Proximity,
        Some(w) => {
            return Err(format!(
                "audience {text:?}: weights {w:?}: expected sum or proximity"
            ));
        }
    };
    if parts.next().is_some() || (kind == "pair" && text.trim() != "pair") {
        return Err(format!(
            "audience {text:?}: expected pair or neighbours[:RADIUS_M[:sum|proximity]]"
        ));
    }
    scbg_courtesy::Audience::parse(kind, radius_m, weighting)
}

/// What a labelled lane move may ask of A by default in `scbg label` and the demo
/// ([`LabelOptions::lane_move_room`]): hard braking, the synthetic world's least courteous
/// cut-in and the closed loop's gap acceptance. Over four data seeds, sample and rank's
/// control in truth rose from 0.522 to 0.552 pooled and from 0.389 to 0.484 on cut-in against
/// MOBIL's polite limit (BENCHMARKS.md, *Lane moves that ask A to brake hard*).
pub const DEFAULT_LANE_MOVE_ROOM: scbg_features::FollowerRoom =
    scbg_features::FollowerRoom::HARD_BRAKING;

/// The lane moves that `scbg label` and the demo label after B's sampled futures by default:
/// completed within 30 steps (3 s; [`LabelOptions::lane_move_steps`]). The generator trains
/// without them; sample and rank chooses among them (BENCHMARKS.md, *Lane moves in the
/// labels by default*).
pub const DEFAULT_LABEL_LANE_MOVE_STEPS: usize = 30;

/// Reaction siblings `scbg label --reaction-siblings` and the demo write per ground-truth
/// role: B's first this-many sampled futures, replayed.
pub const REACTION_SIBLINGS_PER_ROLE: usize = 3;

/// The label table's file for cache shard `index`.
pub fn shard_table_name(index: usize) -> String {
    format!("labels-{index:05}.parquet")
}

/// Writes the label table of each cache shard, the ψ histogram (paper Fig. 3) and
/// `summary.json` in `out` from labelled scenes (by an ensemble of `predictors`), and returns
/// the rows and the summary.
pub fn write_label_outputs(
    out: &Path,
    dataset: &PreparedDataset,
    labelled: &[SceneLabels],
    options: LabelOptions,
    truth: Option<&[GroundTruth]>,
    predictors: usize,
) -> anyhow::Result<(Vec<LabelRow>, LabelSummary)> {
    std::fs::create_dir_all(out).with_context(|| format!("creating {}", out.display()))?;
    let index = truth
        .filter(|_| options.audience == scbg_courtesy::Audience::Pair)
        .map(crate::fidelity::TruthIndex::new);
    let mut rows = Vec::new();
    let mut next = labelled.iter().peekable();
    for (si, range) in shard_ranges(dataset).into_iter().enumerate() {
        let mut scenes = Vec::new();
        while let Some(s) = next.next_if(|s| range.contains(&s.index)) {
            scenes.push(s);
        }
        let shard_rows = scored_rows(&scenes, index.as_ref());
        write_label_table(&out.join(shard_table_name(si)), &shard_rows)?;
        rows.extend(shard_rows);
    }
    let summary = finish_labels(out, &rows, options, truth, predictors, None)?;
    Ok((rows, summary))
}

/// The label-table rows of labelled scenes, scored by the oracle where a ground-truth line
/// describes the scene (in parallel: the oracle re-simulates each scene some 40 times).
fn scored_rows(
    scenes: &[&SceneLabels],
    truth: Option<&crate::fidelity::TruthIndex<'_>>,
) -> Vec<LabelRow> {
    use rayon::prelude::*;
    scenes
        .par_iter()
        .map(|s| s.rows(truth.and_then(|t| t.get(&s.scenario_id))))
        .collect::<Vec<_>>()
        .concat()
}

/// Writes the reaction siblings of one cache shard's ground-truth roles
/// (`dir/reaction-NNNNN.tfrecord`, atomically).
fn write_reaction_siblings(
    dir: &Path,
    shard: usize,
    scenes: &[&SceneLabels],
    truth: &crate::fidelity::TruthIndex<'_>,
    samples: usize,
    per_role: usize,
) -> anyhow::Result<()> {
    use rayon::prelude::*;
    std::fs::create_dir_all(dir).with_context(|| format!("creating {}", dir.display()))?;
    let siblings: Vec<scbg_scene::Scene> = scenes
        .par_iter()
        .flat_map_iter(|s| {
            let t = truth.get(&s.scenario_id);
            s.roles
                .iter()
                .flat_map(move |r| {
                    t.map(|t| crate::fidelity::reaction_scenes(t, r, samples, per_role))
                        .unwrap_or_default()
                })
                .collect::<Vec<_>>()
        })
        .collect();
    scbg_womd::write_scenes(&dir.join(reaction_file_name(shard)), siblings.iter())?;
    Ok(())
}

/// The reaction siblings' file for cache shard `index`.
fn reaction_file_name(index: usize) -> String {
    format!("reaction-{index:05}.tfrecord")
}

/// The histogram and summary.json of a finished label table.
fn finish_labels(
    out: &Path,
    rows: &[LabelRow],
    options: LabelOptions,
    truth: Option<&[GroundTruth]>,
    predictors: usize,
    validation_fraction: Option<f64>,
) -> anyhow::Result<LabelSummary> {
    let logged: Vec<f64> = rows
        .iter()
        .filter(|r| r.sample == 0)
        .map(|r| f64::from(r.psi))
        .collect();
    scbg_plot::histogram(
        &logged,
        40,
        "courtesy ψ of logged trajectories (m/s)",
        &out.join("psi_histogram.png"),
    )?;
    let mut summary = LabelSummary {
        predictors,
        ..LabelSummary::of(rows, options, truth)
    };
    if let (Some(vf), Some(truth), Some(_)) = (validation_fraction, truth, &summary.fidelity) {
        use scbg_train::data::{Split, split_of};
        let held_out: Vec<LabelRow> = rows
            .iter()
            .filter(|r| split_of(&r.scenario_id, vf) == Split::Validation)
            .cloned()
            .collect();
        summary.fidelity_held_out =
            crate::fidelity::fidelity(&held_out, truth, summary.samples_per_pair);
    }
    if let (Some(truth), Some(_)) = (truth, &summary.fidelity) {
        crate::fidelity::write_scatter(rows, truth, &out.join("psi_fidelity.png"))?;
    }
    scbg_base::atomic::write_json(out.join("summary.json"), &summary)?;
    Ok(summary)
}

/// The global scene indices of each cache shard, in manifest order.
fn shard_ranges(dataset: &PreparedDataset) -> Vec<std::ops::Range<usize>> {
    let mut start = 0;
    dataset
        .manifest
        .shards
        .iter()
        .map(|s| {
            let r = start..start + s.scenarios;
            start = r.end;
            r
        })
        .collect()
}

/// `scbg label`: labels every pair role of the cache, one Parquet table per shard (a shard
/// whose table exists is read back, not labelled again, if [`LABEL_OPTIONS_FILE`] shows the
/// same options), then the histogram and summary.
pub fn label_cache(
    run: &LabelRun,
    progress: &dyn Progress,
) -> anyhow::Result<(Vec<LabelRow>, LabelSummary)> {
    ensure_request!(
        run.num_shards > 0 && run.shard_index < run.num_shards,
        "shard index {} is not below the number of shards {}",
        run.shard_index,
        run.num_shards
    );
    let ckpt = Checkpoint::read(&run.model)?;
    let device = scbg_model::device::device(&ckpt.train_config.backend)?;
    let model = ckpt.load_model(&run.model, &device)?;
    let mut loaded = vec![(model, ckpt)];
    for dir in &run.ensemble {
        let ckpt = Checkpoint::read(dir)?;
        let model = ckpt.load_model(dir, &device)?;
        loaded.push((model, ckpt));
    }
    let members: Vec<(&Multipath, &Checkpoint)> = loaded.iter().map(|(m, c)| (m, c)).collect();
    ensemble_features(&members.iter().map(|&(_, c)| c).collect::<Vec<_>>())?;
    let dataset = PreparedDataset::open(&run.data)?;
    let truth = run
        .ground_truth
        .as_deref()
        .map(crate::synth::read_ground_truth)
        .transpose()?;
    std::fs::create_dir_all(&run.out).with_context(|| format!("creating {}", run.out.display()))?;
    let shards = shard_ranges(&dataset);
    claim_label_folder(run, members.len(), shards.len())?;
    // The oracle scores ψ toward A alone: ψ_true only for the paper's pair audience.
    let index = truth
        .as_deref()
        .filter(|_| run.options.audience == scbg_courtesy::Audience::Pair)
        .map(crate::fidelity::TruthIndex::new);
    let mut rows = Vec::new();
    for (si, range) in shards.into_iter().enumerate() {
        if si % run.num_shards != run.shard_index {
            continue;
        }
        let path = run.out.join(shard_table_name(si));
        let siblings_done = run
            .reaction_siblings
            .as_ref()
            .is_none_or(|(dir, _)| dir.join(reaction_file_name(si)).is_file());
        if path.is_file() && siblings_done {
            rows.extend(read_label_table(&path)?);
            continue;
        }
        let labelled = label_scenes_ensemble(
            &members,
            &device,
            &dataset,
            range,
            &|_| true,
            run.options,
            run.seed,
            progress,
        )?;
        let scenes: Vec<&SceneLabels> = labelled.iter().collect();
        if let (Some((dir, per_role)), Some(index)) = (&run.reaction_siblings, index.as_ref()) {
            write_reaction_siblings(
                dir,
                si,
                &scenes,
                index,
                run.options.labelled_samples(),
                *per_role,
            )?;
        }
        let shard_rows = scored_rows(&scenes, index.as_ref());
        write_label_table(&path, &shard_rows)?;
        rows.extend(shard_rows);
    }
    if run.num_shards > 1 {
        progress.note(&format!(
            "labelled shard(s) {} of every {} of {}: {} rows; the summary is written by a run without --num-shards",
            run.shard_index,
            run.num_shards,
            run.data.display(),
            rows.len()
        ));
        let summary = LabelSummary {
            predictors: members.len(),
            ..LabelSummary::of(&rows, run.options, None)
        };
        return Ok((rows, summary));
    }
    ensure_request!(
        !rows.is_empty(),
        "no interacting pairs to label in {}",
        run.data.display()
    );
    let summary = finish_labels(
        &run.out,
        &rows,
        run.options,
        truth.as_deref(),
        members.len(),
        Some(loaded[0].1.train_config.validation_fraction),
    )?;
    progress.note(&summary.to_text());
    Ok((rows, summary))
}

#[cfg(test)]
mod tests {
    /// The labels' lane moves may ask of A what the synthetic world's least courteous cut-in
    /// asks (and the closed loop's guard accepts): the two must not drift apart.
    #[test]
    fn the_default_lane_move_room_is_the_worlds_least_courteous_cut_in() {
        let room = super::DEFAULT_LANE_MOVE_ROOM;
        assert_eq!(
            f64::from(room.braking_mps2),
            scbg_synth::LEAST_COURTEOUS_CUT_IN_BRAKE_MPS2
        );
        assert_eq!(f64::from(room.reaction_s), scbg_synth::CUT_IN_REACTION_S);
    }
}
