//! The [`Model`] every front end calls: a loaded model folder with its policy and the pair
//! contexts it keeps.

use std::collections::{HashMap, VecDeque};
use std::path::{Path, PathBuf};
use std::sync::{Arc, Mutex, Weak};

use scbg_generator::{Policy, Variant};
use scbg_scene::Scene;

use crate::Courtesy;
pub use crate::artefact::*;
use crate::generate::{CourtesyOf, Generation, PairContext};

/// How [`Model::load`] loads a model folder.
#[derive(Debug, Clone, PartialEq)]
pub struct LoadOptions {
    /// A predictor folder overriding the one `generator.json` names.
    pub predictor: Option<PathBuf>,
    /// How a courtesy becomes B's future: the learned generator (default) or sample and rank.
    pub policy: Policy,
    /// Pair contexts kept for repeated generation (the oldest half goes when it is full).
    pub cached_pairs: usize,
}

impl Default for LoadOptions {
    fn default() -> Self {
        Self {
            predictor: None,
            policy: Policy::Generator,
            cached_pairs: 1024,
        }
    }
}

/// A loaded model with its policy, as every front end uses it: [`Model::generate`] B's future
/// at a courtesy, [`Model::courtesy_of`] a given future, and closed-loop
/// [`Session`](crate::session::Session)s.
///
/// Generation keeps what every courtesy of a pair shares (the pair's samples, B's embedding,
/// E[r(Y_A) | x], the predicted range, the scene's lane segments) per (scene, A, B), so asking
/// the same pair again costs the generator, lane keeping and J_φ only. A scene is known by its allocation: pass the same
/// `Arc<Scene>` to reuse the context; a scene dropped by its owner drops out of the cache.
#[derive(Debug)]
pub struct Model {
    loaded: LoadedScbg,
    contexts: Mutex<PairContexts>,
    cached_pairs: usize,
}

/// Pair contexts by (scene allocation, A, B), each with a weak handle on its scene (the address
/// names the scene only while it lives) and the order of insertion.
type PairContexts = (
    HashMap<(usize, i64, i64), (Weak<Scene>, Arc<PairContext>)>,
    VecDeque<(usize, i64, i64)>,
);

impl Model {
    /// Loads a generator folder (from `scbg train generator`) and its predictor, or an ensemble
    /// folder's members (`ensemble.json`).
    pub fn load(dir: &Path, options: &LoadOptions) -> anyhow::Result<Self> {
        let mut loaded = load_scbg(dir, options.predictor.as_deref())?;
        loaded.set_policy(options.policy);
        Ok(Self {
            loaded,
            contexts: Mutex::new((HashMap::new(), VecDeque::new())),
            cached_pairs: options.cached_pairs.max(1),
        })
    }

    /// How a courtesy becomes B's future.
    pub fn policy(&self) -> Policy {
        self.loaded.scbg.policy
    }

    /// The generator's training variant.
    pub fn variant(&self) -> Variant {
        self.loaded.checkpoint.variant
    }

    /// Whose reward the model's courtesy counts: `pair` (A alone) or `neighbours <radius> m
    /// <sum|proximity>`.
    pub fn audience(&self) -> String {
        self.loaded.checkpoint.labels.audience.describe()
    }

    /// How many generators plan together: 1, or an ensemble folder's members (B's future at
    /// a courtesy is their medoid, `crate::generate::medoid`).
    pub fn members(&self) -> usize {
        self.loaded.members().count()
    }

    /// The model folder's description (an ensemble's first member's).
    pub fn checkpoint(&self) -> &GeneratorCheckpoint {
        &self.loaded.checkpoint
    }

    /// The loaded networks (for the research pipeline and the simulator's planner).
    pub fn loaded(&self) -> &LoadedScbg {
        &self.loaded
    }

    /// B's futures at each courtesy for the pair (A = `a`, B = `b`) of `scene`, starting after
    /// its current step, in the world frame.
    pub fn generate(
        &self,
        scene: &Arc<Scene>,
        a: i64,
        b: i64,
        courtesy: &[Courtesy],
    ) -> anyhow::Result<Generation> {
        let context = self.pair_context(scene, a, b)?;
        let trajectories = crate::generate::generate_in(&self.loaded, &context, courtesy)?;
        Ok(Generation {
            scenario_id: scene.scenario_id.clone(),
            a_id: a,
            b_id: b,
            current_step: scene.current_step,
            variant: self.variant(),
            trajectories,
        })
    }

    /// ψ of a given world-frame future of B (80 points after the scene's current step) toward
    /// A, with both expectations (paper eq. 2). Shares the pair's cached context with
    /// [`Self::generate`].
    pub fn courtesy_of(
        &self,
        scene: &Arc<Scene>,
        a: i64,
        b: i64,
        future_world: &[[f64; 2]],
    ) -> anyhow::Result<CourtesyOf> {
        let context = self.pair_context(scene, a, b)?;
        crate::generate::courtesy_in(&self.loaded, &context, future_world)
    }

    /// The pair's context, from the cache or computed and kept.
    fn pair_context(&self, scene: &Arc<Scene>, a: i64, b: i64) -> anyhow::Result<Arc<PairContext>> {
        let key = (Arc::as_ptr(scene) as usize, a, b);
        {
            let (map, _) = &*self.contexts.lock().expect("pair contexts");
            if let Some((weak, context)) = map.get(&key)
                && weak.upgrade().is_some_and(|s| Arc::ptr_eq(&s, scene))
            {
                return Ok(context.clone());
            }
        }
        let context = Arc::new(crate::generate::pair_context(&self.loaded, scene, a, b)?);
        let (map, order) = &mut *self.contexts.lock().expect("pair contexts");
        if map.len() >= self.cached_pairs {
            // Scenes gone first, then the oldest half.
            map.retain(|_, (weak, _)| weak.strong_count() > 0);
            order.retain(|k| map.contains_key(k));
            while map.len() >= self.cached_pairs.div_ceil(2) {
                let Some(old) = order.pop_front() else { break };
                map.remove(&old);
            }
        }
        if map
            .insert(key, (Arc::downgrade(scene), context.clone()))
            .is_none()
        {
            order.push_back(key);
        }
        Ok(context)
    }

    /// Pair contexts kept now.
    pub fn cached_pairs(&self) -> usize {
        self.contexts.lock().expect("pair contexts").0.len()
    }
}
