//! Feature outputs are pinned: a hash of every sample (marginal and both pair directions, every
//! window) of every shared real scene. Speed work on the feature code must not change a bit;
//! a deliberate change of the features updates `EXPECTED` (run with `--nocapture` to see the
//! new value) and says why in the commit.

mod common;

use scbg_features::{AgentSample, FeatureConfig, SampleBuilder, WindowConfig, marginal_targets};

/// FNV-1a over every field of the samples.
struct Fnv(u64);

impl Fnv {
    fn bytes(&mut self, b: &[u8]) {
        for &x in b {
            self.0 = (self.0 ^ u64::from(x)).wrapping_mul(0x100_0000_01b3);
        }
    }
    fn f32s(&mut self, v: &[f32]) {
        for x in v {
            self.bytes(&x.to_bits().to_le_bytes());
        }
    }
    fn bools(&mut self, v: &[bool]) {
        for &x in v {
            self.bytes(&[u8::from(x)]);
        }
    }
    fn sample(&mut self, s: &AgentSample) {
        self.bytes(&s.target_track_id.to_le_bytes());
        self.bytes(&s.condition_track_id.unwrap_or(-1).to_le_bytes());
        for v in [
            &s.target_history,
            &s.target_diffs,
            &s.others_history,
            &s.others_diffs,
            &s.road_segments,
            &s.condition_future_xy_m,
            &s.future_xy_m,
            &s.future_heading_rad,
        ] {
            self.f32s(v);
        }
        self.f32s(&s.current_velocity_mps);
        for v in [
            &s.others_valid,
            &s.road_valid,
            &s.condition_future_valid,
            &s.future_valid,
        ] {
            self.bools(v);
        }
    }
}

/// The hash of the original (pre-speed-work) feature code on the shared real files.
const EXPECTED: u64 = 0x65d3_041c_f634_cc25;

#[test]
fn features_of_the_shared_real_scenes_are_unchanged() {
    let Some(scenes) = common::real_prepared_scenes() else {
        return; // real_data_dir said why (and fails under CI)
    };
    let (future_steps, features) = (
        WindowConfig::default().future_steps,
        FeatureConfig::default(),
    );
    let mut hash = Fnv(0xcbf2_9ce4_8422_2325);
    let mut samples = 0;
    for prepared in &scenes {
        let mut builder = SampleBuilder::new(prepared, &features);
        for (w, pairs) in prepared.windows.iter().zip(&prepared.pairs) {
            for target in marginal_targets(prepared, w, future_steps, 1) {
                hash.sample(&builder.sample(w, target, None).unwrap());
                samples += 1;
            }
            for p in pairs {
                for (a, b) in [(p.first, p.second), (p.second, p.first)] {
                    hash.sample(&builder.sample(w, a, Some(b)).unwrap());
                    samples += 1;
                }
            }
        }
    }
    println!("feature hash {:#018x} over {samples} samples", hash.0);
    assert!(samples > 5000, "{samples} samples");
    assert_eq!(
        hash.0, EXPECTED,
        "feature outputs changed ({samples} samples)"
    );
}
