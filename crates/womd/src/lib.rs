//! Waymo Open Motion Dataset formats, to and from [`Scene`].
//!
//! Main entry points: [`WomdFile::open`] (memory-maps a TFRecord file, detects whether it
//! holds `Scenario` protos or motion `tf.Example`s, iterates [`Scene`]s with errors that name
//! the file, record index and byte offset), [`write_scenes`] (atomic `Scenario` TFRecord
//! writer), [`encode_scene`] / [`scenario::scene_from_scenario`] for single records, and
//! [`wosac`] (Waymo Open Sim Agents Challenge submission export).
//!
//! **Architecture invariant:** this is the only crate that knows protobuf, TFRecord or
//! tf.Example. Everything downstream sees [`Scene`] only. It knows nothing about features,
//! models or training.

#![warn(missing_docs)]

use std::fmt;
use std::io::BufWriter;
use std::path::{Path, PathBuf};

use prost::Message;
use scbg_base::atomic::AtomicFile;
use scbg_scene::{Scene, Track};

pub mod example;
pub mod fast;
pub mod fixtures;
pub mod proto;
pub mod scenario;
pub mod tfrecord;
pub mod wosac;

pub use scenario::{TrackIdOverflow, encode_scene};
pub use tfrecord::{Record, RecordAt, RecordError, RecordIter, RecordWriter};

/// The record format of a WOMD TFRecord file.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Format {
    /// `waymo.open_dataset.Scenario` protos (the `uncompressed/scenario` release).
    Scenario,
    /// Motion `tf.Example`s (the `uncompressed/tf_example` release).
    TfExample,
}

impl fmt::Display for Format {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.write_str(match self {
            Self::Scenario => "scenario",
            Self::TfExample => "tf_example",
        })
    }
}

/// Why one record could not be decoded into a [`Scene`].
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
pub enum DecodeError {
    /// The record is not valid protobuf for the detected message type.
    #[error("protobuf: {0}")]
    Proto(prost::DecodeError),
    /// A decoded `Scenario` does not make a valid [`Scene`].
    #[error("scenario: {0}")]
    Scenario(scenario::ScenarioError),
    /// A decoded tf.Example does not have the motion layout or does not make a valid [`Scene`].
    #[error("tf.Example: {0}")]
    Example(example::ExampleError),
    /// Format detection found neither message type.
    #[allow(missing_docs)]
    #[error("record is neither a WOMD Scenario nor a WOMD motion tf.Example ({detail})")]
    NotWomd { detail: String },
}

// Causes are shown in each message, so they are not also exposed as `source()` (which would
// print them twice in an error chain).
impl From<prost::DecodeError> for DecodeError {
    fn from(e: prost::DecodeError) -> Self {
        Self::Proto(e)
    }
}
impl From<scenario::ScenarioError> for DecodeError {
    fn from(e: scenario::ScenarioError) -> Self {
        Self::Scenario(e)
    }
}
impl From<example::ExampleError> for DecodeError {
    fn from(e: example::ExampleError) -> Self {
        Self::Example(e)
    }
}

/// An error reading or writing a WOMD file. The message ends with the file's path.
#[derive(Debug, thiserror::Error)]
pub enum WomdError {
    /// Opening, mapping or writing the file failed.
    #[error("{error}: {}", path.display())]
    Io {
        /// The file.
        path: PathBuf,
        /// The underlying I/O error.
        error: std::io::Error,
    },
    /// The file has zero bytes.
    #[allow(missing_docs)]
    #[error("file is empty (no TFRecord records): {}", path.display())]
    EmptyFile { path: PathBuf },
    /// Bad TFRecord framing (truncation or CRC mismatch) at the given record.
    #[allow(missing_docs)]
    #[error("{error} in {}", path.display())]
    Framing { path: PathBuf, error: RecordAt },
    /// A well-framed record could not be decoded into a [`Scene`].
    #[error("record {index} at byte {offset}: {error} in {}", path.display())]
    Decode {
        /// The file.
        path: PathBuf,
        /// 0-based index of the record in the file.
        index: usize,
        /// Byte offset of the record's length field in the file.
        offset: u64,
        /// Why decoding failed.
        error: DecodeError,
    },
    /// A scene could not be encoded as a `Scenario` (see [`write_scenes`]).
    #[error("scenario {scenario_id}: {error} (writing {})", path.display())]
    Encode {
        /// The file being written.
        path: PathBuf,
        /// Id of the scene that failed.
        scenario_id: String,
        /// Why it failed.
        error: TrackIdOverflow,
    },
}

impl WomdError {
    /// The file the error is about.
    pub fn path(&self) -> &Path {
        match self {
            Self::Io { path, .. }
            | Self::EmptyFile { path }
            | Self::Framing { path, .. }
            | Self::Decode { path, .. }
            | Self::Encode { path, .. } => path,
        }
    }

    /// A short, stable name for the kind of problem, for skip counters in summaries.
    pub fn reason(&self) -> &'static str {
        match self {
            Self::Io { .. } => "io",
            Self::EmptyFile { .. } => "empty_file",
            Self::Framing { error, .. } => match error.kind {
                RecordError::TruncatedHeader { .. } | RecordError::TruncatedData { .. } => {
                    "truncated_record"
                }
                RecordError::LengthCrc { .. } => "bad_length_crc",
                RecordError::DataCrc { .. } => "bad_data_crc",
            },
            Self::Decode { error, .. } => match error {
                DecodeError::Proto(_) => "bad_protobuf",
                DecodeError::NotWomd { .. } => "not_womd",
                DecodeError::Scenario(scenario::ScenarioError::Scene(_))
                | DecodeError::Example(example::ExampleError::Scene(_)) => "invalid_scene",
                DecodeError::Scenario(_) | DecodeError::Example(_) => "bad_layout",
            },
            Self::Encode { .. } => "encode",
        }
    }
}

enum Bytes {
    Mapped(memmap2::Mmap),
    Owned(Vec<u8>),
}

/// A TFRecord file of WOMD records, memory-mapped.
pub struct WomdFile {
    path: PathBuf,
    bytes: Bytes,
}

impl fmt::Debug for WomdFile {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        f.debug_struct("WomdFile")
            .field("path", &self.path)
            .field("len", &self.bytes().len())
            .finish()
    }
}

impl WomdFile {
    /// Memory-maps `path`. A zero-length file is an error ([`WomdError::EmptyFile`]).
    pub fn open(path: impl AsRef<Path>) -> Result<Self, WomdError> {
        let path = path.as_ref().to_path_buf();
        let io = |error| WomdError::Io {
            path: path.clone(),
            error,
        };
        let file = std::fs::File::open(&path).map_err(io)?;
        let len = file.metadata().map_err(io)?.len();
        if len == 0 {
            return Err(WomdError::EmptyFile { path });
        }
        // SAFETY: the map is read-only and private to this process; like every mmap-based
        // reader we rely on the file not being truncated by another process while mapped.
        #[allow(unsafe_code)]
        let map = unsafe { memmap2::Mmap::map(&file) }.map_err(io)?;
        Ok(Self {
            path,
            bytes: Bytes::Mapped(map),
        })
    }

    /// Wraps in-memory bytes (tests, fuzzing); `label` stands in for the path in errors.
    pub fn from_bytes(label: impl Into<PathBuf>, bytes: Vec<u8>) -> Result<Self, WomdError> {
        let path = label.into();
        if bytes.is_empty() {
            return Err(WomdError::EmptyFile { path });
        }
        Ok(Self {
            path,
            bytes: Bytes::Owned(bytes),
        })
    }

    /// The file's path (or the label given to [`WomdFile::from_bytes`]).
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The raw file bytes.
    pub fn bytes(&self) -> &[u8] {
        match &self.bytes {
            Bytes::Mapped(m) => m,
            Bytes::Owned(v) => v,
        }
    }

    /// The file's records; framing errors carry the path.
    pub fn records(&self) -> impl Iterator<Item = Result<Record<'_>, WomdError>> + '_ {
        RecordIter::new(self.bytes()).map(|r| {
            r.map_err(|error| WomdError::Framing {
                path: self.path.clone(),
                error,
            })
        })
    }

    fn decode_error(&self, record: &Record<'_>, error: DecodeError) -> WomdError {
        WomdError::Decode {
            path: self.path.clone(),
            index: record.index,
            offset: record.offset,
            error,
        }
    }

    /// Detects the record format from the first record.
    pub fn detect_format(&self) -> Result<Format, WomdError> {
        let first = self
            .records()
            .next()
            .expect("a non-empty file has a first record or error")?;
        detect_record_format(first.data).map_err(|e| self.decode_error(&first, e))
    }

    /// Decodes every record into a [`Scene`], in file order. The format is detected once from
    /// the first record (which is decoded once, not once to detect and again to convert). Each
    /// item is an error or a scene; after a framing error that leaves the next record's start
    /// unknown, iteration stops.
    pub fn scenes(&self) -> impl Iterator<Item = Result<Scene, WomdError>> + '_ {
        let mut format: Option<Result<Format, DecodeError>> = None;
        self.records().map(move |record| {
            let record = record?;
            let scene = match &format {
                Some(fmt) => fmt.clone().and_then(|f| decode_record(record.data, f)),
                None => {
                    let detected = detect(record.data);
                    format = Some(
                        detected
                            .as_ref()
                            .map(Detected::format)
                            .map_err(Clone::clone),
                    );
                    detected.and_then(Detected::into_scene)
                }
            };
            scene.map_err(|e| self.decode_error(&record, e))
        })
    }
}

/// A first record, decoded as whichever message it is.
enum Detected {
    Example(proto::Example),
    /// A scenario as [`fast::decode_parts`] gives it.
    Scenario(proto::Scenario, Vec<Track>),
}

impl Detected {
    fn format(&self) -> Format {
        match self {
            Self::Example(_) => Format::TfExample,
            Self::Scenario(..) => Format::Scenario,
        }
    }

    fn into_scene(self) -> Result<Scene, DecodeError> {
        Ok(match self {
            Self::Example(ex) => example::scene_from_example(&ex)?,
            Self::Scenario(s, tracks) => scenario::scene_from_parts(&s, tracks)?,
        })
    }
}

fn detect(data: &[u8]) -> Result<Detected, DecodeError> {
    if let Ok(ex) = proto::Example::decode(data)
        && example::is_motion_example(&ex)
    {
        return Ok(Detected::Example(ex));
    }
    match fast::decode_parts(data) {
        Ok((s, tracks)) if s.scenario_id.is_some() => Ok(Detected::Scenario(s, tracks)),
        Ok(_) => Err(DecodeError::NotWomd {
            detail: "no `scenario_id`".into(),
        }),
        Err(e) => Err(DecodeError::NotWomd {
            detail: e.to_string(),
        }),
    }
}

/// Decides whether a serialized record is a motion tf.Example or a Scenario.
pub fn detect_record_format(data: &[u8]) -> Result<Format, DecodeError> {
    detect(data).map(|d| d.format())
}

/// Decodes one serialized record of a known format into a validated [`Scene`].
pub fn decode_record(data: &[u8], format: Format) -> Result<Scene, DecodeError> {
    match format {
        Format::Scenario => {
            let (scenario, tracks) = fast::decode_parts(data)?;
            Ok(scenario::scene_from_parts(&scenario, tracks)?)
        }
        Format::TfExample => {
            let example = proto::Example::decode(data)?;
            Ok(example::scene_from_example(&example)?)
        }
    }
}

/// Writes scenes as a `Scenario` TFRecord file, atomically: the data goes to a temporary file
/// in the same directory, which is renamed over `path` only when complete. Returns the number
/// of records written.
pub fn write_scenes<'a>(
    path: &Path,
    scenes: impl IntoIterator<Item = &'a Scene>,
) -> Result<usize, WomdError> {
    let io = |error| WomdError::Io {
        path: path.to_path_buf(),
        error,
    };
    let mut file = AtomicFile::create(path).map_err(|e| io(e.into()))?;
    let mut writer = RecordWriter::new(BufWriter::new(&mut file));
    for scene in scenes {
        let bytes = encode_scene(scene).map_err(|error| WomdError::Encode {
            path: path.to_path_buf(),
            scenario_id: scene.scenario_id.clone(),
            error,
        })?;
        writer.write_record(&bytes).map_err(io)?;
    }
    let n = writer.records_written();
    writer
        .into_inner()
        .into_inner()
        .map_err(|e| io(e.into_error()))?;
    file.commit().map_err(|e| io(e.into()))?;
    Ok(n)
}

/// Serializes scenes into an in-memory `Scenario` TFRecord (tests, fuzz seeds).
pub fn scenes_to_tfrecord_bytes<'a>(
    scenes: impl IntoIterator<Item = &'a Scene>,
) -> Result<Vec<u8>, TrackIdOverflow> {
    let mut w = RecordWriter::new(Vec::new());
    for s in scenes {
        w.write_record(&encode_scene(s)?)
            .expect("writing to a Vec cannot fail");
    }
    Ok(w.into_inner())
}

#[cfg(test)]
mod tests;
