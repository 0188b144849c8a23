//! The hot path of `Scenario` decoding: tracks and map points read by a hand-written wire loop,
//! everything else by prost.
//!
//! A WOMD scenario holds 9 000–40 000 `ObjectState`s (every track × every step), each ten fields.
//! prost's generic decoding spends, per field, a key varint, a dispatch through the derived
//! `merge_field`, a wire-type check and the `Option` bookkeeping — about a third of the whole
//! ingest pipeline's time in a `perf` profile (docs/findings.md, *Speed work that changed no
//! number*). WOMD's writers (and ours) put each state's fields behind one-byte keys with
//! fixed-width values, which the loop below reads directly, straight into scene tracks (no
//! intermediate proto states); the same holds for the map's points (a lane or line is a list of
//! 27-byte `MapPoint`s), which prost decodes as one message each.
//!
//! **Exactness.** The loop accepts only what it fully understands: the known fields of `Track`,
//! `ObjectState`, `MapFeature`, `RoadLine`/`RoadEdge` and `MapPoint` with their declared wire
//! types and one-byte keys, varints prost accepts, lengths inside the record. Anything else — an
//! unknown field, another wire type, a multi-byte key, a group, truncation, a map feature with
//! two `oneof` fields — returns `None`, and [`decode_parts`] decodes the whole record with
//! prost instead, so the result (a scenario or prost's error) is always exactly prost's. The tests compare both decoders on every shared real file, synthetic
//! scenes and mutated records.

use prost::Message;
use scbg_scene::{AgentState, ObjectType, Track};

use crate::{proto, scenario};

/// A `Scenario` record as its other fields (`tracks` left empty) and its tracks converted to
/// scene tracks: by the fast loop when it understands the tracks, otherwise by prost. Same
/// result as `proto::Scenario::decode(data)` followed by the conversion of its tracks.
pub fn decode_parts(data: &[u8]) -> Result<(proto::Scenario, Vec<Track>), prost::DecodeError> {
    match try_fast(data) {
        Some(parts) => Ok(parts),
        None => by_prost(data),
    }
}

/// The same parts through prost alone (the fallback, and the tests' reference).
fn by_prost(data: &[u8]) -> Result<(proto::Scenario, Vec<Track>), prost::DecodeError> {
    let mut s = proto::Scenario::decode(data)?;
    let tracks = s.tracks.iter().map(scenario::scene_track).collect();
    s.tracks = Vec::new();
    Ok((s, tracks))
}

/// The fast decoding, or `None` where it does not apply.
fn try_fast(data: &[u8]) -> Option<(proto::Scenario, Vec<Track>)> {
    // prost decodes everything but the tracks and the map (fields 2 and 8 are unknown to
    // `ScenarioRest` and skipped by their length, unread).
    let rest = proto::ScenarioRest::decode(data).ok()?;
    let mut tracks: Vec<Track> = Vec::new();
    let mut map_features = Vec::new();
    let mut r = Reader::new(data);
    while !r.is_empty() {
        let (field, wire) = r.key()?;
        match (field, wire) {
            (2, 2) => {
                let hint = tracks.last().map_or(0, |t| t.states.len());
                tracks.push(track(r.len_delimited()?, hint)?);
            }
            (8, 2) => map_features.push(map_feature(r.len_delimited()?)?),
            (2 | 8, _) => return None,
            _ => r.skip(wire)?,
        }
    }
    Some((rest.with_map(map_features), tracks))
}

/// One `MapFeature`: lanes, road lines and road edges with their points read here; the other
/// kinds (few, small) by prost. A feature with more than one of its `oneof` fields (which
/// prost merges) is left to prost.
fn map_feature(mut r: Reader<'_>) -> Option<proto::MapFeature> {
    use proto::MapFeatureData as D;
    let mut id = None;
    let mut data = None;
    while !r.is_empty() {
        let key = r.byte()?;
        if key == 0x08 {
            id = Some(r.varint()? as i64); // 1: int64
            continue;
        }
        if data.is_some() {
            return None;
        }
        let body = r.len_delimited()?;
        data = Some(match key {
            0x1a => D::Lane(lane(body)?),
            0x22 => {
                let (t, polyline) = typed_polyline(body)?;
                D::RoadLine(proto::RoadLine {
                    line_type: t,
                    polyline,
                })
            }
            0x2a => {
                let (t, polyline) = typed_polyline(body)?;
                D::RoadEdge(proto::RoadEdge {
                    edge_type: t,
                    polyline,
                })
            }
            0x3a => D::StopSign(proto::StopSign::decode(body.buf).ok()?),
            0x42 => D::Crosswalk(proto::PolygonFeature::decode(body.buf).ok()?),
            0x4a => D::SpeedBump(proto::PolygonFeature::decode(body.buf).ok()?),
            0x52 => D::Driveway(proto::PolygonFeature::decode(body.buf).ok()?),
            _ => return None,
        });
    }
    Some(proto::MapFeature {
        id,
        feature_data: data,
    })
}

/// A `LaneCenter` in one pass: scalars, points and lane ids here, the (small) neighbour and
/// boundary messages by prost. A field number or wire type outside the schema is left to
/// prost (`None`).
fn lane(mut r: Reader<'_>) -> Option<proto::LaneCenter> {
    // A point takes 29 bytes (key, length, 27): an upper bound on the count.
    let mut lane = proto::LaneCenter {
        polyline: Vec::with_capacity(r.buf.len() / 29),
        ..Default::default()
    };
    while !r.is_empty() {
        let (field, wire) = r.key()?;
        match (field, wire) {
            (1, 1) => lane.speed_limit_mph = Some(r.f64()?),
            (2, 0) => lane.lane_type = Some(r.varint()? as i32),
            (3, 0) => lane.interpolating = Some(r.varint()? != 0),
            (8, 2) => lane.polyline.push(map_point(r.len_delimited()?)?),
            (9 | 10, 0) => {
                let id = r.varint()? as i64;
                lane_ids(&mut lane, field).push(id);
            }
            (9 | 10, 2) => {
                let mut packed = r.len_delimited()?;
                let ids = lane_ids(&mut lane, field);
                while !packed.is_empty() {
                    ids.push(packed.varint()? as i64);
                }
            }
            (11, 2) => lane
                .left_neighbors
                .push(proto::LaneNeighbor::decode(r.len_delimited()?.buf).ok()?),
            (12, 2) => lane
                .right_neighbors
                .push(proto::LaneNeighbor::decode(r.len_delimited()?.buf).ok()?),
            (13, 2) => lane
                .left_boundaries
                .push(proto::BoundarySegment::decode(r.len_delimited()?.buf).ok()?),
            (14, 2) => lane
                .right_boundaries
                .push(proto::BoundarySegment::decode(r.len_delimited()?.buf).ok()?),
            _ => return None,
        }
    }
    Some(lane)
}

/// `entry_lanes` (field 9) or `exit_lanes` (10).
fn lane_ids(lane: &mut proto::LaneCenter, field: u64) -> &mut Vec<i64> {
    if field == 9 {
        &mut lane.entry_lanes
    } else {
        &mut lane.exit_lanes
    }
}

/// A `RoadLine` or `RoadEdge`: type (field 1) and points (field 2).
fn typed_polyline(mut r: Reader<'_>) -> Option<(Option<i32>, Vec<proto::MapPoint>)> {
    let mut t = None;
    let mut points = Vec::with_capacity(r.buf.len() / 29);
    while !r.is_empty() {
        match r.byte()? {
            0x08 => t = Some(r.varint()? as i32),
            0x12 => points.push(map_point(r.len_delimited()?)?),
            _ => return None,
        }
    }
    Some((t, points))
}

/// One `MapPoint` (x, y, z doubles).
fn map_point(mut r: Reader<'_>) -> Option<proto::MapPoint> {
    let b = r.buf;
    if b.len() == 27 && b[0] == 0x09 && b[9] == 0x11 && b[18] == 0x19 {
        // x, y, z in order: read at fixed offsets (the loop below gives the same).
        let at = |i: usize| f64::from_le_bytes(b[i..i + 8].try_into().unwrap_or([0; 8]));
        return Some(proto::MapPoint {
            x: Some(at(1)),
            y: Some(at(10)),
            z: Some(at(19)),
        });
    }
    let mut p = proto::MapPoint::default();
    while !r.is_empty() {
        match r.byte()? {
            0x09 => p.x = Some(r.f64()?),
            0x11 => p.y = Some(r.f64()?),
            0x19 => p.z = Some(r.f64()?),
            _ => return None,
        }
    }
    Some(p)
}

/// One `Track` message; `states_hint` is the expected number of states (the previous track's).
/// Absent fields read as their defaults, as in [`scenario::scene_track`].
fn track(mut r: Reader<'_>, states_hint: usize) -> Option<Track> {
    let (mut id, mut object_type) = (0i32, 0i32);
    let mut states = Vec::with_capacity(states_hint);
    while !r.is_empty() {
        match r.byte()? {
            0x08 => id = r.varint()? as i32,                 // 1: int32
            0x10 => object_type = r.varint()? as i32,        // 2: enum (int32)
            0x1a => states.push(state(r.len_delimited()?)?), // 3: ObjectState
            _ => return None,
        }
    }
    Some(Track {
        id: i64::from(id),
        object_type: ObjectType::from_code(object_type),
        states,
    })
}

/// Key byte and offset of each field of a state written whole, in field order (59 bytes):
/// three doubles, six floats, the bool `valid` as a one-byte varint.
const FULL_STATE: [(usize, u8); 10] = [
    (0, 0x11),
    (9, 0x19),
    (18, 0x21),
    (27, 0x2d),
    (32, 0x35),
    (37, 0x3d),
    (42, 0x45),
    (47, 0x4d),
    (52, 0x55),
    (57, 0x58),
];
const FULL_STATE_BYTES: usize = 59;

/// One `ObjectState` message (absent fields read as 0 / false).
fn state(mut r: Reader<'_>) -> Option<AgentState> {
    let b = r.buf;
    if b.len() == FULL_STATE_BYTES
        && FULL_STATE.iter().all(|&(at, key)| b[at] == key)
        && b[58] < 0x80
    {
        // The common case, read at fixed offsets (the general loop below gives the same).
        let f64_at = |at: usize| f64::from_le_bytes(b[at..at + 8].try_into().unwrap_or([0; 8]));
        let f32_at = |at: usize| f32::from_le_bytes(b[at..at + 4].try_into().unwrap_or([0; 4]));
        return Some(AgentState {
            x_m: f64_at(1),
            y_m: f64_at(10),
            z_m: f64_at(19),
            length_m: f32_at(28),
            width_m: f32_at(33),
            height_m: f32_at(38),
            heading_rad: f32_at(43),
            velocity_x_mps: f32_at(48),
            velocity_y_mps: f32_at(53),
            valid: b[58] != 0,
        });
    }
    let mut s = AgentState::default();
    while !r.is_empty() {
        match r.byte()? {
            0x11 => s.x_m = r.f64()?,            // 2: double center_x
            0x19 => s.y_m = r.f64()?,            // 3: double center_y
            0x21 => s.z_m = r.f64()?,            // 4: double center_z
            0x2d => s.length_m = r.f32()?,       // 5: float length
            0x35 => s.width_m = r.f32()?,        // 6: float width
            0x3d => s.height_m = r.f32()?,       // 7: float height
            0x45 => s.heading_rad = r.f32()?,    // 8: float heading
            0x4d => s.velocity_x_mps = r.f32()?, // 9: float velocity_x
            0x55 => s.velocity_y_mps = r.f32()?, // 10: float velocity_y
            0x58 => s.valid = r.varint()? != 0,  // 11: bool valid
            _ => return None,
        }
    }
    Some(s)
}

/// A cursor over protobuf wire bytes; every read is bounds-checked and `None` past the end.
struct Reader<'a> {
    buf: &'a [u8],
}

impl<'a> Reader<'a> {
    fn new(buf: &'a [u8]) -> Self {
        Self { buf }
    }

    fn is_empty(&self) -> bool {
        self.buf.is_empty()
    }

    fn take(&mut self, n: usize) -> Option<&'a [u8]> {
        if n > self.buf.len() {
            return None;
        }
        let (head, tail) = self.buf.split_at(n);
        self.buf = tail;
        Some(head)
    }

    fn byte(&mut self) -> Option<u8> {
        let (&b, tail) = self.buf.split_first()?;
        self.buf = tail;
        Some(b)
    }

    /// A field key as `(field number, wire type)`; `None` where prost would reject it (field 0
    /// or above the largest field number).
    fn key(&mut self) -> Option<(u64, u64)> {
        let key = self.varint()?;
        let (field, wire) = (key >> 3, key & 7);
        (field != 0 && field <= u64::from(u32::MAX >> 3)).then_some((field, wire))
    }

    /// A varint as prost reads it: at most ten bytes, the tenth at most 1.
    fn varint(&mut self) -> Option<u64> {
        let mut v = 0u64;
        for i in 0..10 {
            let b = self.byte()?;
            if i == 9 && b > 1 {
                return None;
            }
            v |= u64::from(b & 0x7f) << (7 * i);
            if b < 0x80 {
                return Some(v);
            }
        }
        None
    }

    fn f64(&mut self) -> Option<f64> {
        Some(f64::from_le_bytes(self.take(8)?.try_into().ok()?))
    }

    fn f32(&mut self) -> Option<f32> {
        Some(f32::from_le_bytes(self.take(4)?.try_into().ok()?))
    }

    /// A length-delimited field's bytes.
    fn len_delimited(&mut self) -> Option<Reader<'a>> {
        let len = usize::try_from(self.varint()?).ok()?;
        Some(Reader::new(self.take(len)?))
    }

    /// Skips one field's value of wire type `wire` (groups are not handled: `None`).
    fn skip(&mut self, wire: u64) -> Option<()> {
        match wire {
            0 => self.varint().map(drop),
            1 => self.take(8).map(drop),
            2 => self.len_delimited().map(drop),
            5 => self.take(4).map(drop),
            _ => None,
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Per track: id, type code, each state's fields as bits.
    type TrackBits = (i64, i32, Vec<[u64; 10]>);

    /// Bit-exact comparison (NaN fields compare unequal under PartialEq).
    fn bits(parts: &(proto::Scenario, Vec<Track>)) -> (Vec<u8>, Vec<TrackBits>) {
        let tracks = parts
            .1
            .iter()
            .map(|t| {
                let states = t
                    .states
                    .iter()
                    .map(|s| {
                        [
                            s.x_m.to_bits(),
                            s.y_m.to_bits(),
                            s.z_m.to_bits(),
                            s.length_m.to_bits().into(),
                            s.width_m.to_bits().into(),
                            s.height_m.to_bits().into(),
                            s.heading_rad.to_bits().into(),
                            s.velocity_x_mps.to_bits().into(),
                            s.velocity_y_mps.to_bits().into(),
                            s.valid.into(),
                        ]
                    })
                    .collect();
                (t.id, t.object_type.code(), states)
            })
            .collect();
        (parts.0.encode_to_vec(), tracks)
    }

    /// Both decoders on `data`: the same parts, or both an error.
    fn assert_same(data: &[u8]) {
        let prost = by_prost(data);
        let fast = decode_parts(data);
        match (&prost, &fast) {
            (Ok(a), Ok(b)) => assert_eq!(bits(a), bits(b)),
            (Err(a), Err(b)) => assert_eq!(a.to_string(), b.to_string()),
            _ => panic!("prost {prost:?} but fast {fast:?}"),
        }
    }

    fn sample_bytes() -> Vec<u8> {
        crate::encode_scene(&crate::tests::sample_scene()).unwrap()
    }

    #[test]
    fn fast_path_is_taken_for_our_encoding() {
        let bytes = sample_bytes();
        let fast = try_fast(&bytes).expect("our encoder's output takes the fast path");
        assert_eq!(bits(&fast), bits(&by_prost(&bytes).unwrap()));
        assert_eq!(fast.1.len(), 2);
        assert_eq!(fast.1[0].states.len(), 5);
    }

    #[test]
    fn same_as_prost_on_every_shared_real_file() {
        let Some(paths) = crate::fixtures::real_tfrecords() else {
            return; // real_data_dir said why (and fails under CI)
        };
        let mut records = 0;
        for path in &paths {
            let file = crate::WomdFile::open(path).unwrap();
            for record in file.records() {
                let data = record.unwrap().data;
                // The tf.Example fixture is not a Scenario: both must fail alike.
                assert_same(data);
                if proto::Scenario::decode(data).is_ok_and(|s| s.scenario_id.is_some()) {
                    assert!(try_fast(data).is_some(), "{}: slow path", path.display());
                }
                records += 1;
            }
        }
        assert!(records >= 25, "{records} records");
    }

    #[test]
    fn same_as_prost_on_cut_and_mutated_records() {
        let bytes = sample_bytes();
        for cut in 0..bytes.len() {
            assert_same(&bytes[..cut]);
        }
        // Every single-byte change at every position, to a spread of values.
        for pos in 0..bytes.len() {
            for v in [0x00, 0x01, 0x02, 0x08, 0x0a, 0x1a, 0x58, 0x7f, 0x80, 0xff] {
                let mut b = bytes.clone();
                b[pos] = v;
                assert_same(&b);
            }
        }
    }

    #[test]
    fn lane_ids_packed_and_unpacked_agree_with_prost() {
        // entry_lanes (9) unpacked twice, exit_lanes (10) packed, lane_type, one point.
        let mut lane = vec![0x48, 5, 0x48, 6, 0x52, 2, 7, 8, 0x10, 1, 0x42, 27, 0x09];
        lane.extend(1.0f64.to_le_bytes());
        lane.push(0x11);
        lane.extend(2.0f64.to_le_bytes());
        lane.push(0x19);
        lane.extend(0.0f64.to_le_bytes());
        // A scenario "x" whose one map feature (id 42) is this lane.
        let scenario_with = |lane: &[u8]| {
            let mut feature = vec![0x08, 42, 0x1a, lane.len() as u8];
            feature.extend(lane);
            let mut data = vec![0x42, feature.len() as u8];
            data.extend(&feature);
            data.extend([0x2a, 1, b'x']);
            data
        };
        let data = scenario_with(&lane);
        assert!(try_fast(&data).is_some());
        assert_same(&data);
        let (scenario, _) = decode_parts(&data).unwrap();
        let Some(proto::MapFeatureData::Lane(l)) = &scenario.map_features[0].feature_data else {
            panic!("a lane");
        };
        assert_eq!(
            (&l.entry_lanes[..], &l.exit_lanes[..]),
            (&[5, 6][..], &[7, 8][..])
        );
        // A field outside the schema (15) leaves the scenario to prost, with the same result.
        let mut odd = lane.clone();
        odd.extend([0x78, 1]);
        let data = scenario_with(&odd);
        assert!(try_fast(&data).is_none());
        assert_same(&data);
    }

    #[test]
    fn unknown_and_repeated_fields_fall_back_or_agree() {
        // A state with an unknown field 15 (fixed32) and `valid` written twice.
        let mut state = vec![0x11];
        state.extend(1.5f64.to_le_bytes());
        state.extend([0x7d, 1, 2, 3, 4, 0x58, 1, 0x58, 0]);
        let mut track = vec![0x08, 7, 0x1a, state.len() as u8];
        track.extend(&state);
        let mut data = vec![0x12, track.len() as u8];
        data.extend(&track);
        data.extend([0x2a, 1, b'x']); // scenario_id "x"
        assert!(try_fast(&data).is_none());
        assert_same(&data);
        let (_, tracks) = decode_parts(&data).unwrap();
        assert!(!tracks[0].states[0].valid);
        assert_eq!(tracks[0].states[0].x_m, 1.5);
        // Without the unknown field the fast path takes it, with the same result.
        let mut plain = vec![0x11];
        plain.extend(1.5f64.to_le_bytes());
        plain.extend([0x58, 1, 0x58, 0]);
        let mut track = vec![0x08, 0xff, 0xff, 0xff, 0xff, 0x0f, 0x1a, plain.len() as u8];
        track.extend(&plain);
        let mut data = vec![0x12, track.len() as u8];
        data.extend(&track);
        data.extend([0x2a, 1, b'x']);
        assert!(try_fast(&data).is_some());
        assert_same(&data);
        assert_eq!(decode_parts(&data).unwrap().1[0].id, -1);
    }
}
