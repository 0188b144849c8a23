//! Binary record format of a [`PreparedScene`] in the cache (little-endian).
//!
//! Hand-written rather than serde + a format crate because the layout is the point: track
//! values are stored for valid steps only (a validity bitmask says which), which makes a
//! record several times smaller than the raw protobuf. Layout:
//!
//! ```text
//! str scenario_id · f64 origin_x · f64 origin_y · u32 num_steps · f32 step_secs
//! u32 n_tracks  { i64 id · u8 type · u8 is_sdc · f32 length · f32 width
//!                 · bitmask[ceil(num_steps/8)] · (f32 x, y, heading, vx, vy) per valid step }
//! u32 n_road    { u8 kind · u32 n_points · (f32 x, y) per point }
//! u32 n_windows { u32 current_step · u32 n_pairs · (u32 first · u32 second · u8 source) per pair }
//! ```
//! (`str` = u32 length + UTF-8 bytes.)

use scbg_scene::ObjectType;

use crate::prepared::{
    InteractingPair, PairSource, PreparedScene, PreparedTrack, RoadKind, RoadPolyline,
};
use crate::window::Window;

/// A malformed cache record: names the first field that could not be read or is invalid.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("cache record is corrupt at field `{field}`")]
pub struct DecodeError {
    /// The field, as named in the layout above (e.g. `track.valid`, `pair.source`).
    pub field: &'static str,
}

impl PreparedScene {
    /// Encodes into the cache's binary record format.
    pub fn encode(&self) -> Vec<u8> {
        encode(self)
    }

    /// Decodes a cache record; errors say which field is malformed.
    pub fn decode(bytes: &[u8]) -> Result<Self, DecodeError> {
        decode(bytes)
    }
}

fn encode(s: &PreparedScene) -> Vec<u8> {
    let mut out = Vec::with_capacity(1024);
    let u32_ = |out: &mut Vec<u8>, v: usize| out.extend_from_slice(&(v as u32).to_le_bytes());
    u32_(&mut out, s.scenario_id.len());
    out.extend_from_slice(s.scenario_id.as_bytes());
    out.extend_from_slice(&s.origin_xy_m[0].to_le_bytes());
    out.extend_from_slice(&s.origin_xy_m[1].to_le_bytes());
    u32_(&mut out, s.num_steps);
    out.extend_from_slice(&s.step_secs.to_le_bytes());
    u32_(&mut out, s.tracks.len());
    for t in &s.tracks {
        out.extend_from_slice(&t.id.to_le_bytes());
        out.push(t.object_type.code() as u8);
        out.push(u8::from(t.is_sdc));
        out.extend_from_slice(&t.length_m.to_le_bytes());
        out.extend_from_slice(&t.width_m.to_le_bytes());
        let mut mask = vec![0u8; s.num_steps.div_ceil(8)];
        for (i, &v) in t.valid.iter().enumerate() {
            if v {
                mask[i / 8] |= 1 << (i % 8);
            }
        }
        out.extend_from_slice(&mask);
        for i in (0..s.num_steps).filter(|&i| t.valid[i]) {
            for v in [
                t.x_m[i],
                t.y_m[i],
                t.heading_rad[i],
                t.vx_mps[i],
                t.vy_mps[i],
            ] {
                out.extend_from_slice(&v.to_le_bytes());
            }
        }
    }
    u32_(&mut out, s.road.len());
    for p in &s.road {
        out.push(p.kind as u8);
        u32_(&mut out, p.xy_m.len());
        for xy in &p.xy_m {
            out.extend_from_slice(&xy[0].to_le_bytes());
            out.extend_from_slice(&xy[1].to_le_bytes());
        }
    }
    u32_(&mut out, s.windows.len());
    for (w, pairs) in s.windows.iter().zip(&s.pairs) {
        u32_(&mut out, w.current_step);
        u32_(&mut out, pairs.len());
        for p in pairs {
            u32_(&mut out, p.first);
            u32_(&mut out, p.second);
            out.push(p.source as u8);
        }
    }
    out
}

struct Reader<'a> {
    bytes: &'a [u8],
    pos: usize,
}

impl<'a> Reader<'a> {
    fn take(&mut self, n: usize, field: &'static str) -> Result<&'a [u8], DecodeError> {
        let end = self
            .pos
            .checked_add(n)
            .filter(|&e| e <= self.bytes.len())
            .ok_or(DecodeError { field })?;
        let out = &self.bytes[self.pos..end];
        self.pos = end;
        Ok(out)
    }
    fn u8(&mut self, field: &'static str) -> Result<u8, DecodeError> {
        Ok(self.take(1, field)?[0])
    }
    fn u32(&mut self, field: &'static str) -> Result<usize, DecodeError> {
        Ok(u32::from_le_bytes(self.take(4, field)?.try_into().expect("4")) as usize)
    }
    fn f32(&mut self, field: &'static str) -> Result<f32, DecodeError> {
        Ok(f32::from_le_bytes(
            self.take(4, field)?.try_into().expect("4"),
        ))
    }
    fn f64(&mut self, field: &'static str) -> Result<f64, DecodeError> {
        Ok(f64::from_le_bytes(
            self.take(8, field)?.try_into().expect("8"),
        ))
    }
    fn i64(&mut self, field: &'static str) -> Result<i64, DecodeError> {
        Ok(i64::from_le_bytes(
            self.take(8, field)?.try_into().expect("8"),
        ))
    }
    /// A count, checked against the bytes left so that a corrupt count cannot allocate.
    fn count(&mut self, min_item_bytes: usize, field: &'static str) -> Result<usize, DecodeError> {
        let n = self.u32(field)?;
        if n.saturating_mul(min_item_bytes) > self.bytes.len() - self.pos {
            return Err(DecodeError { field });
        }
        Ok(n)
    }
}

fn decode(bytes: &[u8]) -> Result<PreparedScene, DecodeError> {
    let mut r = Reader { bytes, pos: 0 };
    let id_len = r.count(1, "scenario_id")?;
    let scenario_id =
        String::from_utf8(r.take(id_len, "scenario_id")?.to_vec()).map_err(|_| DecodeError {
            field: "scenario_id",
        })?;
    let origin_xy_m = [r.f64("origin")?, r.f64("origin")?];
    let num_steps = r.count(0, "num_steps")?;
    if num_steps > 100_000 {
        return Err(DecodeError { field: "num_steps" });
    }
    let step_secs = r.f32("step_secs")?;
    let n_tracks = r.count(18, "tracks")?;
    let mut tracks = Vec::with_capacity(n_tracks);
    for _ in 0..n_tracks {
        let id = r.i64("track.id")?;
        let object_type = ObjectType::from_code(i32::from(r.u8("track.type")?));
        let is_sdc = r.u8("track.is_sdc")? != 0;
        let length_m = r.f32("track.length")?;
        let width_m = r.f32("track.width")?;
        let mask = r.take(num_steps.div_ceil(8), "track.valid")?;
        let valid: Vec<bool> = (0..num_steps)
            .map(|i| mask[i / 8] & (1 << (i % 8)) != 0)
            .collect();
        let mut t = PreparedTrack {
            id,
            object_type,
            is_sdc,
            length_m,
            width_m,
            x_m: vec![0.0; num_steps],
            y_m: vec![0.0; num_steps],
            heading_rad: vec![0.0; num_steps],
            vx_mps: vec![0.0; num_steps],
            vy_mps: vec![0.0; num_steps],
            valid,
        };
        for i in 0..num_steps {
            if t.valid[i] {
                t.x_m[i] = r.f32("track.x")?;
                t.y_m[i] = r.f32("track.y")?;
                t.heading_rad[i] = r.f32("track.heading")?;
                t.vx_mps[i] = r.f32("track.vx")?;
                t.vy_mps[i] = r.f32("track.vy")?;
            }
        }
        tracks.push(t);
    }
    let n_road = r.count(5, "road")?;
    let mut road = Vec::with_capacity(n_road);
    for _ in 0..n_road {
        let kind =
            RoadKind::from_index(r.u8("road.kind")?).ok_or(DecodeError { field: "road.kind" })?;
        let n = r.count(8, "road.points")?;
        let xy_m = (0..n)
            .map(|_| Ok([r.f32("road.x")?, r.f32("road.y")?]))
            .collect::<Result<Vec<_>, DecodeError>>()?;
        if xy_m.is_empty() {
            return Err(DecodeError {
                field: "road.points",
            });
        }
        road.push(RoadPolyline { kind, xy_m });
    }
    let n_windows = r.count(8, "windows")?;
    let mut windows = Vec::with_capacity(n_windows);
    let mut pairs = Vec::with_capacity(n_windows);
    for _ in 0..n_windows {
        let current_step = r.u32("window.current_step")?;
        let n_pairs = r.count(9, "window.pairs")?;
        let mut ps = Vec::with_capacity(n_pairs);
        for _ in 0..n_pairs {
            let first = r.u32("pair.first")?;
            let second = r.u32("pair.second")?;
            let source = match r.u8("pair.source")? {
                0 => PairSource::Labelled,
                1 => PairSource::Mined,
                _ => {
                    return Err(DecodeError {
                        field: "pair.source",
                    });
                }
            };
            if first >= n_tracks || second >= n_tracks {
                return Err(DecodeError {
                    field: "pair.track",
                });
            }
            ps.push(InteractingPair {
                first,
                second,
                source,
            });
        }
        if current_step >= num_steps {
            return Err(DecodeError {
                field: "window.current_step",
            });
        }
        windows.push(Window { current_step });
        pairs.push(ps);
    }
    if r.pos != bytes.len() {
        return Err(DecodeError {
            field: "trailing bytes",
        });
    }
    Ok(PreparedScene {
        scenario_id,
        origin_xy_m,
        num_steps,
        step_secs,
        tracks,
        road,
        windows,
        pairs,
    })
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    /// A small scene with an invalid step, an all-invalid track, a road polygon and a pair.
    pub(crate) fn scene(id: &str) -> PreparedScene {
        let n = 12;
        let mut valid = vec![true; n];
        valid[3] = false;
        PreparedScene {
            scenario_id: id.into(),
            origin_xy_m: [1.5, -2.5],
            num_steps: n,
            step_secs: 0.1,
            tracks: vec![
                PreparedTrack {
                    id: 5,
                    object_type: ObjectType::Vehicle,
                    is_sdc: true,
                    length_m: 4.0,
                    width_m: 2.0,
                    x_m: (0..n)
                        .map(|i| if valid[i] { i as f32 } else { 0.0 })
                        .collect(),
                    y_m: vec![0.0; n],
                    heading_rad: vec![0.0; n],
                    vx_mps: (0..n).map(|i| if valid[i] { 10.0 } else { 0.0 }).collect(),
                    vy_mps: vec![0.0; n],
                    valid,
                },
                PreparedTrack {
                    id: 6,
                    object_type: ObjectType::Cyclist,
                    is_sdc: false,
                    length_m: 2.0,
                    width_m: 1.0,
                    valid: vec![false; n],
                    x_m: vec![0.0; n],
                    y_m: vec![0.0; n],
                    heading_rad: vec![0.0; n],
                    vx_mps: vec![0.0; n],
                    vy_mps: vec![0.0; n],
                },
            ],
            road: vec![RoadPolyline {
                kind: RoadKind::Crosswalk,
                xy_m: vec![[0.0, 1.0], [2.0, 3.0]],
            }],
            windows: vec![Window { current_step: 4 }],
            pairs: vec![vec![InteractingPair {
                first: 0,
                second: 1,
                source: PairSource::Mined,
            }]],
        }
    }

    #[test]
    fn record_round_trip() {
        let s = scene("abc");
        assert_eq!(PreparedScene::decode(&s.encode()).unwrap(), s);
    }

    #[test]
    fn truncated_or_garbled_records_are_errors_not_panics() {
        let bytes = scene("abc").encode();
        for cut in 0..bytes.len() {
            assert!(PreparedScene::decode(&bytes[..cut]).is_err(), "cut {cut}");
        }
        let mut state = 7u32;
        for _ in 0..2000 {
            let mut b = bytes.clone();
            state = state.wrapping_mul(1_103_515_245).wrapping_add(12345);
            let i = (state as usize >> 8) % b.len();
            b[i] = (state >> 3) as u8;
            let _ = PreparedScene::decode(&b);
        }
    }
}
