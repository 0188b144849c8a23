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

use scbg_base::atomic::AtomicFile;
use serde::{Deserialize, Serialize};

use crate::codec::DecodeError;
use crate::prepared::PreparedScene;

const MAGIC: &[u8; 8] = b"SCBGPS01";
const FOOTER_BYTES: usize = 8 + 8 + 8;

/// An error reading or writing the cache.
#[derive(Debug, thiserror::Error)]
pub enum CacheError {
    /// A record's bytes do not decode.
    #[error(transparent)]
    Corrupt(#[from] DecodeError),
    /// Reading or writing a file failed.
    #[error("{error}: {}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        error: std::io::Error,
    },
    /// The file lacks the shard magic or has an inconsistent footer or index.
    #[allow(missing_docs)]
    #[error("not a scbg cache shard (bad magic or footer): {}", path.display())]
    NotAShard { path: PathBuf },
    /// A record of a shard could not be read.
    #[error("record {index}: {error} in {}", path.display())]
    Record {
        /// The shard file.
        path: PathBuf,
        /// 0-based index of the record in the shard.
        index: usize,
        /// Why (normally [`CacheError::Corrupt`]).
        error: Box<CacheError>,
    },
    /// `manifest.json` is not valid JSON for a [`Manifest`].
    #[allow(missing_docs)]
    #[error("manifest {}: {message}", path.display())]
    Manifest { path: PathBuf, message: String },
}

/// Writes one shard file atomically.
#[derive(Debug)]
pub struct ShardWriter {
    path: PathBuf,
    out: BufWriter<AtomicFile>,
    index: Vec<(u64, u64)>,
    pos: u64,
}

impl ShardWriter {
    /// Starts writing a shard at `path` (a temporary file until [`ShardWriter::finish`]).
    pub fn create(path: &Path) -> Result<Self, CacheError> {
        let io = |error| CacheError::Io {
            path: path.to_path_buf(),
            error,
        };
        let mut out = BufWriter::new(AtomicFile::create(path).map_err(|e| io(e.into()))?);
        out.write_all(MAGIC).map_err(io)?;
        Ok(Self {
            path: path.to_path_buf(),
            out,
            index: Vec::new(),
            pos: MAGIC.len() as u64,
        })
    }

    /// Appends one encoded scene; returns the record's size in bytes.
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
        let file = self.out.into_inner().map_err(|e| io(e.into_error()))?;
        file.commit().map_err(|e| io(e.into()))?;
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
    /// Memory-maps a shard and checks its magic, footer and index.
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

    /// Number of records.
    pub fn len(&self) -> usize {
        self.index.len()
    }

    /// True when the shard holds no records.
    pub fn is_empty(&self) -> bool {
        self.index.is_empty()
    }

    /// The shard's path.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// Decodes record `i`.
    pub fn get(&self, i: usize) -> Result<PreparedScene, CacheError> {
        let (o, l) = self.index[i];
        PreparedScene::decode(&self.map[o..o + l]).map_err(|e| CacheError::Record {
            path: self.path.clone(),
            index: i,
            error: Box::new(e.into()),
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
    /// Scenes prepared (scenes with at least one window).
    pub scenarios: usize,
    /// Windows over those scenes.
    pub windows: usize,
    /// Interacting pairs over all windows.
    pub pairs: usize,
    /// Marginal-mode targets over all windows (valid vehicles with a future).
    pub targets: usize,
    /// Skipped records or files by reason.
    pub skipped: BTreeMap<String, usize>,
    /// Total size of the input files, bytes.
    pub raw_bytes: u64,
    /// Size of the shard file(s) written, bytes.
    pub bytes: u64,
}

impl ShardSummary {
    /// Adds `other`'s counts (not its `file` or `inputs`) to these.
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
    /// Version of the cache format (currently 1).
    pub format_version: u32,
    /// The preparation settings, as `key = value` strings, so a cache says how it was made.
    pub settings: BTreeMap<String, String>,
    /// One summary per shard, in shard order.
    pub shards: Vec<ShardSummary>,
    /// Sum of the shard summaries.
    pub total: ShardSummary,
}

impl Manifest {
    /// File name of the manifest in the cache folder.
    pub const FILE: &'static str = "manifest.json";

    /// Reads `dir/manifest.json`.
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

    /// Writes `dir/manifest.json` atomically (pretty JSON plus a newline).
    pub fn write(&self, dir: &Path) -> Result<(), CacheError> {
        let path = dir.join(Self::FILE);
        scbg_base::atomic::write_json(&path, self).map_err(|e| CacheError::Io {
            path,
            error: e.into(),
        })
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
    /// The cache's manifest.
    pub manifest: Manifest,
    shards: Vec<Shard>,
    /// (shard, record) of every scene, in manifest order.
    locations: Vec<(usize, usize)>,
}

impl PreparedDataset {
    /// Reads the manifest of the cache folder `dir` and opens every shard it lists.
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

    /// Number of scenes over all shards.
    pub fn len(&self) -> usize {
        self.locations.len()
    }

    /// True when the cache holds no scenes.
    pub fn is_empty(&self) -> bool {
        self.locations.is_empty()
    }

    /// Decodes scene `i` (0-based, in manifest order). Panics if `i >= len()`.
    pub fn scene(&self, i: usize) -> Result<PreparedScene, CacheError> {
        let (s, r) = self.locations[i];
        self.shards[s].get(r)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::codec::tests::scene;

    #[test]
    fn a_corrupt_record_reads_as_before() {
        let e = CacheError::from(DecodeError {
            field: "track.valid",
        });
        assert_eq!(
            e.to_string(),
            "cache record is corrupt at field `track.valid`"
        );
        let bytes = scene("abc").encode();
        let e: CacheError = PreparedScene::decode(&bytes[..bytes.len() - 1])
            .unwrap_err()
            .into();
        assert!(matches!(e, CacheError::Corrupt(_)), "{e:?}");
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
