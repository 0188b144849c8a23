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
