//! The prepared cache: sharded files of [`PreparedScene`] records plus a JSON manifest.
//!
//! A shard file is `magic · records · index (u64 offset, u64 length per record) · footer
//! (u64 index offset, u64 record count, magic)`. It is written to a temporary file and renamed
//! into place when complete, then a per-shard summary `shard-NNNNN.json` is written the same
//! way; a shard whose summary exists with the same inputs is finished and is skipped on a
//! re-run (resumable). Shards are memory-mapped for reading and records decoded on demand,
//! so memory is bounded by what a consumer holds, not by the dataset.

use std::collections::BTreeMap;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use crate::prepared::PreparedScene;

const MAGIC: &[u8; 8] = b"SCBGPS01";
const FOOTER_BYTES: usize = 8 + 8 + 8;

/// An error reading or writing the cache.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    #[error("cache record is corrupt at field `{field}`")]
    Corrupt { field: &'static str },
    #[error("{error}: {}", path.display())]
    Io {
        path: PathBuf,
        error: std::io::Error,
    },
    #[error("not a scbg cache shard (bad magic or footer): {}", path.display())]
    NotAShard { path: PathBuf },
    #[error("record {index}: {error} in {}", path.display())]
    Record {
        path: PathBuf,
        index: usize,
        error: Box<CacheError>,
    },
    #[error("manifest {}: {message}", path.display())]
    Manifest { path: PathBuf, message: String },
}

/// Writes one shard file atomically.
#[derive(Debug)]
pub struct ShardWriter {
    path: PathBuf,
    out: BufWriter<tempfile::NamedTempFile>,
    index: Vec<(u64, u64)>,
    pos: u64,
}

impl ShardWriter {
    pub fn create(path: &Path) -> Result<Self, CacheError> {
        let io = |error| CacheError::Io {
            path: path.to_path_buf(),
            error,
        };
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        let mut out = BufWriter::new(tempfile::NamedTempFile::new_in(dir).map_err(io)?);
        out.write_all(MAGIC).map_err(io)?;
        Ok(Self {
            path: path.to_path_buf(),
            out,
            index: Vec::new(),
            pos: MAGIC.len() as u64,
        })
    }

    pub fn append(&mut self, scene: &PreparedScene) -> Result<u64, CacheError> {
        let bytes = scene.encode();
        self.out.write_all(&bytes).map_err(|error| CacheError::Io {
            path: self.path.clone(),
            error,
        })?;
        self.index.push((self.pos, bytes.len() as u64));
        self.pos += bytes.len() as u64;
        Ok(bytes.len() as u64)
    }

    /// Writes the index and footer and renames the file into place. Returns its size in bytes.
    pub fn finish(mut self) -> Result<u64, CacheError> {
        let io = |error| CacheError::Io {
            path: self.path.clone(),
            error,
        };
        let index_offset = self.pos;
        for (o, l) in &self.index {
            self.out.write_all(&o.to_le_bytes()).map_err(io)?;
            self.out.write_all(&l.to_le_bytes()).map_err(io)?;
        }
        self.out
            .write_all(&index_offset.to_le_bytes())
            .map_err(io)?;
        self.out
            .write_all(&(self.index.len() as u64).to_le_bytes())
            .map_err(io)?;
        self.out.write_all(MAGIC).map_err(io)?;
        let tmp = self.out.into_inner().map_err(|e| io(e.into_error()))?;
        tmp.as_file().sync_all().map_err(io)?;
        tmp.persist(&self.path).map_err(|e| io(e.error))?;
        Ok(index_offset + self.index.len() as u64 * 16 + FOOTER_BYTES as u64)
    }
}

/// A memory-mapped shard file.
#[derive(Debug)]
pub struct Shard {
    path: PathBuf,
    map: memmap2::Mmap,
    index: Vec<(usize, usize)>,
}

impl Shard {
    pub fn open(path: &Path) -> Result<Self, CacheError> {
        let io = |error| CacheError::Io {
            path: path.to_path_buf(),
            error,
        };
        let bad = || CacheError::NotAShard {
            path: path.to_path_buf(),
        };
        let file = std::fs::File::open(path).map_err(io)?;
        if file.metadata().map_err(io)?.len() < (MAGIC.len() + FOOTER_BYTES) as u64 {
            return Err(bad());
        }
        // SAFETY: read-only private map; shards are immutable once renamed into place.
        #[allow(unsafe_code)]
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(io)?;
        let n = map.len();
        let u64_at = |at: usize| u64::from_le_bytes(map[at..at + 8].try_into().expect("8"));
        if &map[..8] != MAGIC || &map[n - 8..] != MAGIC {
            return Err(bad());
        }
        let index_offset = usize::try_from(u64_at(n - 24)).map_err(|_| bad())?;
        let count = usize::try_from(u64_at(n - 16)).map_err(|_| bad())?;
        if index_offset < MAGIC.len()
            || count
                .checked_mul(16)
                .and_then(|b| b.checked_add(index_offset))
                != Some(n - FOOTER_BYTES)
        {
            return Err(bad());
        }
        let index = (0..count)
            .map(|i| {
                let (o, l) = (
                    u64_at(index_offset + 16 * i) as usize,
                    u64_at(index_offset + 16 * i + 8) as usize,
                );
                if o < MAGIC.len() || o.checked_add(l).is_none_or(|e| e > index_offset) {
                    return Err(bad());
                }
                Ok((o, l))
            })
            .collect::<Result<_, _>>()?;
        Ok(Self {
            path: path.to_path_buf(),
            map,
            index,
        })
    }

    pub fn len(&self) -> usize {
        self.index.len()
    }

    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Decodes record `i`.
    pub fn get(&self, i: usize) -> Result<PreparedScene, CacheError> {
        let (o, l) = self.index[i];
        PreparedScene::decode(&self.map[o..o + l]).map_err(|e| CacheError::Record {
            path: self.path.clone(),
            index: i,
            error: Box::new(e),
        })
    }
}

/// Counts of what one shard (or the whole cache) holds and what was skipped.
#[derive(Debug, Clone, Default, PartialEq, Serialize, Deserialize)]
pub struct ShardSummary {
    /// Shard file name, relative to the cache folder.
    pub file: String,
    /// Input files, as given.
    pub inputs: Vec<String>,
    pub scenarios: usize,
    pub windows: usize,
    pub pairs: usize,
    /// Marginal-mode targets over all windows (valid vehicles with a future).
    pub targets: usize,
    /// Skipped records or files by reason.
    pub skipped: BTreeMap<String, usize>,
    pub raw_bytes: u64,
    pub bytes: u64,
}

impl ShardSummary {
    pub fn add(&mut self, other: &ShardSummary) {
        self.scenarios += other.scenarios;
        self.windows += other.windows;
        self.pairs += other.pairs;
        self.targets += other.targets;
        self.raw_bytes += other.raw_bytes;
        self.bytes += other.bytes;
        for (k, v) in &other.skipped {
            *self.skipped.entry(k.clone()).or_default() += v;
        }
    }
}

/// The cache's table of contents, `manifest.json`.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct Manifest {
    pub format_version: u32,
    /// The preparation settings, as `key = value` strings, so a cache says how it was made.
    pub settings: BTreeMap<String, String>,
    pub shards: Vec<ShardSummary>,
    pub total: ShardSummary,
}

/// Writes JSON atomically (temp file + rename).
pub fn write_json_atomic<T: Serialize>(path: &Path, value: &T) -> Result<(), CacheError> {
    let io = |error| CacheError::Io {
        path: path.to_path_buf(),
        error,
    };
    let dir = path
        .parent()
        .filter(|p| !p.as_os_str().is_empty())
        .unwrap_or(Path::new("."));
    let mut tmp = tempfile::NamedTempFile::new_in(dir).map_err(io)?;
    serde_json::to_writer_pretty(&mut tmp, value).map_err(|e| io(e.into()))?;
    tmp.write_all(b"\n").map_err(io)?;
    tmp.persist(path).map_err(|e| io(e.error))?;
    Ok(())
}

impl Manifest {
    pub const FILE: &'static str = "manifest.json";

    pub fn read(dir: &Path) -> Result<Self, CacheError> {
        let path = dir.join(Self::FILE);
        let text = std::fs::read_to_string(&path).map_err(|error| CacheError::Io {
            path: path.clone(),
            error,
        })?;
        serde_json::from_str(&text).map_err(|e| CacheError::Manifest {
            path,
            message: e.to_string(),
        })
    }

    pub fn write(&self, dir: &Path) -> Result<(), CacheError> {
        write_json_atomic(&dir.join(Self::FILE), self)
    }
}

/// Reads a finished shard's summary if present and made from the same inputs.
pub fn finished_shard(dir: &Path, shard_file: &str, inputs: &[String]) -> Option<ShardSummary> {
    let summary_path = dir.join(shard_file).with_extension("json");
    let text = std::fs::read_to_string(summary_path).ok()?;
    let summary: ShardSummary = serde_json::from_str(&text).ok()?;
    (summary.inputs == inputs && dir.join(shard_file).is_file()).then_some(summary)
}

/// All shards of a cache folder, opened, with a flat scene index.
#[derive(Debug)]
pub struct PreparedDataset {
    pub manifest: Manifest,
    shards: Vec<Shard>,
    /// (shard, record) of every scene, in manifest order.
    locations: Vec<(usize, usize)>,
}

impl PreparedDataset {
    pub fn open(dir: &Path) -> Result<Self, CacheError> {
        let manifest = Manifest::read(dir)?;
        let shards: Vec<Shard> = manifest
            .shards
            .iter()
            .map(|s| Shard::open(&dir.join(&s.file)))
            .collect::<Result<_, _>>()?;
        let locations = shards
            .iter()
            .enumerate()
            .flat_map(|(si, s)| (0..s.len()).map(move |r| (si, r)))
            .collect();
        Ok(Self {
            manifest,
            shards,
            locations,
        })
    }

    pub fn len(&self) -> usize {
        self.locations.len()
    }

    pub fn is_empty(&self) -> bool {
        self.locations.is_empty()
    }

    pub fn scene(&self, i: usize) -> Result<PreparedScene, CacheError> {
        let (s, r) = self.locations[i];
        self.shards[s].get(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pairs::{InteractingPair, PairSource};
    use crate::prepared::{PreparedTrack, RoadKind, RoadPolyline};
    use crate::window::Window;
    use scbg_scene::ObjectType;

    fn scene(id: &str) -> PreparedScene {
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

    #[test]
    fn shard_round_trip() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("shard-00000.bin");
        let mut w = ShardWriter::create(&path).unwrap();
        w.append(&scene("a")).unwrap();
        w.append(&scene("b")).unwrap();
        let size = w.finish().unwrap();
        assert_eq!(size, std::fs::metadata(&path).unwrap().len());
        let shard = Shard::open(&path).unwrap();
        assert_eq!(shard.len(), 2);
        assert_eq!(shard.get(1).unwrap().scenario_id, "b");
        // A file that is not a shard is refused with its path.
        std::fs::write(
            dir.path().join("junk.bin"),
            b"0123456789012345678901234567890123",
        )
        .unwrap();
        let e = Shard::open(&dir.path().join("junk.bin")).unwrap_err();
        assert!(e.to_string().contains("junk.bin"), "{e}");
    }
}
