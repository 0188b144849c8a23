//! The wheel's build and the workspace's resolve every shared crate with the same features.
//!
//! maturin builds `scbg-python` alone, and Cargo picks a dependency's features from the packages
//! being built: where the two builds disagree on a crate, it and everything above it (burn,
//! arrow, …) are compiled twice, once for the wheel and once for `cargo test --workspace`. The
//! feature-unification list in `crates/python/Cargo.toml` keeps them alike; this test names what
//! to add when a dependency change makes them drift.

use std::collections::{BTreeMap, BTreeSet};
use std::path::Path;
use std::process::Command;

/// Each package of `cargo tree ARGS` with the feature sets it is built with.
fn resolved_features(args: &[&str]) -> BTreeMap<String, BTreeSet<String>> {
    let cargo = std::env::var("CARGO").unwrap_or_else(|_| "cargo".into());
    let out = Command::new(cargo)
        .current_dir(Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."))
        .args(["tree", "--offline", "--locked", "--prefix", "none"])
        .args(["--format", "{p}|{f}"])
        .args(args)
        .output()
        .expect("cargo tree runs");
    assert!(
        out.status.success(),
        "cargo tree {args:?}: {}",
        String::from_utf8_lossy(&out.stderr)
    );
    let mut packages: BTreeMap<String, BTreeSet<String>> = BTreeMap::new();
    for line in String::from_utf8_lossy(&out.stdout).lines() {
        // A package already listed above is marked `(*)` at the end of its line.
        let line = line.trim_end().trim_end_matches("(*)").trim_end();
        if let Some((package, features)) = line.split_once('|') {
            let (package, features) = (package.trim().to_owned(), features.to_owned());
            packages.entry(package).or_default().insert(features);
        }
    }
    packages
}

#[test]
fn the_wheel_resolves_shared_crates_with_the_workspaces_features() {
    let wheel = resolved_features(&["-p", "scbg-python", "--edges", "normal,build"]);
    let workspace = resolved_features(&["--workspace", "--edges", "normal,build,dev"]);
    assert!(
        wheel.len() > 100,
        "cargo tree listed {} packages",
        wheel.len()
    );
    let drift: Vec<String> = wheel
        .iter()
        .filter(|(package, features)| workspace.get(*package) != Some(*features))
        .map(|(package, features)| {
            format!(
                "  {package}: wheel {features:?}, workspace {:?}",
                workspace.get(package)
            )
        })
        .collect();
    assert!(
        drift.is_empty(),
        "maturin's build of scbg-python would compile these crates again, with other features \
         than `cargo test --workspace`; list the workspace's features for them in \
         crates/python/Cargo.toml (feature unification):\n{}",
        drift.join("\n")
    );
}
