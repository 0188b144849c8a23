use super::*;

/// A deterministic generator (no dependency needed for a test's random layouts).
struct Lcg(u64);
impl Lcg {
    fn next(&mut self) -> f32 {
        self.0 = self
            .0
            .wrapping_mul(6_364_136_223_846_793_005)
            .wrapping_add(1_442_695_040_888_963_407);
        (self.0 >> 40) as f32 / (1u64 << 24) as f32
    }
    fn range(&mut self, lo: f32, hi: f32) -> f32 {
        lo + (hi - lo) * self.next()
    }
}

#[test]
fn total_order_bits_order_like_total_cmp() {
    let xs = [
        f32::NEG_INFINITY,
        -1e30,
        -1.0,
        -1e-40,
        -0.0,
        0.0,
        1e-40,
        1.0,
        1e30,
        f32::INFINITY,
        f32::NAN,
        -f32::NAN,
    ];
    for &a in &xs {
        assert_eq!(
            f32_from_total_order_bits(total_order_bits(a)).to_bits(),
            a.to_bits()
        );
        for &b in &xs {
            assert_eq!(
                total_order_bits(a).cmp(&total_order_bits(b)),
                a.total_cmp(&b),
                "{a} vs {b}"
            );
        }
    }
}

fn check(index: &SegmentIndex, scratch: &mut Scratch, origin: [f32; 2], p: usize, radius_m: f32) {
    let mut got = Vec::new();
    index.closest(origin, p, radius_m, scratch, &mut got);
    let want = closest_brute_force(index, origin, p, radius_m);
    assert_eq!(
        got.iter().map(|x| (x.0, x.1.to_bits())).collect::<Vec<_>>(),
        want.iter()
            .map(|x| (x.0, x.1.to_bits()))
            .collect::<Vec<_>>(),
        "origin {origin:?}, p {p}, radius {radius_m}"
    );
}

/// Polylines of short steps (a road network), a few long segments, exact duplicates
/// (ties), degenerate points.
fn layout(rng: &mut Lcg, polylines: usize, extent: f32) -> SegmentIndex {
    let (mut a, mut b) = (Vec::new(), Vec::new());
    for _ in 0..polylines {
        let mut p = [rng.range(-extent, extent), rng.range(-extent, extent)];
        let heading = rng.range(0.0, std::f32::consts::TAU);
        let step = rng.range(0.3, 4.0);
        for _ in 0..(rng.range(1.0, 60.0) as usize) {
            let q = [p[0] + step * heading.cos(), p[1] + step * heading.sin()];
            a.push(p);
            b.push(q);
            p = q;
        }
    }
    for _ in 0..polylines / 4 {
        let p = [rng.range(-extent, extent), rng.range(-extent, extent)];
        let q = [rng.range(-extent, extent), rng.range(-extent, extent)];
        a.push(p);
        b.push(q);
        a.push(p); // duplicate: equal distances, ranked by index
        b.push(q);
        a.push(q); // a point
        b.push(q);
    }
    let kind = vec![RoadKind::LaneSurfaceStreet; a.len()];
    SegmentIndex::new(a, b, kind)
}

#[test]
fn same_as_brute_force_on_random_layouts() {
    let mut rng = Lcg(7);
    for (polylines, extent) in [
        (0, 10.0),
        (1, 10.0),
        (40, 60.0),
        (300, 400.0),
        (200, 3000.0),
    ] {
        let index = layout(&mut rng, polylines, extent);
        let mut scratch = Scratch::default();
        // Radius outermost: the scratch's offset table is made once per radius.
        for radius in [5.0, 150.0, 5000.0, f32::INFINITY] {
            for _ in 0..30 {
                // Queries inside, at the edge of and far outside the layout.
                let spread = [0.5 * extent, extent, 3.0 * extent][(rng.next() * 3.0) as usize];
                let origin = [rng.range(-spread, spread), rng.range(-spread, spread)];
                for p in [1, 8, 128, 5000] {
                    check(&index, &mut scratch, origin, p, radius);
                }
            }
        }
    }
}

/// `any_within` finds a segment exactly when one of those it accepts passes within the
/// radius (every segment checked), inside, at the edge of and outside the layout.
#[test]
fn any_within_is_the_brute_force_answer() {
    let mut rng = Lcg(11);
    let mut hits = [0usize; 2];
    for (polylines, extent) in [(0, 10.0), (40, 60.0), (300, 400.0)] {
        let index = layout(&mut rng, polylines, extent);
        for radius in [0.5f32, 1.5, 12.0, 40.0] {
            for _ in 0..200 {
                let origin = [rng.range(-extent, extent), rng.range(-extent, extent)];
                // Only segments heading right (x increasing) count.
                let accept = |a: [f32; 2], b: [f32; 2]| b[0] > a[0];
                let brute = (0..index.seg_a.len()).any(|i| {
                    let (a, b) = (index.seg_a[i], index.seg_b[i]);
                    let q = closest_point_to_origin(
                        [a[0] - origin[0], a[1] - origin[1]],
                        [b[0] - origin[0], b[1] - origin[1]],
                    );
                    q[0] * q[0] + q[1] * q[1] <= radius * radius && accept(a, b)
                });
                assert_eq!(
                    index.any_within(origin, radius, accept),
                    brute,
                    "{origin:?}"
                );
                hits[usize::from(brute)] += 1;
            }
        }
    }
    assert!(hits[0] > 100 && hits[1] > 100, "{hits:?}");
}

#[test]
fn same_as_brute_force_on_the_segments_of_real_scenes() {
    use crate::{PairConfig, PreparedScene, WindowConfig};
    let Some(paths) = scbg_womd::fixtures::real_tfrecords() else {
        return; // real_data_dir said why (and fails under CI)
    };
    let mut queries = 0;
    for path in &paths {
        let file = scbg_womd::WomdFile::open(path).unwrap();
        let Ok(format) = file.detect_format() else {
            continue;
        };
        if format != scbg_womd::Format::Scenario {
            continue;
        }
        for scene in file.scenes() {
            let scene = scene.unwrap();
            let Ok(prepared) = PreparedScene::from_scene(
                &scene,
                &WindowConfig::default(),
                &PairConfig::default(),
                4,
            ) else {
                continue;
            };
            let index = SegmentIndex::from_road(&prepared.road);
            let mut scratch = Scratch::default();
            for w in &prepared.windows {
                for t in &prepared.tracks {
                    if t.valid_at(w.current_step as isize) {
                        let o = [t.x_m[w.current_step], t.y_m[w.current_step]];
                        check(&index, &mut scratch, o, 128, 150.0);
                        queries += 1;
                    }
                }
            }
        }
    }
    assert!(queries > 1000, "{queries} queries");
}
