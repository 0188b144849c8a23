//! Checks on the repository itself: the layering the architecture promises, the size limits of
//! the docs and sources, and that nothing tracked reads like a work log.

use std::path::{Path, PathBuf};

fn root() -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join("../..")
}

/// Every tracked file (git ls-files), relative to the root.
fn tracked() -> Vec<PathBuf> {
    let out = std::process::Command::new("git")
        .arg("-C")
        .arg(root())
        .args(["ls-files", "-z"])
        .output()
        .expect("git ls-files");
    assert!(out.status.success(), "git ls-files failed");
    out.stdout
        .split(|&b| b == 0)
        .filter(|p| !p.is_empty())
        .map(|p| PathBuf::from(String::from_utf8_lossy(p).into_owned()))
        .filter(|p| root().join(p).is_file())
        .collect()
}

/// The Rust sources of a crate, without its tests (`tests.rs`, `tests/`).
fn sources(dir: &str) -> Vec<(PathBuf, String)> {
    tracked()
        .into_iter()
        .filter(|p| p.starts_with(dir) && p.extension().is_some_and(|e| e == "rs"))
        .filter(|p| {
            !p.components().any(|c| c.as_os_str() == "tests")
                && p.file_name().is_none_or(|n| n != "tests.rs")
        })
        .map(|p| {
            let text = std::fs::read_to_string(root().join(&p)).unwrap();
            (p, text)
        })
        .collect()
}

/// Lines of `text` matching any of `words`, as `file:line: text`.
fn hits(file: &Path, text: &str, words: &[&str]) -> Vec<String> {
    text.lines()
        .enumerate()
        .filter(|(_, l)| words.iter().any(|w| l.contains(w)))
        .map(|(i, l)| format!("{}:{}: {}", file.display(), i + 1, l.trim()))
        .collect()
}

#[test]
fn front_ends_go_through_the_runtime_only() {
    // What a front end must leave to the runtime: the generator's and the simulator's types
    // and settings, pair-context caches, courtesy parsing, model internals.
    let forbidden = [
        "scbg::sim::",
        "scbg::generate::",
        "scbg::model::",
        "scbg_generator",
        "scbg_sim",
        "PairContext",
        "SimConfig",
        "default_replan_every",
        "Courtesy::Quantile",
        "Courtesy::Psi",
        "LoadedScbg",
        ".scbg.",
        "contexts",
    ];
    let mut found = Vec::new();
    for dir in ["crates/serve/src", "crates/python/src"] {
        let files = sources(dir);
        assert!(!files.is_empty(), "no sources under {dir}");
        for (file, text) in files {
            found.extend(hits(&file, &text, &forbidden));
        }
    }
    assert!(
        found.is_empty(),
        "front ends past the runtime:\n{}",
        found.join("\n")
    );
    // Nor may they depend on a crate below the runtime, or on the lab.
    for manifest in ["crates/serve/Cargo.toml", "crates/python/Cargo.toml"] {
        let text = std::fs::read_to_string(root().join(manifest)).unwrap();
        let deps = text
            .split("[dependencies]")
            .nth(1)
            .and_then(|d| d.split("\n[").next())
            .unwrap_or_default();
        for line in deps.lines() {
            let name = line.split(['=', '.', ' ']).next().unwrap_or("").trim();
            assert!(
                !name.starts_with("scbg-"),
                "{manifest}: depends on {name}; front ends depend on `scbg` alone"
            );
        }
    }
}

#[test]
fn the_runtime_never_depends_on_the_lab() {
    let text = std::fs::read_to_string(root().join("crates/scbg/Cargo.toml")).unwrap();
    assert!(!text.contains("scbg-lab"), "crates/scbg depends on the lab");
    let mut found = Vec::new();
    for (file, text) in sources("crates/scbg/src") {
        found.extend(hits(&file, &text, &["scbg_lab"]));
    }
    assert!(found.is_empty(), "{}", found.join("\n"));
}

#[test]
fn one_quantile_to_psi_mapping_and_one_ranked_choice() {
    // Definitions, not calls: each written once in the code.
    let count = |needle: &str| {
        tracked()
            .into_iter()
            .filter(|p| p.extension().is_some_and(|e| e == "rs"))
            .map(|p| std::fs::read_to_string(root().join(p)).unwrap())
            .map(|t| t.matches(needle).count())
            .sum::<usize>()
    };
    // The needles are put together here so that this file does not count.
    assert_eq!(count(&format!("fn {}(", "psi_for_quantile")), 1);
    assert_eq!(count(&format!("fn {}(", "ranked_choice")), 1);
}

#[test]
fn sources_stay_small_and_docs_short() {
    let mut long = Vec::new();
    for p in tracked() {
        if p.extension().is_some_and(|e| e == "rs") && !p.starts_with("crates/womd/src/generated") {
            let n = std::fs::read_to_string(root().join(&p))
                .unwrap()
                .lines()
                .count();
            if n > 600 {
                long.push(format!("{}: {n} lines", p.display()));
            }
        }
    }
    assert!(
        long.is_empty(),
        "Rust files over 600 lines:\n{}",
        long.join("\n")
    );
    for (doc, max) in [
        ("README.md", 300),
        ("BENCHMARKS.md", 400),
        ("docs/findings.md", 400),
    ] {
        let n = std::fs::read_to_string(root().join(doc))
            .unwrap()
            .lines()
            .count();
        assert!(n <= max, "{doc}: {n} lines (at most {max})");
    }
}

/// The system's scratch folder, spelled in pieces so that this file does not name it.
const SCRATCH_DIR: &str = concat!("/", "tm", "p/");

/// Words of a work log: numbered or relative sessions, issue numbers, dates, scratch paths.
fn log_words(line: &str) -> Option<&'static str> {
    let lower = line.to_lowercase();
    let ordinals = [
        "first",
        "second",
        "third",
        "fourth",
        "fifth",
        "sixth",
        "seventh",
        "eighth",
        "ninth",
        "tenth",
        "eleventh",
        "twelfth",
        "twentieth",
        "thirtieth",
        "fortieth",
        "this",
        "last",
        "earlier",
        "previous",
        "same",
    ];
    for w in ["session", "sessions"] {
        for (i, _) in lower.match_indices(w) {
            let before = lower[..i].trim_end();
            let word = before
                .rsplit(|c: char| !c.is_alphanumeric() && c != '-')
                .next()
                .unwrap_or("");
            let last = word.rsplit('-').next().unwrap_or(word);
            let numbered = word.starts_with(|c: char| c.is_ascii_digit())
                && ["th", "st", "nd", "rd"].iter().any(|s| word.ends_with(s));
            if numbered || ordinals.contains(&word) || ordinals.contains(&last) {
                return Some("a work session");
            }
        }
    }
    let bytes = lower.as_bytes();
    for (i, _) in lower.match_indices("issue") {
        let rest = lower[i + 5..].trim_start_matches([' ', '#']);
        if rest.starts_with(|c: char| c.is_ascii_digit()) {
            return Some("an issue number");
        }
    }
    if lower.contains(SCRATCH_DIR) {
        return Some("a scratch path");
    }
    // A date: 20YY-MM-DD.
    for i in 0..bytes.len().saturating_sub(9) {
        let s = &bytes[i..i + 10];
        let digits = |r: std::ops::Range<usize>| r.into_iter().all(|k| s[k].is_ascii_digit());
        if s[0] == b'2'
            && s[1] == b'0'
            && digits(0..4)
            && s[4] == b'-'
            && digits(5..7)
            && s[7] == b'-'
            && digits(8..10)
        {
            return Some("a date");
        }
    }
    None
}

#[test]
fn log_words_are_recognised() {
    // The examples are put together here so that this file reads like none of them.
    let (session, issue) = (concat!("ses", "sion"), concat!("iss", "ue"));
    assert!(log_words(&format!("measured in the thirty-ninth {session}")).is_some());
    assert!(log_words(&format!("as this {session} found")).is_some());
    assert!(log_words(&format!("see {issue} 11")).is_some());
    assert!(log_words(&format!("written to {SCRATCH_DIR}out")).is_some());
    assert!(log_words(&format!("run on {}-11-28", 2000 + 26)).is_some());
    assert!(log_words("a closed-loop Session steps the simulation").is_none());
    assert!(log_words("POST /v1/sessions opens one").is_none());
    assert!(log_words("sessions idle longer than the TTL").is_none());
    assert!(log_words(&format!("the server's sessions and the 12th {session}")).is_some());
    assert!(log_words("the server's sessions").is_none());
}

#[test]
fn nothing_tracked_reads_like_a_work_log() {
    let mut found = Vec::new();
    for p in tracked() {
        let Ok(text) = std::fs::read_to_string(root().join(&p)) else {
            continue; // binary
        };
        if p.extension().is_some_and(|e| e == "lock") {
            continue;
        }
        for (i, line) in text.lines().enumerate() {
            if let Some(what) = log_words(line) {
                found.push(format!(
                    "{}:{}: {what}: {}",
                    p.display(),
                    i + 1,
                    line.trim()
                ));
            }
        }
    }
    assert!(
        found.is_empty(),
        "{} lines read like a work log:\n{}",
        found.len(),
        found.join("\n")
    );
}
