//! The roundabout's map.

use std::f64::consts::TAU;

use scbg_scene::{Lane, LaneType, Map, RoadEdge, RoadEdgeType, RoadLine, RoadLineType};

use super::ring::{ARM_M, Ring, ccw_span};

/// How far inside the ring lane's inner side the island's edge lies, m.
const APRON_M: f64 = 1.2;
use crate::RefPath;
use crate::families::pts;

impl Ring {
    /// The roundabout's map: per arm an entry and an exit lane, the ring in segments between
    /// the connectors, a centre line on each arm, the island's edge (clockwise, closed) and
    /// one outer edge per sector between arms (the right side of one arm's entry, the ring's
    /// outside, the right side of the next arm's exit).
    pub(super) fn map(&self) -> Map {
        let n = self.arms_rad.len();
        let w = self.lane_width_m;
        let limit_mph = Some((self.radius_m * 2.7).sqrt() * 2.237);
        let lane = |id, polyline, entry_lanes, exit_lanes| Lane {
            id,
            lane_type: LaneType::SurfaceStreet,
            speed_limit_mph: limit_mph,
            polyline,
            entry_lanes,
            exit_lanes,
            ..Default::default()
        };
        let (entry_id, exit_id) = (|k: usize| 100 + k as i64, |k: usize| 200 + k as i64);
        // Ring segments: 300 + k from arm k's join to arm k + 1's leave, 400 + k passing arm k.
        let (between_id, passing_id) = (|k: usize| 300 + k as i64, |k: usize| 400 + k as i64);
        let mut map = Map::default();
        for k in 0..n {
            let next = (k + 1) % n;
            map.lanes.push(lane(
                entry_id(k),
                thin(self.entry_points(k)),
                vec![],
                vec![between_id(k)],
            ));
            let mut exit = vec![self.on_ring(self.leave(k), self.radius_m)];
            exit.extend(self.exit_points(k));
            map.lanes
                .push(lane(exit_id(k), thin(exit), vec![passing_id(k)], vec![]));
            let mut between = vec![self.on_ring(self.join(k), self.radius_m)];
            between.extend(self.arc_points(
                self.join(k),
                ccw_span(self.join(k), self.leave(next)),
                self.radius_m,
            ));
            map.lanes.push(lane(
                between_id(k),
                thin(between),
                vec![entry_id(k), passing_id(k)],
                vec![passing_id(next)],
            ));
            let mut passing = vec![self.on_ring(self.leave(k), self.radius_m)];
            passing.extend(self.arc_points(
                self.leave(k),
                2.0 * self.deflection().1,
                self.radius_m,
            ));
            map.lanes.push(lane(
                passing_id(k),
                thin(passing),
                vec![between_id((k + n - 1) % n)],
                vec![between_id(k), exit_id(k)],
            ));
            let r0 = self.deflection().0;
            map.road_lines.push(RoadLine {
                id: 500 + k as i64,
                line_type: RoadLineType::SolidDoubleYellow,
                polyline: pts(vec![
                    self.on_arm(k, r0 + ARM_M, 0.0),
                    self.on_arm(k, r0, 0.0),
                ]),
            });
            // The sector's outer edge, driven the way traffic goes (the road on its left).
            let off = -(w / 2.0 + 0.3);
            let entry = RefPath::from_points(&self.entry_points(k), 1.0);
            let mut edge = entry.offset_points(0.0, entry.length_m(), 2.0, |_| off);
            let r_out = self.radius_m - off;
            edge.extend(self.arc_points(
                self.join(k),
                ccw_span(self.join(k), self.leave(next)),
                r_out,
            ));
            let mut exit = vec![self.on_ring(self.leave(next), self.radius_m)];
            exit.extend(self.exit_points(next));
            let exit = RefPath::from_points(&exit, 1.0);
            edge.extend(exit.offset_points(0.0, exit.length_m(), 2.0, |_| off));
            map.road_edges.push(RoadEdge {
                id: 600 + k as i64,
                edge_type: RoadEdgeType::Boundary,
                polyline: thin(edge),
            });
        }
        // The island, clockwise so that the road (outside it) is on its left, behind an apron
        // that makes the circulatory roadway the lane plus 1.5 m wide (5.1–5.9 m, as wide as
        // single-lane roundabouts' 4.9–6.1 m).
        let r_in = self.radius_m - w / 2.0 - APRON_M;
        let mut island: Vec<(f64, f64)> = (0..=72)
            .map(|i| self.on_ring(-(i as f64) * TAU / 72.0, r_in))
            .collect();
        island[72] = island[0];
        map.road_edges.push(RoadEdge {
            id: 700,
            edge_type: RoadEdgeType::Median,
            polyline: pts(island),
        });
        map
    }
}

/// Every point of a polyline at least 1 m from the last one kept, and its last point.
fn thin(points: Vec<(f64, f64)>) -> Vec<scbg_scene::MapPoint> {
    let mut kept: Vec<(f64, f64)> = Vec::with_capacity(points.len() / 2);
    let last = *points.last().expect("an edge has points");
    for p in points {
        if kept
            .last()
            .is_none_or(|q| (p.0 - q.0).hypot(p.1 - q.1) >= 1.0)
        {
            kept.push(p);
        }
    }
    if kept.last() != Some(&last) {
        kept.push(last);
    }
    pts(kept)
}
