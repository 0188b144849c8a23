//! The trained models of an SCBG ([`Scbg`]), the checks of a request and the pair's samples
//! and labels every inference starts from. The choice of B's future is [`crate::plan`]'s; the
//! open-loop generation with J_φ's measurement is [`crate::generate`]'s.

use burn::tensor::Device;
use rand::SeedableRng;
use scbg_courtesy::label::{LabelOptions, LabelledRole, label_built_role};
use scbg_features::{
    FeatureConfig, FeatureStats, PreparedScene, SampleBuilder, SampleError, Window,
};
use scbg_model::Multipath;

use crate::courtesy::Policy;
use crate::model::Generator;
use crate::range::RangePredictor;

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

impl Scbg {
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
