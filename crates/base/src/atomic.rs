//! Atomic file writing: the complete file appears at its destination, or nothing changes.
//!
//! Data goes to a temporary file in the destination's folder (`.` when the path has no
//! parent), which is synced and renamed over the destination when complete. On any failure,
//! and when an [`AtomicFile`] is dropped without [`AtomicFile::commit`], the temporary file
//! is removed and the destination keeps what it held before. Temporary names are
//! `.tmp<random>.tmp` (hidden, and with an extension, so that libraries which add one to a
//! bare name write where they are told).
//!
//! The file ends up with the permissions [`std::fs::File::create`] gives: on Unix `0o666`
//! masked by the process umask, not the owner-only `0o600` that `tempfile` uses by default.
//!
//! **Stale temporary files.** A process killed mid-write (SIGKILL, power loss) cannot remove
//! its temporary file. Every writer therefore holds an exclusive advisory lock on its
//! temporary file while it lives, and the first atomic write of a process into a folder
//! removes the temporary files there that nobody holds ([`sweep_stale`]): those of dead
//! writers. Live writers in other processes, such as shards sharing an output folder, keep
//! theirs. (A library given the temporary path by [`write_with_path`] that *replaces* the file
//! leaves the replacement unlocked until the rename; a sweep starting in that instant may take
//! it, and the write fails with an error rather than leaving a wrong file.)
//!
//! Entry points:
//! - [`write()`]: bytes or text;
//! - [`write_json`]: a value as pretty JSON followed by a newline;
//! - [`write_with`]: a callback that writes to the open temporary file;
//! - [`write_with_path`]: a callback given the temporary file's path, for libraries that
//!   open the file themselves;
//! - [`AtomicFile`]: a streaming writer ([`Write`]) whose commit comes later;
//! - [`sweep_stale`]: removes dead writers' temporary files from a folder.

use std::collections::HashSet;
use std::fs::File;
use std::io::{self, BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Mutex;

use serde::Serialize;

/// An error writing a file atomically; names the destination.
///
/// Crates whose own error type names the path convert it with `io::Error::from` (the
/// [`Io`](Self::Io) variant gives its `io::Error` back unchanged).
#[derive(Debug, thiserror::Error)]
pub enum AtomicWriteError {
    /// Creating, writing, syncing or renaming the temporary file failed.
    #[error("{error}: {}", path.display())]
    Io {
        /// The destination.
        path: PathBuf,
        /// The underlying error.
        error: io::Error,
    },
    /// The value given to [`write_json`] could not be serialised.
    #[error("{error}: {}", path.display())]
    Json {
        /// The destination.
        path: PathBuf,
        /// The serialisation error.
        error: serde_json::Error,
    },
}

impl AtomicWriteError {
    /// The destination that was being written.
    pub fn path(&self) -> &Path {
        match self {
            Self::Io { path, .. } | Self::Json { path, .. } => path,
        }
    }

    fn io(path: &Path, error: io::Error) -> Self {
        Self::Io {
            path: path.to_path_buf(),
            error,
        }
    }
}

impl From<AtomicWriteError> for io::Error {
    /// The underlying error, without the path: for callers whose own error names it.
    /// A serialisation error becomes an `io::Error` as `serde_json` converts it.
    fn from(e: AtomicWriteError) -> Self {
        match e {
            AtomicWriteError::Io { error, .. } => error,
            AtomicWriteError::Json { error, .. } => error.into(),
        }
    }
}

/// A file being written atomically: a temporary file next to the destination, renamed into
/// place by [`commit`](Self::commit). Dropping it uncommitted removes the temporary file.
///
/// Writes through [`Write`] (or [`file_mut`](Self::file_mut)) are unbuffered; wrap it in a
/// [`BufWriter`] (e.g. `BufWriter::new(&mut atomic_file)`) for many small writes.
#[derive(Debug)]
pub struct AtomicFile {
    path: PathBuf,
    temp: tempfile::NamedTempFile,
}

impl AtomicFile {
    /// Creates the temporary file for `path` in `path`'s folder (`.` when it has none). The
    /// destination itself is not touched until [`commit`](Self::commit).
    pub fn create(path: impl AsRef<Path>) -> Result<Self, AtomicWriteError> {
        let path = path.as_ref();
        let dir = path
            .parent()
            .filter(|p| !p.as_os_str().is_empty())
            .unwrap_or(Path::new("."));
        sweep_once(dir);
        let temp = locked_temp_in(dir).map_err(|error| AtomicWriteError::io(path, error))?;
        Ok(Self {
            path: path.to_path_buf(),
            temp,
        })
    }

    /// The destination.
    pub fn path(&self) -> &Path {
        &self.path
    }

    /// The temporary file's path (in the destination's folder).
    pub fn temp_path(&self) -> &Path {
        self.temp.path()
    }

    /// The open temporary file.
    pub fn file_mut(&mut self) -> &mut File {
        self.temp.as_file_mut()
    }

    /// Syncs the temporary file to disk and renames it over the destination. On failure the
    /// temporary file is removed and the destination is unchanged.
    pub fn commit(self) -> Result<(), AtomicWriteError> {
        let Self { path, temp } = self;
        temp.as_file()
            .sync_all()
            .map_err(|error| AtomicWriteError::io(&path, error))?;
        temp.persist(&path)
            .map_err(|e| AtomicWriteError::io(&path, e.error))?;
        Ok(())
    }
}

impl Write for AtomicFile {
    fn write(&mut self, buf: &[u8]) -> io::Result<usize> {
        self.temp.write(buf)
    }

    fn write_vectored(&mut self, bufs: &[io::IoSlice<'_>]) -> io::Result<usize> {
        self.temp.write_vectored(bufs)
    }

    fn write_all(&mut self, buf: &[u8]) -> io::Result<()> {
        self.temp.write_all(buf)
    }

    fn flush(&mut self) -> io::Result<()> {
        self.temp.flush()
    }
}

/// Prefix and suffix of temporary names: `.tmp<random>.tmp`.
const TEMP_PREFIX: &str = ".tmp";
const TEMP_SUFFIX: &str = ".tmp";

/// A new temporary file in `dir`, exclusively locked, and still at its path once locked (a
/// sweep in another process may have taken it between its creation and the lock: then a new
/// one is made).
fn locked_temp_in(dir: &Path) -> io::Result<tempfile::NamedTempFile> {
    let mut builder = tempfile::Builder::new();
    builder.prefix(TEMP_PREFIX).suffix(TEMP_SUFFIX);
    // What `File::create` asks for; the kernel masks it with the umask at creation.
    #[cfg(unix)]
    builder.permissions(std::os::unix::fs::PermissionsExt::from_mode(0o666));
    for _ in 0..8 {
        let temp = builder.tempfile_in(dir)?;
        if temp.as_file().lock().is_err() {
            // A file system without advisory locks: write unlocked. No sweep can take the
            // file then (its `try_lock` fails too), so a killed writer's file stays.
            return Ok(temp);
        }
        if still_at_path(&temp)? {
            return Ok(temp);
        }
    }
    Err(io::Error::other(format!(
        "temporary files in {} keep vanishing (another process sweeping?)",
        dir.display()
    )))
}

/// Whether the file at `temp`'s path is the one `temp` has open.
fn still_at_path(temp: &tempfile::NamedTempFile) -> io::Result<bool> {
    let at_path = match std::fs::symlink_metadata(temp.path()) {
        Ok(m) => m,
        Err(e) if e.kind() == io::ErrorKind::NotFound => return Ok(false),
        Err(e) => return Err(e),
    };
    #[cfg(unix)]
    {
        use std::os::unix::fs::MetadataExt;
        let open = temp.as_file().metadata()?;
        Ok(open.dev() == at_path.dev() && open.ino() == at_path.ino())
    }
    #[cfg(not(unix))]
    {
        Ok(at_path.is_file())
    }
}

/// Whether `name` is one of this module's temporary names.
fn is_temp_name(name: &str) -> bool {
    name.len() > TEMP_PREFIX.len() + TEMP_SUFFIX.len()
        && name.starts_with(TEMP_PREFIX)
        && name.ends_with(TEMP_SUFFIX)
}

/// Sweeps `dir` the first time this process writes there ([`sweep_stale`]); a failed sweep
/// is not an error for the write (it only leaves stale files where they were).
fn sweep_once(dir: &Path) {
    static SWEPT: Mutex<Option<HashSet<PathBuf>>> = Mutex::new(None);
    let key = std::fs::canonicalize(dir).unwrap_or_else(|_| dir.to_path_buf());
    let first = SWEPT
        .lock()
        .unwrap_or_else(|p| p.into_inner())
        .get_or_insert_with(HashSet::new)
        .insert(key);
    // The base crate has no logger: a failed sweep is said on stderr, once per folder.
    if first && let Err(e) = sweep_stale(dir) {
        eprintln!(
            "warning: could not sweep stale temporary files in {}: {e}",
            dir.display()
        );
    }
}

/// Removes the temporary files in `dir` that no live writer holds (those a killed process
/// left) and returns how many it removed. Files another process is writing stay, and so does
/// every file where the file system has no advisory locks. A file that vanishes meanwhile (its
/// writer committed it) is not an error.
pub fn sweep_stale(dir: &Path) -> io::Result<usize> {
    let mut removed = 0;
    for entry in std::fs::read_dir(dir)? {
        let entry = entry?;
        let name = entry.file_name();
        if !name.to_str().is_some_and(is_temp_name) || !entry.file_type()?.is_file() {
            continue;
        }
        let path = entry.path();
        let file = match File::open(&path) {
            Ok(f) => f,
            Err(e) if e.kind() == io::ErrorKind::NotFound => continue,
            Err(e) => return Err(e),
        };
        match file.try_lock() {
            Ok(()) => match std::fs::remove_file(&path) {
                Ok(()) => removed += 1,
                Err(e) if e.kind() == io::ErrorKind::NotFound => {}
                Err(e) => return Err(e),
            },
            // Held by a live writer, or no advisory locks on this file system: leave it.
            Err(std::fs::TryLockError::WouldBlock | std::fs::TryLockError::Error(_)) => {}
        }
    }
    Ok(removed)
}

/// Writes `path` atomically with `write`, which gets the open temporary file. The file is
/// renamed into place only when `write` returns `Ok`; its error is returned as is, and the
/// writer's own failures (creating, syncing, renaming) as `E::from(AtomicWriteError)` —
/// `E` may be [`AtomicWriteError`], [`io::Error`] or a crate's error type.
pub fn write_with<T, E>(
    path: impl AsRef<Path>,
    write: impl FnOnce(&mut File) -> Result<T, E>,
) -> Result<T, E>
where
    E: From<AtomicWriteError>,
{
    let mut file = AtomicFile::create(path)?;
    let out = write(file.file_mut())?;
    file.commit()?;
    Ok(out)
}

/// Like [`write_with`], for libraries that open the file themselves: `write` gets the path
/// of the (already created, empty) temporary file, which it may truncate, rewrite or
/// replace (rename over); whatever is at that path when it returns `Ok` is renamed into
/// place. Data written through other handles to the same file is synced with it; a library
/// that replaces the file is trusted to have synced its own.
pub fn write_with_path<T, E>(
    path: impl AsRef<Path>,
    write: impl FnOnce(&Path) -> Result<T, E>,
) -> Result<T, E>
where
    E: From<AtomicWriteError>,
{
    let file = AtomicFile::create(path)?;
    let out = write(file.temp_path())?;
    file.commit()?;
    Ok(out)
}

/// Writes `contents` (bytes or text) to `path` atomically.
pub fn write(path: impl AsRef<Path>, contents: impl AsRef<[u8]>) -> Result<(), AtomicWriteError> {
    let path = path.as_ref();
    write_with(path, |f| {
        f.write_all(contents.as_ref())
            .map_err(|error| AtomicWriteError::io(path, error))
    })
}

/// Writes `value` to `path` atomically as pretty-printed JSON (`serde_json`'s two-space
/// indent) followed by a newline.
pub fn write_json<T: Serialize + ?Sized>(
    path: impl AsRef<Path>,
    value: &T,
) -> Result<(), AtomicWriteError> {
    let path = path.as_ref();
    write_with(path, |f| {
        let mut out = BufWriter::new(f);
        serde_json::to_writer_pretty(&mut out, value).map_err(|error| {
            if error.is_io() {
                AtomicWriteError::io(path, error.into())
            } else {
                AtomicWriteError::Json {
                    path: path.to_path_buf(),
                    error,
                }
            }
        })?;
        out.write_all(b"\n")
            .and_then(|()| out.flush())
            .map_err(|error| AtomicWriteError::io(path, error))
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Names in `dir`, sorted.
    fn listing(dir: &Path) -> Vec<String> {
        let mut names: Vec<String> = std::fs::read_dir(dir)
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .collect();
        names.sort();
        names
    }

    #[test]
    fn writes_bytes_text_and_json() {
        let dir = tempfile::tempdir().unwrap();
        let bytes = dir.path().join("a.bin");
        write(&bytes, [0u8, 1, 2, 255]).unwrap();
        assert_eq!(std::fs::read(&bytes).unwrap(), [0, 1, 2, 255]);
        let text = dir.path().join("b.txt");
        write(&text, "first").unwrap();
        write(&text, String::from("second\n")).unwrap();
        assert_eq!(std::fs::read_to_string(&text).unwrap(), "second\n");

        #[derive(Serialize)]
        struct Value {
            name: &'static str,
            values: Vec<u32>,
        }
        let json = dir.path().join("c.json");
        let value = Value {
            name: "x",
            values: vec![1, 2],
        };
        write_json(&json, &value).unwrap();
        let expected = serde_json::to_string_pretty(&value).unwrap() + "\n";
        assert_eq!(std::fs::read_to_string(&json).unwrap(), expected);
        assert_eq!(listing(dir.path()), ["a.bin", "b.txt", "c.json"]);
    }

    #[test]
    fn streaming_writer_commits_later_and_drop_removes_it() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("stream.bin");
        let mut file = AtomicFile::create(&path).unwrap();
        assert_eq!(file.path(), path);
        assert_eq!(file.temp_path().parent(), Some(dir.path()));
        {
            let mut out = BufWriter::new(&mut file);
            out.write_all(b"abc").unwrap();
            out.flush().unwrap();
        }
        file.file_mut().write_all(b"def").unwrap();
        assert!(!path.exists(), "nothing at the destination before commit");
        file.commit().unwrap();
        assert_eq!(std::fs::read(&path).unwrap(), b"abcdef");

        let mut file = AtomicFile::create(&path).unwrap();
        file.write_all(b"never committed").unwrap();
        drop(file);
        assert_eq!(std::fs::read(&path).unwrap(), b"abcdef");
        assert_eq!(listing(dir.path()), ["stream.bin"]);
    }

    #[test]
    fn a_failing_callback_leaves_nothing_behind() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("keep.txt");
        write(&path, "old").unwrap();
        let e = write_with(&path, |f| {
            f.write_all(b"partial").unwrap();
            Err::<(), _>(io::Error::other("callback failed"))
        })
        .unwrap_err();
        assert_eq!(e.to_string(), "callback failed");
        let e = write_with_path(&path, |tmp| {
            std::fs::write(tmp, "partial").unwrap();
            Err::<(), _>(AtomicWriteError::io(
                tmp,
                io::Error::other("library failed"),
            ))
        })
        .unwrap_err();
        assert!(e.to_string().contains("library failed"), "{e}");
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "old");
        assert_eq!(listing(dir.path()), ["keep.txt"]);
    }

    #[test]
    fn path_callback_may_rewrite_or_replace_the_file() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("lib.out");
        let n = write_with_path(&path, |tmp| {
            assert!(
                tmp.extension().is_some(),
                "a library adding an extension would miss it"
            );
            std::fs::write(tmp, "rewritten").map(|()| 9)
        })
        .unwrap();
        assert_eq!(n, 9);
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "rewritten");
        write_with_path::<_, io::Error>(&path, |tmp| {
            let other = tmp.with_extension("other");
            std::fs::write(&other, "replaced")?;
            std::fs::rename(&other, tmp)
        })
        .unwrap();
        assert_eq!(std::fs::read_to_string(&path).unwrap(), "replaced");
        assert_eq!(listing(dir.path()), ["lib.out"]);
    }

    #[test]
    fn errors_name_the_destination() {
        let dir = tempfile::tempdir().unwrap();
        let path = dir.path().join("missing-folder").join("x.json");
        let e = write_json(&path, &[1, 2]).unwrap_err();
        assert_eq!(e.path(), path);
        assert!(e.to_string().contains("missing-folder"), "{e}");
        let kind = io::Error::from(e).kind();
        assert_eq!(kind, io::ErrorKind::NotFound);

        // A map with non-string keys cannot be JSON.
        let bad: std::collections::BTreeMap<(u8, u8), u8> = [((1, 2), 3)].into();
        let json = dir.path().join("bad.json");
        let e = write_json(&json, &bad).unwrap_err();
        assert!(matches!(e, AtomicWriteError::Json { .. }), "{e:?}");
        assert!(e.to_string().contains("bad.json"), "{e}");
        assert!(listing(dir.path()).is_empty());
    }

    #[test]
    fn dead_writers_temporary_files_are_swept_and_live_ones_kept() {
        let dir = tempfile::tempdir().unwrap();
        // What a killed writer leaves: a temporary name nobody holds.
        let stale = dir.path().join(".tmpDEAD01.tmp");
        std::fs::write(&stale, "partial").unwrap();
        // A live writer in the same folder (its lock conflicts with the sweep's, as another
        // process's would).
        let mut live = AtomicFile::create(dir.path().join("live.bin")).unwrap();
        live.write_all(b"in progress").unwrap();
        assert!(!stale.exists(), "the first write into the folder sweeps it");
        let other_stale = dir.path().join(".tmpDEAD02.tmp");
        std::fs::write(&other_stale, "partial").unwrap();
        // Names that only look similar, and folders, are never touched.
        for keep in [".tmp", "a.tmp", ".tmpx"] {
            std::fs::write(dir.path().join(keep), "user data").unwrap();
        }
        std::fs::create_dir(dir.path().join(".tmpdir.tmp")).unwrap();
        assert_eq!(sweep_stale(dir.path()).unwrap(), 1);
        assert!(!other_stale.exists());
        assert!(live.temp_path().exists(), "a live writer's file stays");
        live.commit().unwrap();
        assert_eq!(
            listing(dir.path()),
            [".tmp", ".tmpdir.tmp", ".tmpx", "a.tmp", "live.bin"]
        );
        assert_eq!(
            std::fs::read(dir.path().join("live.bin")).unwrap(),
            b"in progress"
        );
    }

    /// The committed file has the mode `File::create` gives in the same folder (0o666 masked
    /// by the umask), not tempfile's 0o600.
    #[cfg(unix)]
    #[test]
    fn permissions_match_file_create() {
        use std::os::unix::fs::PermissionsExt;
        let dir = tempfile::tempdir().unwrap();
        let reference = dir.path().join("reference");
        File::create(&reference).unwrap();
        let mode = |p: &Path| std::fs::metadata(p).unwrap().permissions().mode() & 0o7777;
        let expected = mode(&reference);
        let atomic = dir.path().join("atomic");
        write(&atomic, "x").unwrap();
        assert_eq!(
            mode(&atomic),
            expected,
            "{:o} vs {expected:o}",
            mode(&atomic)
        );
        let streamed = dir.path().join("streamed");
        let mut file = AtomicFile::create(&streamed).unwrap();
        file.write_all(b"x").unwrap();
        file.commit().unwrap();
        assert_eq!(mode(&streamed), expected);
        // And that is 0o666 masked by the process umask (Linux reports it in /proc).
        #[cfg(target_os = "linux")]
        {
            let status = std::fs::read_to_string("/proc/self/status").unwrap();
            let umask = status
                .lines()
                .find_map(|l| l.strip_prefix("Umask:"))
                .map(|m| u32::from_str_radix(m.trim(), 8).unwrap());
            if let Some(umask) = umask {
                assert_eq!(expected, 0o666 & !umask, "umask {umask:o}");
            }
        }
    }
}
