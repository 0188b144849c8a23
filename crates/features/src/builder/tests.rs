use super::*;
use crate::prepared::{InteractingPair, PairSource};
use crate::sample::tests::{scene, straight_track};
use crate::sample::track_history;

/// A scene of `n` tracks at pseudo-random places, some with gaps in their history, and
/// one pair in its only window.
fn crowded_scene(n: usize, seed: u64) -> PreparedScene {
    let mut state = seed;
    let mut next = move || {
        state = state
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (state >> 40) as f32 / (1u64 << 24) as f32
    };
    let mut s = scene();
    s.tracks = (0..n)
        .map(|i| {
            let mut t = straight_track(i as i64 + 1, 0.0, 2.0 + 10.0 * next(), 91);
            let (x0, y0, h) = (80.0 * next() - 40.0, 80.0 * next() - 40.0, 6.0 * next());
            for x in &mut t.x_m {
                *x += x0;
            }
            for y in &mut t.y_m {
                *y += y0;
            }
            t.heading_rad.fill(h);
            // Some tracks miss steps of the history (one misses all but "now").
            if i % 3 == 1 {
                t.valid[9] = false;
            }
            if i % 5 == 2 {
                t.valid[..10].fill(false);
            }
            t
        })
        .collect();
    s.pairs = vec![vec![InteractingPair {
        first: 0,
        second: n - 1,
        source: PairSource::Mined,
    }]];
    s
}

/// The conditioned sample computed directly: every other agent ranked, the condition
/// agent first, each row from `track_history`.
fn others_directly(
    s: &PreparedScene,
    w: &Window,
    target: usize,
    condition: usize,
    cfg: &FeatureConfig,
) -> (Vec<f32>, Vec<f32>, Vec<bool>) {
    let now = w.current_step;
    let t = &s.tracks[target];
    let frame = AgentFrame::new(
        f64::from(t.x_m[now]),
        f64::from(t.y_m[now]),
        f64::from(t.heading_rad[now]),
    );
    let h = cfg.history_steps;
    let mut ranked: Vec<(f32, usize)> = (0..s.tracks.len())
        .filter(|&i| i != target)
        .filter_map(|i| {
            let o = &s.tracks[i];
            let last = (0..h)
                .rev()
                .filter_map(|k| w.history_step(k, h))
                .find(|&st| o.valid[st])?;
            let (dx, dy) = (o.x_m[last] - t.x_m[now], o.y_m[last] - t.y_m[now]);
            Some((
                if i == condition {
                    -1.0
                } else {
                    dx * dx + dy * dy
                },
                i,
            ))
        })
        .collect();
    ranked.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    ranked.truncate(cfg.max_other_agents);
    let (hs, ds) = (h * AGENT_FEATURES, (h - 1) * DIFF_FEATURES);
    let mut hist = vec![0.0; cfg.max_other_agents * hs];
    let mut diffs = vec![0.0; cfg.max_other_agents * ds];
    let mut valid = vec![false; cfg.max_other_agents];
    for (k, &(_, i)) in ranked.iter().enumerate() {
        track_history(
            &s.tracks[i],
            w,
            h,
            &frame,
            &mut hist[k * hs..(k + 1) * hs],
            &mut diffs[k * ds..(k + 1) * ds],
        );
        valid[k] = true;
    }
    (hist, diffs, valid)
}

#[test]
fn conditioned_samples_from_kept_marginals_equal_direct_ones() {
    for (seed, max_others) in [(1, 3), (2, 4), (3, 32), (4, 1), (5, 0)] {
        let s = crowded_scene(12, seed);
        let w = s.windows[0];
        let cfg = FeatureConfig {
            max_other_agents: max_others,
            max_road_segments: 4,
            ..Default::default()
        };
        let mut builder = SampleBuilder::new(&s, &cfg);
        // Every order of asking: marginal first (pair member or not), conditioned first,
        // the same target under several conditions.
        for target in 0..s.tracks.len() {
            if !s.tracks[target].valid[w.current_step] {
                continue;
            }
            let marginal = builder.sample(&w, target, None).unwrap();
            let fresh = SampleBuilder::new(&s, &cfg)
                .sample(&w, target, None)
                .unwrap();
            assert_eq!(marginal, fresh);
            for condition in (0..s.tracks.len()).rev() {
                let c = builder.sample(&w, target, Some(condition)).unwrap();
                let (hist, diffs, valid) = others_directly(&s, &w, target, condition, &cfg);
                let why = format!("seed {seed}, target {target}, condition {condition}");
                assert_eq!(c.others_history, hist, "{why}");
                assert_eq!(c.others_diffs, diffs, "{why}");
                assert_eq!(c.others_valid, valid, "{why}");
                assert_eq!(c.condition_track_id, Some(s.tracks[condition].id));
                // The rest is the marginal sample's.
                assert_eq!(
                    (&c.road_segments, &c.target_history, &c.future_xy_m),
                    (
                        &marginal.road_segments,
                        &marginal.target_history,
                        &marginal.future_xy_m
                    ),
                );
                let again = SampleBuilder::new(&s, &cfg)
                    .sample(&w, target, Some(condition))
                    .unwrap();
                assert_eq!(c, again, "{why}");
            }
        }
    }
}
