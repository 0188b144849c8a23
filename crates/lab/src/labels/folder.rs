//! The record of a label folder's options ([`LABEL_OPTIONS_FILE`]): what a run resuming into
//! the folder must ask for.

use anyhow::Context;
use scbg_courtesy::label::LabelOptions;

use super::{LabelRun, shard_table_name};
use crate::ensure_request;

/// The file in a label folder naming what its tables were labelled with (the options, the
/// seed and the ensemble's size): a run resuming into the folder must ask for the same, or
/// the tables would mix layouts (the options decide which futures each table holds).
pub const LABEL_OPTIONS_FILE: &str = "label_options.json";

/// What [`LABEL_OPTIONS_FILE`] holds: one flat object of the options' fields, `seed` and
/// `predictors`.
#[derive(Debug, serde::Serialize, serde::Deserialize)]
struct LabelRecord {
    #[serde(flatten)]
    options: LabelOptions,
    seed: u64,
    predictors: usize,
}

/// Checks `run` against its folder's [`LABEL_OPTIONS_FILE`] (or writes it there before any
/// of its `shards` tables): a folder labelled with other options, or holding tables without
/// the file, is refused with what differs, and nothing in it is touched. The file is one flat
/// object: the options' fields, `seed` and `predictors`.
pub(super) fn claim_label_folder(
    run: &LabelRun,
    predictors: usize,
    shards: usize,
) -> anyhow::Result<()> {
    let path = run.out.join(LABEL_OPTIONS_FILE);
    let mine = serde_json::to_value(LabelRecord {
        options: run.options,
        seed: run.seed,
        predictors,
    })?;
    if !path.is_file() {
        ensure_request!(
            !(0..shards).any(|si| run.out.join(shard_table_name(si)).is_file()),
            "{} holds label tables but no {LABEL_OPTIONS_FILE} (labelled by a version that did not record its options, whose layout may differ): label into another folder, or delete its tables to relabel",
            run.out.display()
        );
        scbg_base::atomic::write_json(&path, &mine)
            .with_context(|| format!("writing {}", path.display()))?;
        return Ok(());
    }
    let text =
        std::fs::read_to_string(&path).with_context(|| format!("reading {}", path.display()))?;
    // Read through the options, so a field added since takes the value the earlier run had
    // (its serde default), and re-written like mine.
    let raw: serde_json::Value = serde_json::from_str(&text)
        .with_context(|| format!("{}: not the JSON a label run writes", path.display()))?;
    let record: LabelRecord = serde_json::from_value(raw.clone())
        .with_context(|| format!("{}: not the JSON a label run writes", path.display()))?;
    let mut theirs = serde_json::to_value(record)?;
    // A field this build does not know (a newer run's) is a difference too.
    if let (Some(t), Some(r)) = (theirs.as_object_mut(), raw.as_object()) {
        for (k, v) in r {
            t.entry(k.clone()).or_insert_with(|| v.clone());
        }
    }
    let (empty, field) = (serde_json::Map::new(), |v: Option<&serde_json::Value>| {
        v.map_or("-".to_string(), ToString::to_string)
    });
    let (a, b) = (
        mine.as_object().unwrap_or(&empty),
        theirs.as_object().unwrap_or(&empty),
    );
    let keys: std::collections::BTreeSet<&String> = a.keys().chain(b.keys()).collect();
    let differ: Vec<String> = keys
        .into_iter()
        .filter(|k| a.get(*k) != b.get(*k))
        .map(|k| format!("{k}: {} there, {} asked", field(b.get(k)), field(a.get(k))))
        .collect();
    ensure_request!(
        differ.is_empty(),
        "{} was labelled with other options ({}): label into another folder, or delete it to relabel",
        run.out.display(),
        differ.join("; ")
    );
    Ok(())
}
