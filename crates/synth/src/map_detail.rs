//! Map detail varied the way real maps and other simulators vary it, so that a model trained on
//! the synthetic world does not depend on details only this world guarantees.
//!
//! Per scene, from its own random stream (so every other draw of the scene, and the oracle,
//! stay as they are; a counterfactual sibling gets its scene's map):
//! - **lane type**: kept as the family draws it (40 %), else every lane Undefined, Freeway or
//!   SurfaceStreet (20 % each) — what a map converted from another simulator typically has;
//! - **road lines**: all left out (30 %);
//! - **road edges**: on a road of parallel edges (cut-in, following), one of the two left out
//!   (25 %), so the road is bounded on one side only. Where edges close around corners (merge,
//!   crossing) every edge is kept: a gap there would put the road's own cars off the road by
//!   WOSAC's rule, whose sign comes from the nearest edge;
//! - **sampling**: every polyline resampled every 0.5 m (35 %), 1 m (35 %, as drawn) or 2.5 m
//!   (30 %), lane neighbour and boundary index ranges carried along.

use rand::{Rng, SeedableRng};
use rand_pcg::Pcg64Mcg;
use scbg_scene::{LaneType, Map, MapPoint};

/// The stream of [`vary`]'s draws, mixed with the scene's own seed.
const MAP_DETAIL_STREAM: u64 = 0x6d61_705f_6465_7461;

/// Varies the detail of `map`, the map of scene `(seed, index)`; `parallel_edges` says whether
/// its road edges are two parallel boundaries, one of which may then be left out.
pub(crate) fn vary(map: &mut Map, seed: u64, index: u64, parallel_edges: bool) {
    let mut rng = Pcg64Mcg::seed_from_u64(scbg_base::seed::mix(
        scbg_base::seed::mix(seed, index),
        MAP_DETAIL_STREAM,
    ));
    let lane_type = match rng.random_range(0..5) {
        0 => Some(LaneType::Undefined),
        1 => Some(LaneType::Freeway),
        2 => Some(LaneType::SurfaceStreet),
        _ => None,
    };
    if let Some(t) = lane_type {
        for lane in &mut map.lanes {
            lane.lane_type = t;
        }
    }
    if rng.random_bool(0.3) {
        map.road_lines.clear();
    }
    let drop_edge = rng.random_bool(0.25);
    let which = rng.random_range(0..map.road_edges.len().max(1));
    if drop_edge && parallel_edges && map.road_edges.len() >= 2 {
        map.road_edges.remove(which);
    }
    let spacing_m = match rng.random_range(0..20) {
        0..7 => 0.5,
        7..14 => 1.0,
        _ => 2.5,
    };
    if spacing_m != 1.0 {
        resample_map(map, spacing_m);
    }
}

/// Every polyline of `map` resampled every `spacing_m` of its length (ends kept); the index
/// ranges of lane neighbours and boundaries follow the lanes' new points.
fn resample_map(map: &mut Map, spacing_m: f64) {
    let mut index_maps = std::collections::HashMap::new();
    for lane in &mut map.lanes {
        let (points, index_of) = resample(&lane.polyline, spacing_m);
        lane.polyline = points;
        index_maps.insert(lane.id, index_of);
    }
    let mapped = |id: i64, i: i32| index_maps.get(&id).map_or(i, |f| f(i));
    for lane in &mut map.lanes {
        let id = lane.id;
        for n in lane
            .left_neighbors
            .iter_mut()
            .chain(&mut lane.right_neighbors)
        {
            n.self_start_index = mapped(id, n.self_start_index);
            n.self_end_index = mapped(id, n.self_end_index);
            n.neighbor_start_index = mapped(n.feature_id, n.neighbor_start_index);
            n.neighbor_end_index = mapped(n.feature_id, n.neighbor_end_index);
        }
        for b in lane
            .left_boundaries
            .iter_mut()
            .chain(&mut lane.right_boundaries)
        {
            b.lane_start_index = mapped(id, b.lane_start_index);
            b.lane_end_index = mapped(id, b.lane_end_index);
        }
    }
    for line in &mut map.road_lines {
        line.polyline = resample(&line.polyline, spacing_m).0;
    }
    for edge in &mut map.road_edges {
        edge.polyline = resample(&edge.polyline, spacing_m).0;
    }
}

/// An old point index → the nearest new one.
type IndexMap = Box<dyn Fn(i32) -> i32>;

/// A polyline resampled every `spacing_m` of arclength (as near as a whole number of equal
/// steps allows), with both ends, and the map from an old point index to the nearest new one.
fn resample(points: &[MapPoint], spacing_m: f64) -> (Vec<MapPoint>, IndexMap) {
    let mut arclength = Vec::with_capacity(points.len());
    let mut total = 0.0;
    for (i, p) in points.iter().enumerate() {
        if i > 0 {
            let q = &points[i - 1];
            total += (p.x_m - q.x_m).hypot(p.y_m - q.y_m);
        }
        arclength.push(total);
    }
    let last_old = points.len() as i32 - 1;
    if points.len() < 2 || total <= spacing_m {
        return (
            points.to_vec(),
            Box::new(move |i: i32| i.clamp(0, last_old.max(0))),
        );
    }
    let n_new = (total / spacing_m).round().max(1.0) as usize;
    let mut out = Vec::with_capacity(n_new + 1);
    let mut seg = 0;
    for k in 0..=n_new {
        let s = total * k as f64 / n_new as f64;
        while seg + 2 < points.len() && arclength[seg + 1] < s {
            seg += 1;
        }
        let (a, b) = (&points[seg], &points[seg + 1]);
        let len = arclength[seg + 1] - arclength[seg];
        let t = if len > 0.0 {
            ((s - arclength[seg]) / len).clamp(0.0, 1.0)
        } else {
            0.0
        };
        out.push(MapPoint {
            x_m: a.x_m + t * (b.x_m - a.x_m),
            y_m: a.y_m + t * (b.y_m - a.y_m),
            z_m: a.z_m + t * (b.z_m - a.z_m),
        });
    }
    let index_of = move |i: i32| {
        let i = i.clamp(0, last_old) as usize;
        ((arclength[i] / total * n_new as f64).round() as i32).clamp(0, n_new as i32)
    };
    (out, Box::new(index_of))
}

#[cfg(test)]
mod tests {
    use super::*;
    use scbg_scene::{Lane, LaneNeighbor};

    fn line(n: usize, step: f64) -> Vec<MapPoint> {
        (0..n)
            .map(|i| MapPoint {
                x_m: i as f64 * step,
                y_m: 0.0,
                z_m: 0.0,
            })
            .collect()
    }

    #[test]
    fn resampling_keeps_the_ends_and_moves_neighbour_indices() {
        let lane = |id, other| Lane {
            id,
            polyline: line(101, 1.0),
            left_neighbors: vec![LaneNeighbor {
                feature_id: other,
                self_start_index: 20,
                self_end_index: 100,
                neighbor_start_index: 10,
                neighbor_end_index: 90,
                ..Default::default()
            }],
            ..Default::default()
        };
        let mut map = Map {
            lanes: vec![lane(1, 2), lane(2, 1)],
            ..Default::default()
        };
        resample_map(&mut map, 2.5);
        let l = &map.lanes[0];
        assert_eq!(l.polyline.len(), 41);
        assert_eq!(l.polyline[40].x_m, 100.0);
        assert!((l.polyline[1].x_m - 2.5).abs() < 1e-9);
        let n = &l.left_neighbors[0];
        assert_eq!(
            (
                n.self_start_index,
                n.self_end_index,
                n.neighbor_start_index,
                n.neighbor_end_index
            ),
            (8, 40, 4, 36)
        );
    }

    #[test]
    fn varied_maps_keep_an_edge_and_are_deterministic() {
        for index in 0..200 {
            let g = crate::generate(3, index, &crate::Family::ALL);
            assert!(
                !g.scene.map.road_edges.is_empty(),
                "{}",
                g.scene.scenario_id
            );
            assert_eq!(
                crate::generate(3, index, &crate::Family::ALL).scene,
                g.scene
            );
        }
    }
}
