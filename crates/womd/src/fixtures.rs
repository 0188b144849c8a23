//! Where the shared real WOMD/nuScenes files live, for tests and benchmarks.
//!
//! `SCBG_REAL_DATA` overrides the default `<workspace>/../shared/data/real`. When the folder is
//! absent, [`real_data_dir`] returns `None` after printing why, so a test can skip with a clear
//! message; under CI (`CI` set) a missing folder is a failure instead, never a silent pass.

use std::path::PathBuf;

/// The folder holding `womd/`, `womd-reencoded/` and `nuscenes-reencoded/`.
pub fn real_data_dir() -> Option<PathBuf> {
    let dir = std::env::var_os("SCBG_REAL_DATA")
        .map(PathBuf::from)
        .unwrap_or_else(|| {
            PathBuf::from(env!("CARGO_MANIFEST_DIR")).join("../../../shared/data/real")
        });
    if dir.join("womd").is_dir() {
        return Some(dir);
    }
    if std::env::var_os("CI").is_some() {
        panic!(
            "real data folder {} is missing in CI (set SCBG_REAL_DATA)",
            dir.display()
        );
    }
    eprintln!(
        "SKIPPED: real data folder {} not found (set SCBG_REAL_DATA)",
        dir.display()
    );
    None
}

/// Every `.tfrecord` file of the shared real folders (`womd/`, `womd-reencoded/`,
/// `nuscenes-reencoded/`), sorted; `None` as [`real_data_dir`]. Panics when a folder cannot be
/// read (a test's broken fixture, never a silent skip).
pub fn real_tfrecords() -> Option<Vec<PathBuf>> {
    let dir = real_data_dir()?;
    let mut paths: Vec<PathBuf> = ["womd", "womd-reencoded", "nuscenes-reencoded"]
        .iter()
        .flat_map(|sub| {
            let sub = dir.join(sub);
            std::fs::read_dir(&sub).unwrap_or_else(|e| panic!("{}: {e}", sub.display()))
        })
        .map(|entry| entry.expect("a real-data folder entry").path())
        .filter(|p| p.extension().is_some_and(|e| e == "tfrecord"))
        .collect();
    paths.sort();
    Some(paths)
}
