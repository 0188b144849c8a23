//! The logged scenarios of the scenario files, by id: each record decoded once to learn its
//! id, kept as its bytes in the memory-mapped file, and decoded again when it is scored.

use std::collections::HashMap;
use std::path::{Path, PathBuf};

use rayon::prelude::*;
use scbg_scene::Scene;
use scbg_womd::{Format, WomdError, WomdFile};

use super::Skipped;

/// Why a scenario is left out when an earlier scenario file (or record) has the same id.
pub const REPEATED_IN_SCENARIO_FILES: &str = "repeated in the scenario files (the first counts)";

/// Opens every file (memory-mapped); a file that cannot be opened is listed in `skipped`.
pub fn open_files(paths: &[PathBuf], skipped: &mut Vec<Skipped>) -> Vec<WomdFile> {
    paths
        .iter()
        .filter_map(|p| match WomdFile::open(p) {
            Ok(f) => Some(f),
            Err(e) => {
                skipped.push(Skipped::unreadable(&e));
                None
            }
        })
        .collect()
}

/// Where one logged scenario is.
#[derive(Debug, Clone, Copy)]
pub struct Entry<'f> {
    file: &'f WomdFile,
    format: Format,
    record: usize,
    offset: u64,
    data: &'f [u8],
}

impl Entry<'_> {
    /// The file holding the scenario.
    pub fn path(&self) -> &Path {
        self.file.path()
    }

    /// The scenario, decoded.
    pub fn decode(&self) -> Result<Scene, WomdError> {
        scbg_womd::decode_record(self.data, self.format).map_err(|error| WomdError::Decode {
            path: self.file.path().to_path_buf(),
            index: self.record,
            offset: self.offset,
            error,
        })
    }
}

/// The scenarios of a set of files, by scenario id (the first file and record win).
#[derive(Debug)]
pub struct ScenarioIndex<'f> {
    by_id: HashMap<String, Entry<'f>>,
    num_files: usize,
}

impl<'f> ScenarioIndex<'f> {
    /// Decodes every record of `files` (files and records in parallel) and indexes it by
    /// scenario id; unreadable files and records, and ids seen before, go to `skipped`.
    pub fn build(
        files: &'f [WomdFile],
        skipped: &mut Vec<Skipped>,
        progress: &dyn crate::Progress,
    ) -> Self {
        let bar = progress.bar("indexing scenario files", files.len() as u64);
        let per_file: Vec<Vec<Result<(String, Entry<'f>), Skipped>>> = files
            .par_iter()
            .map(|file| {
                let entries = index_file(file);
                bar.inc(1);
                entries
            })
            .collect();
        drop(bar);
        let mut by_id = HashMap::new();
        for item in per_file.into_iter().flatten() {
            match item {
                Ok((id, entry)) => {
                    if let Some(first) = by_id.get(&id) {
                        let first: &Entry<'_> = first;
                        skipped.push(Skipped {
                            file: entry.path().display().to_string(),
                            scenario_id: Some(id.clone()),
                            reason: REPEATED_IN_SCENARIO_FILES.into(),
                            detail: format!(
                                "scenario {id}: record {} of {} repeats record {} of {}",
                                entry.record,
                                entry.path().display(),
                                first.record,
                                first.path().display()
                            ),
                        });
                    } else {
                        by_id.insert(id, entry);
                    }
                }
                Err(s) => skipped.push(s),
            }
        }
        Self {
            by_id,
            num_files: files.len(),
        }
    }

    /// The scenario with this id.
    pub fn get(&self, scenario_id: &str) -> Option<&Entry<'f>> {
        self.by_id.get(scenario_id)
    }

    /// Scenarios indexed.
    pub fn len(&self) -> usize {
        self.by_id.len()
    }

    /// Every scenario id indexed, in no particular order.
    pub fn ids(&self) -> impl Iterator<Item = &String> {
        self.by_id.keys()
    }

    /// Files read (the ones that could be opened).
    pub fn num_files(&self) -> usize {
        self.num_files
    }
}

/// Every record of one file, in file order, as its id and entry or why it cannot be read.
fn index_file(file: &WomdFile) -> Vec<Result<(String, Entry<'_>), Skipped>> {
    let format = match file.detect_format() {
        Ok(f) => f,
        Err(e) => return vec![Err(Skipped::unreadable(&e))],
    };
    let mut records = Vec::new();
    let mut out = Vec::new();
    for record in file.records() {
        match record {
            Ok(r) => records.push(r),
            Err(e) => out.push(Err(Skipped::unreadable(&e))),
        }
    }
    let mut entries: Vec<Result<(String, Entry<'_>), Skipped>> = records
        .par_iter()
        .map(|r| {
            let entry = Entry {
                file,
                format,
                record: r.index,
                offset: r.offset,
                data: r.data,
            };
            entry
                .decode()
                .map(|scene| (scene.scenario_id, entry))
                .map_err(|e| Skipped::unreadable(&e))
        })
        .collect();
    // The records that decode or not, in file order, then those whose framing is bad.
    entries.append(&mut out);
    entries
}
