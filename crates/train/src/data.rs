//! Training samples from a prepared cache: every valid vehicle of every window (marginal) and
//! both directions of every interacting pair (conditional), split by scenario.

use rayon::prelude::*;
use scbg_features::cache::{CacheError, PreparedDataset};
use scbg_features::{AgentSample, FeatureStats, SampleBuilder, marginal_targets};

use crate::config::TrainConfig;

/// Which part of the data a scenario belongs to.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Split {
    /// Used for training.
    Train,
    /// Held out for validation.
    Validation,
}

/// The split of a scenario: [`Split::Validation`] for about `validation_fraction` of the ids.
/// FNV-1a (then SplitMix-mixed) of the scenario id: a stable split that does not depend on file
/// order. A variant of a scene (its id + `~…`, e.g. a counterfactual sibling) shares the
/// scene's split: only the part before the first `~` counts. A scene of a held-out family
/// (its id ends with [`scbg_base::split::HELD_OUT_MARK`]) is always validation.
pub fn split_of(scenario_id: &str, validation_fraction: f64) -> Split {
    if scbg_base::split::is_held_out(scenario_id) {
        return Split::Validation;
    }
    // FNV's high bits are poorly mixed for short, similar ids: finish with SplitMix64's mixer.
    let h = scbg_base::seed::mix(base_id_hash(scenario_id), 0);
    if ((h >> 11) as f64 / (1u64 << 53) as f64) < validation_fraction {
        Split::Validation
    } else {
        Split::Train
    }
}

/// FNV-1a of a scenario id's base (the part before the first `~`, shared by its variants).
pub(crate) fn base_id_hash(scenario_id: &str) -> u64 {
    let mut h: u64 = 0xcbf2_9ce4_8422_2325;
    for b in scbg_base::split::base_id(scenario_id).bytes() {
        h ^= u64::from(b);
        h = h.wrapping_mul(0x0000_0100_0000_01b3);
    }
    h
}

/// Samples of one split: marginal samples and both directions of each pair (conditional).
#[derive(Debug, Default)]
pub struct SampleSet {
    /// The samples, in cache order (standardised once [`standardise`] has run).
    pub samples: Vec<AgentSample>,
}

impl SampleSet {
    /// Number of samples.
    pub fn len(&self) -> usize {
        self.samples.len()
    }

    /// Whether there are no samples.
    pub fn is_empty(&self) -> bool {
        self.samples.is_empty()
    }

    /// Samples that carry a condition (pair samples).
    pub fn conditional(&self) -> impl Iterator<Item = &AgentSample> {
        self.samples.iter().filter(|s| s.has_condition())
    }
}

/// Builds the train and validation sample sets (raw, not yet standardised), in cache order
/// (the reaction cache's samples only when they join from the start).
pub fn load_samples(
    dataset: &PreparedDataset,
    config: &TrainConfig,
) -> Result<(SampleSet, SampleSet), CacheError> {
    let features = config.feature_config();
    let per_scene: Vec<(Split, Vec<AgentSample>)> = (0..dataset.len())
        .into_par_iter()
        .map(|i| {
            let scene = dataset.scene(i)?;
            let split = split_of(&scene.scenario_id, config.validation_fraction);
            let mut builder = SampleBuilder::new(&scene, &features);
            let mut out = Vec::new();
            for (w, pairs) in scene.windows.iter().zip(&scene.pairs) {
                let mut targets = marginal_targets(
                    &scene,
                    w,
                    features.future_steps,
                    config.min_future_valid_steps,
                );
                // Keep the pair members first, then the closest others, up to the cap.
                let in_pair = |t: usize| pairs.iter().any(|p| p.first == t || p.second == t);
                targets.sort_by_key(|&t| (!in_pair(t), t));
                if config.max_targets_per_window > 0 {
                    targets.truncate(config.max_targets_per_window);
                }
                for t in targets {
                    out.push(builder.sample(w, t, None).expect("targets are valid now"));
                }
                for p in pairs {
                    for (a, b) in [(p.first, p.second), (p.second, p.first)] {
                        out.extend(conditional_sample(&mut builder, w, a, b, config));
                    }
                }
            }
            Ok((split, out))
        })
        .collect::<Result<_, CacheError>>()?;
    let (mut train, mut val) = (SampleSet::default(), SampleSet::default());
    for (split, samples) in per_scene {
        match split {
            Split::Train => train.samples.extend(samples),
            Split::Validation => val.samples.extend(samples),
        }
    }
    if let Some(dir) = &config.counterfactual_cache {
        let siblings = PreparedDataset::open(dir)?;
        train
            .samples
            .extend(counterfactual_samples(&siblings, config)?);
    }
    if let (Some(dir), None) = (&config.reaction_cache, config.reaction_from_epoch) {
        train.samples.extend(reaction_samples(dir, config)?);
    }
    Ok((train, val))
}

/// The training samples of the reaction cache in `dir` (see [`TrainConfig::reaction_cache`]):
/// [`counterfactual_samples`] whose condition is required.
pub fn reaction_samples(
    dir: &std::path::Path,
    config: &TrainConfig,
) -> Result<Vec<AgentSample>, CacheError> {
    let siblings = PreparedDataset::open(dir)?;
    Ok(counterfactual_samples(&siblings, config)?
        .into_iter()
        .map(|s| AgentSample {
            condition_required: true,
            ..s
        })
        .collect())
}

/// The training samples of a cache of counterfactual siblings (see
/// [`TrainConfig::counterfactual_cache`]): for each sibling of a training-split scene, the SDC
/// conditioned on the other member of each pair it is in.
pub fn counterfactual_samples(
    siblings: &PreparedDataset,
    config: &TrainConfig,
) -> Result<Vec<AgentSample>, CacheError> {
    let features = config.feature_config();
    let per_scene: Vec<Vec<AgentSample>> = (0..siblings.len())
        .into_par_iter()
        .map(|i| {
            let scene = siblings.scene(i)?;
            if split_of(&scene.scenario_id, config.validation_fraction) != Split::Train {
                return Ok(Vec::new());
            }
            let mut builder = SampleBuilder::new(&scene, &features);
            let mut out = Vec::new();
            for (w, pairs) in scene.windows.iter().zip(&scene.pairs) {
                for p in pairs {
                    let (target, condition) =
                        match (scene.tracks[p.first].is_sdc, scene.tracks[p.second].is_sdc) {
                            (true, false) => (p.first, p.second),
                            (false, true) => (p.second, p.first),
                            _ => continue,
                        };
                    out.extend(conditional_sample(
                        &mut builder,
                        w,
                        target,
                        condition,
                        config,
                    ));
                }
            }
            Ok(out)
        })
        .collect::<Result<_, CacheError>>()?;
    Ok(per_scene.into_iter().flatten().collect())
}

/// `target`'s sample conditioned on `condition`'s future, if it has enough valid future steps.
fn conditional_sample(
    builder: &mut SampleBuilder<'_>,
    window: &scbg_features::Window,
    target: usize,
    condition: usize,
    config: &TrainConfig,
) -> Option<AgentSample> {
    builder
        .sample(window, target, Some(condition))
        .ok()
        .filter(|s| s.future_valid.iter().filter(|&&v| v).count() >= config.min_future_valid_steps)
}

/// Fits standardisation statistics on (up to 4,000 of) the training samples and applies them.
pub fn standardise(train: &mut SampleSet, val: &mut SampleSet) -> FeatureStats {
    let step = (train.len() / 4000).max(1);
    let stats = FeatureStats::fit(train.samples.iter().step_by(step));
    normalise(&stats, train, val);
    stats
}

/// Applies standardisation statistics (fitted here or a checkpoint's) to both sets.
pub fn normalise(stats: &FeatureStats, train: &mut SampleSet, val: &mut SampleSet) {
    for s in train.samples.iter_mut().chain(val.samples.iter_mut()) {
        stats.normalize(s);
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn split_is_stable_and_roughly_proportional() {
        // Pinned: which of s0..s39 are held out at 0.2. A change to the hash moves scenes
        // between the splits of every cache and checkpoint already made.
        let held_out: Vec<usize> = (0..40)
            .filter(|i| split_of(&format!("s{i}"), 0.2) == Split::Validation)
            .collect();
        assert_eq!(held_out, [3, 9, 14, 19, 32]);
        // A larger fraction only adds scenes to the validation split.
        assert!((0..1000).all(|i| {
            let id = format!("s{i}");
            split_of(&id, 0.2) == Split::Train || split_of(&id, 0.3) == Split::Validation
        }));
        let val = (0..10_000)
            .filter(|i| split_of(&format!("s{i}"), 0.2) == Split::Validation)
            .count();
        assert!((1700..2300).contains(&val), "{val}");
        assert!((0..100).all(|i| split_of(&format!("s{i}"), 0.0) == Split::Train));
        assert!((0..100).all(|i| split_of(&format!("s{i}+unseen~cf1"), 0.0) == Split::Validation));
        // A variant shares its scene's split.
        assert!(
            (0..100)
                .all(|i| split_of(&format!("s{i}~cf3"), 0.2) == split_of(&format!("s{i}"), 0.2))
        );
    }
}
