//! Turning user-given paths and glob patterns into a sorted list of input files.

use std::path::PathBuf;

use anyhow::Context;

use crate::ensure_request;

/// Expands each argument: an existing file is taken as is, a folder gives every file in it
/// (sorted, hidden files and `*.json`/`*.md` side files left out), anything else is a glob
/// pattern. The result is sorted and free of duplicates. No match at all is an error.
pub fn expand(args: &[String]) -> anyhow::Result<Vec<PathBuf>> {
    let mut out = Vec::new();
    for arg in args {
        let p = PathBuf::from(arg);
        if p.is_file() {
            out.push(p);
        } else if p.is_dir() {
            for entry in
                std::fs::read_dir(&p).with_context(|| format!("listing {}", p.display()))?
            {
                let path = entry?.path();
                let name = path.file_name().and_then(|n| n.to_str()).unwrap_or("");
                let side_file = name.starts_with('.')
                    || name.ends_with(".json")
                    || name.ends_with(".md")
                    || name.ends_with(".jsonl");
                if path.is_file() && !side_file {
                    out.push(path);
                }
            }
        } else {
            let matches: Vec<PathBuf> = glob::glob(arg)
                .with_context(|| format!("bad glob pattern {arg:?}"))?
                .filter_map(Result::ok)
                .filter(|p| p.is_file())
                .collect();
            ensure_request!(!matches.is_empty(), "no file matches {arg:?}");
            out.extend(matches);
        }
    }
    out.sort();
    out.dedup();
    ensure_request!(!out.is_empty(), "no input files in {args:?}");
    Ok(out)
}
