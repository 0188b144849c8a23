//! Shard files: names, counts and the arguments checked.

use super::*;

// ---- (5) shard files ----

fn listing(dir: &Path) -> Vec<String> {
    let mut names: Vec<String> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
        .collect();
    names.sort();
    names
}

#[test]
fn three_scenarios_into_two_shards() {
    let scene = scene();
    let rollouts: Vec<_> = ["s0", "s1", "s2"]
        .iter()
        .map(|id| ScenarioRolloutsInput {
            scenario_id: (*id).into(),
            ..rollouts_for(&scene)
        })
        .collect();
    let dir = tempfile::tempdir().unwrap();
    let h = header();
    let paths = write_submission_shards(dir.path(), "x", &h, &rollouts, 2).unwrap();
    let names = ["x.binproto-00000-of-00002", "x.binproto-00001-of-00002"];
    assert_eq!(paths, names.map(|n| dir.path().join(n)));
    assert_eq!(listing(dir.path()), names, "no temporary files left");

    let mut seen = Vec::new();
    for path in &paths {
        let bytes = std::fs::read(path).unwrap();
        let (h2, r2) = decode_submission(&bytes).unwrap();
        assert_eq!(h2, h);
        assert!(!r2.is_empty());
        for r in r2 {
            let original = rollouts.iter().find(|o| o.scenario_id == r.scenario_id);
            assert_eq!(Some(&r), original);
            seen.push(r.scenario_id);
        }
    }
    seen.sort();
    assert_eq!(seen, ["s0", "s1", "s2"], "each scenario exactly once");
}

#[test]
fn shard_arguments_are_checked() {
    let dir = tempfile::tempdir().unwrap();
    let h = header();
    for shards in [0, MAX_SHARDS + 1] {
        let e = write_submission_shards(dir.path(), "x", &h, &[], shards).unwrap_err();
        assert!(matches!(e, WosacExportError::ShardCount { .. }), "{e}");
    }
    for name in ["", "a/b"] {
        let e = write_submission_shards(dir.path(), name, &h, &[], 1).unwrap_err();
        assert!(matches!(e, WosacExportError::ShardName { .. }), "{e}");
    }
    let r = rollouts_for(&scene());
    let e = write_submission_shards(dir.path(), "x", &h, &[r.clone(), r], 2).unwrap_err();
    assert!(
        matches!(e, WosacExportError::DuplicateScenario { .. }),
        "{e}"
    );
    assert!(listing(dir.path()).is_empty());

    // More shards than scenarios: the extra shards are header-only submissions.
    let nested = dir.path().join("new").join("folder");
    let paths = write_submission_shards(&nested, "y", &h, &[], 3).unwrap();
    assert_eq!(paths.len(), 3);
    for p in &paths {
        let (h2, r2) = decode_submission(&std::fs::read(p).unwrap()).unwrap();
        assert_eq!((h2, r2.len()), (h.clone(), 0));
    }
    assert_eq!(shard_file_name("y", 2, 3), "y.binproto-00002-of-00003");
}
