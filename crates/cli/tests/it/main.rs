//! Integration tests: the `scbg` binary on the genuine Waymo/nuScenes files, on corrupt
//! inputs, on WOSAC submissions, and on generated data. One test binary; helpers at the top.

use std::path::{Path, PathBuf};
use std::process::{Command, Output};

use serde_json::Value;

mod corrupt;
mod demo;
mod direction;
mod fuzz_corpus;
mod generator;
mod kill;
mod pipeline;
mod predictor;
mod real_data;
mod repo;
mod scale;
mod wosac;

pub fn scbg(args: &[&str]) -> Output {
    Command::new(env!("CARGO_BIN_EXE_scbg"))
        .args(args)
        .env("SCBG_LOG", "error")
        .output()
        .expect("run scbg")
}

/// A pipeline settings file (docs/pipeline.toml's format) with `text`, in `dir`.
pub fn settings(dir: &Path, text: &str) -> PathBuf {
    use std::sync::atomic::{AtomicUsize, Ordering};
    static NEXT: AtomicUsize = AtomicUsize::new(0);
    let path = dir.join(format!(
        "settings-{}.toml",
        NEXT.fetch_add(1, Ordering::Relaxed)
    ));
    std::fs::write(&path, text).unwrap();
    path
}

/// Runs scbg and asserts success; returns stdout.
pub fn scbg_ok(args: &[&str]) -> String {
    let out = scbg(args);
    assert!(
        out.status.success(),
        "scbg {args:?} failed: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    String::from_utf8(out.stdout).unwrap()
}

/// One JSON object per line of `scbg data inspect --json`.
pub fn inspect_json(files: &[&Path]) -> Vec<Value> {
    let mut args = vec!["data", "inspect", "--json"];
    let names: Vec<String> = files.iter().map(|f| f.display().to_string()).collect();
    args.extend(names.iter().map(String::as_str));
    scbg_ok(&args)
        .lines()
        .map(|l| serde_json::from_str(l).unwrap())
        .collect()
}

pub fn real_dir() -> Option<PathBuf> {
    scbg_womd::fixtures::real_data_dir()
}

/// A PNG at `path` that decodes to `size` (width, height) with something drawn on it: a
/// share of its pixels (1–95 %) differs from the background (its corner's colour), in at
/// least three colours.
pub fn assert_drawn_png(path: &Path, size: (u32, u32)) {
    let img = scbg_plot::read_png(path).unwrap_or_else(|e| panic!("{e}"));
    assert_eq!((img.width, img.height), size, "{}", path.display());
    let background = img.pixels().next().expect("a non-empty image");
    let drawn: Vec<[u8; 4]> = img.pixels().filter(|p| *p != background).collect();
    let share = drawn.len() as f64 / f64::from(size.0 * size.1);
    assert!(
        (0.01..=0.95).contains(&share),
        "{}: {:.1} % of the pixels drawn",
        path.display(),
        100.0 * share
    );
    let colours: std::collections::BTreeSet<[u8; 4]> = drawn.iter().copied().collect();
    assert!(
        colours.len() >= 3,
        "{}: colours {colours:?}",
        path.display()
    );
}
