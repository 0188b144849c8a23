//! The shards of a submission file: the file itself, or the shards inside a gzip-compressed tar
//! archive (the challenge's upload format), read one at a time.

use std::io::{Read, Seek};
use std::path::Path;

/// The two bytes every gzip stream starts with. No submission shard starts with them: 0x1F
/// would be field 3 with wire type 7, which protobuf does not have.
const GZIP_MAGIC: [u8; 2] = [0x1F, 0x8B];

/// Why a submission file, or an archive from some entry on, could not be read.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ReadError {
    /// The kind of problem, for the skip counters.
    pub reason: &'static str,
    /// The full message, naming the file (and the archive entry).
    pub detail: String,
}

/// Calls `each(name, bytes)` for every shard of `path`, in order: the file itself, or each
/// regular file of a `.tar.gz` archive (recognised by the gzip magic, whatever its name) whose
/// name contains `.binproto`, named `archive:entry` (other entries are ignored; an archive
/// without any shard is an error). The archive is streamed: one shard is in memory at a time.
/// An error ends the file; the shards before it have been passed on.
pub fn for_each_shard(path: &Path, mut each: impl FnMut(String, Vec<u8>)) -> Result<(), ReadError> {
    let io = |e: std::io::Error| ReadError {
        reason: "unreadable submission file",
        detail: format!("reading {}: {e}", path.display()),
    };
    let mut file = std::fs::File::open(path).map_err(io)?;
    let mut magic = Vec::with_capacity(GZIP_MAGIC.len());
    (&mut file)
        .take(GZIP_MAGIC.len() as u64)
        .read_to_end(&mut magic)
        .map_err(io)?;
    file.rewind().map_err(io)?;
    if magic != GZIP_MAGIC {
        let mut bytes = Vec::new();
        file.read_to_end(&mut bytes).map_err(io)?;
        each(path.display().to_string(), bytes);
        return Ok(());
    }
    let archive_error = |reason: &'static str, what: String| ReadError {
        reason,
        detail: format!("{}: {what}", path.display()),
    };
    let unreadable = "unreadable submission archive";
    let mut archive =
        tar::Archive::new(flate2::read::GzDecoder::new(std::io::BufReader::new(file)));
    let entries = archive
        .entries()
        .map_err(|e| archive_error(unreadable, format!("not a tar.gz archive: {e}")))?;
    let (mut shards, mut others) = (0usize, Vec::new());
    for (k, entry) in entries.enumerate() {
        let mut entry = entry.map_err(|e| archive_error(unreadable, format!("entry {k}: {e}")))?;
        if !entry.header().entry_type().is_file() {
            continue;
        }
        let entry_path = entry
            .path()
            .map_err(|e| archive_error(unreadable, format!("entry {k}: {e}")))?
            .display()
            .to_string();
        let is_shard = Path::new(&entry_path)
            .file_name()
            .is_some_and(|n| n.to_string_lossy().contains(".binproto"));
        if !is_shard {
            others.push(entry_path);
            continue;
        }
        // Grown as it is read, never allocated from the header's size.
        let mut data = Vec::new();
        entry
            .read_to_end(&mut data)
            .map_err(|e| archive_error(unreadable, format!("entry {k} ({entry_path}): {e}")))?;
        shards += 1;
        each(format!("{}:{entry_path}", path.display()), data);
    }
    if shards == 0 {
        return Err(archive_error(
            "no shard in the archive",
            format!(
                "no file named like NAME.binproto-00000-of-00001 among its {} file(s) {:?}",
                others.len(),
                &others[..others.len().min(5)]
            ),
        ));
    }
    Ok(())
}
