//! The label table: one row per labelled future of B ([`LabelRow`]), stored as Parquet (one
//! file per cache shard), written atomically and read back by column name.

mod bounds;

use std::path::Path;
use std::sync::Arc;

use anyhow::Context;
use arrow_array::{ArrayRef, Float32Array, Int64Array, RecordBatch, StringArray, UInt32Array};
use arrow_schema::{DataType, Field, Schema};

/// One labelled future of B for target A.
///
/// The label table (one Parquet file per cache shard) has one row per future:
/// `scenario_id, window_step, a_id, b_id, sample, psi, e_marg, e_cond, psi_true,
/// audience_size` (`psi_true` nullable: only synthetic scenes' ground-truth roles have it;
/// tables written before `audience_size` existed read back with 1).
#[derive(Debug, Clone, PartialEq)]
pub struct LabelRow {
    /// The scenario.
    pub scenario_id: String,
    /// The window's current step.
    pub window_step: u32,
    /// Track id of A (whose expected reward counts).
    pub a_id: i64,
    /// Track id of B (whose future is labelled).
    pub b_id: i64,
    /// 0 = logged future, 1.. = sampled from B's marginal prediction.
    pub sample: u32,
    /// ψ = e_cond − e_marg (m/s for the average-speed reward).
    pub psi: f32,
    /// E[r(Y_A) | x] as estimated.
    pub e_marg: f32,
    /// E[r(Y_A) | x, y_B] for this future.
    pub e_cond: f32,
    /// ψ_true of this future from the synthetic simulator's oracle (m/s), when known.
    pub psi_true: Option<f32>,
    /// Agents whose reward ψ counts: 1 (A) for the paper's pair, A and B's neighbours for
    /// the `neighbours` audience.
    pub audience_size: u32,
}

fn schema() -> Arc<Schema> {
    Arc::new(Schema::new(vec![
        Field::new("scenario_id", DataType::Utf8, false),
        Field::new("window_step", DataType::UInt32, false),
        Field::new("a_id", DataType::Int64, false),
        Field::new("b_id", DataType::Int64, false),
        Field::new("sample", DataType::UInt32, false),
        Field::new("psi", DataType::Float32, false),
        Field::new("e_marg", DataType::Float32, false),
        Field::new("e_cond", DataType::Float32, false),
        Field::new("psi_true", DataType::Float32, true),
        Field::new("audience_size", DataType::UInt32, false),
    ]))
}

/// Writes the label table as Parquet, atomically.
pub fn write_label_table(path: &Path, rows: &[LabelRow]) -> anyhow::Result<()> {
    let schema = schema();
    let columns: Vec<ArrayRef> = vec![
        Arc::new(StringArray::from(
            rows.iter()
                .map(|r| r.scenario_id.as_str())
                .collect::<Vec<_>>(),
        )),
        Arc::new(UInt32Array::from(
            rows.iter().map(|r| r.window_step).collect::<Vec<_>>(),
        )),
        Arc::new(Int64Array::from(
            rows.iter().map(|r| r.a_id).collect::<Vec<_>>(),
        )),
        Arc::new(Int64Array::from(
            rows.iter().map(|r| r.b_id).collect::<Vec<_>>(),
        )),
        Arc::new(UInt32Array::from(
            rows.iter().map(|r| r.sample).collect::<Vec<_>>(),
        )),
        Arc::new(Float32Array::from(
            rows.iter().map(|r| r.psi).collect::<Vec<_>>(),
        )),
        Arc::new(Float32Array::from(
            rows.iter().map(|r| r.e_marg).collect::<Vec<_>>(),
        )),
        Arc::new(Float32Array::from(
            rows.iter().map(|r| r.e_cond).collect::<Vec<_>>(),
        )),
        Arc::new(Float32Array::from(
            rows.iter().map(|r| r.psi_true).collect::<Vec<_>>(),
        )),
        Arc::new(UInt32Array::from(
            rows.iter().map(|r| r.audience_size).collect::<Vec<_>>(),
        )),
    ];
    let batch = RecordBatch::try_new(schema.clone(), columns)?;
    scbg_base::atomic::write_with(path, |file| -> anyhow::Result<()> {
        let mut writer = parquet::arrow::ArrowWriter::try_new(file, schema, None)?;
        writer.write(&batch)?;
        writer.close()?;
        Ok(())
    })?;
    Ok(())
}

/// Column `name` of a label-table batch as its Arrow array type (a cheap, shared copy); a
/// missing column or one of another type is an error naming the file and column.
fn column<T: arrow_array::Array + Clone + 'static>(
    batch: &RecordBatch,
    name: &str,
    path: &Path,
) -> anyhow::Result<T> {
    batch
        .column_by_name(name)
        .with_context(|| format!("{}: no column {name}", path.display()))?
        .as_any()
        .downcast_ref::<T>()
        .cloned()
        .with_context(|| format!("{}: column {name} has the wrong type", path.display()))
}

/// Reads a label table back (resumed shards, summaries, tests); a missing column or a column
/// of the wrong type is an error naming the file and column.
pub fn read_label_table(path: &Path) -> anyhow::Result<Vec<LabelRow>> {
    let bytes = std::fs::read(path).with_context(|| format!("reading {}", path.display()))?;
    label_table_from_bytes(bytes, path)
}

/// [`read_label_table`] of a file's bytes; `path` names it in errors.
///
/// The Parquet and Arrow readers assert on some malformed files (fuzzing found two: a negative
/// column-chunk offset, which is checked first, and bit-buffer bounds deep in the decoding). A
/// panic there means a bad file, so it is turned into an error naming the file. Footers and
/// page headers that would hold the readers for seconds or gigabytes are refused before they
/// read them (`bounds`), as are tables claiming more rows than bytes.
pub fn label_table_from_bytes(bytes: Vec<u8>, path: &Path) -> anyhow::Result<Vec<LabelRow>> {
    std::panic::catch_unwind(|| decode_label_table(bytes, path)).unwrap_or_else(|panic| {
        let why = panic
            .downcast_ref::<&str>()
            .map(|s| s.to_string())
            .or_else(|| panic.downcast_ref::<String>().cloned())
            .unwrap_or_default();
        anyhow::bail!("{}: not a readable label table ({why})", path.display())
    })
}

fn decode_label_table(bytes: Vec<u8>, path: &Path) -> anyhow::Result<Vec<LabelRow>> {
    let named = |e: parquet::errors::ParquetError| anyhow::anyhow!("{}: {e}", path.display());
    let size = bytes.len() as u64;
    bounds::check_footer(&bytes).map_err(|why| anyhow::anyhow!("{}: {why}", path.display()))?;
    let bytes = bytes::Bytes::from(bytes);
    let builder =
        parquet::arrow::arrow_reader::ParquetRecordBatchReaderBuilder::try_new(bytes.clone())
            .map_err(named)?;
    // Run-length encoding lets a few bytes claim millions of rows; a label table's three
    // float columns alone take 12 bytes a row, so more rows than bytes is a malformed file.
    let rows_claimed: i64 = builder
        .metadata()
        .row_groups()
        .iter()
        .map(|g| g.num_rows().max(0))
        .fold(0, i64::saturating_add);
    anyhow::ensure!(
        u64::try_from(rows_claimed).is_ok_and(|n| n <= size),
        "{}: claims {rows_claimed} rows in a {size}-byte file",
        path.display()
    );
    // The reader asserts (panics) on a column chunk with a negative offset or size: check
    // every chunk lies inside the file first, and that its pages claim sizes Snappy can reach.
    for (g, group) in builder.metadata().row_groups().iter().enumerate() {
        for (c, chunk) in group.columns().iter().enumerate() {
            let start = chunk
                .dictionary_page_offset()
                .unwrap_or_else(|| chunk.data_page_offset());
            let len = chunk.compressed_size();
            let inside = u64::try_from(start)
                .ok()
                .zip(u64::try_from(len).ok())
                .and_then(|(s, l)| s.checked_add(l))
                .is_some_and(|end| end <= size);
            anyhow::ensure!(
                inside,
                "{}: row group {g}, column {c}: byte range {start} + {len} is outside the {size}-byte file",
                path.display()
            );
            let chunk = &bytes[start as usize..(start + len) as usize];
            bounds::check_pages(chunk).map_err(|why| {
                anyhow::anyhow!("{}: row group {g}, column {c}: {why}", path.display())
            })?;
        }
    }
    let reader = builder.build().map_err(named)?;
    let mut rows = Vec::new();
    for batch in reader {
        let b = batch.with_context(|| format!("reading {}", path.display()))?;
        let ids: StringArray = column(&b, "scenario_id", path)?;
        let ws: UInt32Array = column(&b, "window_step", path)?;
        let a: Int64Array = column(&b, "a_id", path)?;
        let bb: Int64Array = column(&b, "b_id", path)?;
        let s: UInt32Array = column(&b, "sample", path)?;
        let psi: Float32Array = column(&b, "psi", path)?;
        let em: Float32Array = column(&b, "e_marg", path)?;
        let ec: Float32Array = column(&b, "e_cond", path)?;
        // Optional: tables written before the oracle existed have no psi_true.
        let pt: Option<Float32Array> = match b.column_by_name("psi_true") {
            None => None,
            Some(_) => Some(column(&b, "psi_true", path)?),
        };
        // Optional: tables written before audiences existed are toward A alone.
        let size: Option<UInt32Array> = match b.column_by_name("audience_size") {
            None => None,
            Some(_) => Some(column(&b, "audience_size", path)?),
        };
        for i in 0..b.num_rows() {
            rows.push(LabelRow {
                scenario_id: ids.value(i).to_string(),
                window_step: ws.value(i),
                a_id: a.value(i),
                b_id: bb.value(i),
                sample: s.value(i),
                psi: psi.value(i),
                e_marg: em.value(i),
                e_cond: ec.value(i),
                psi_true: pt
                    .as_ref()
                    .and_then(|c| arrow_array::Array::is_valid(c, i).then(|| c.value(i))),
                audience_size: size.as_ref().map_or(1, |c| c.value(i)),
            });
        }
    }
    Ok(rows)
}
