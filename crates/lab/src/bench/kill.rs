//! `scbg bench kill`: crash safety of the pipeline's stages. Each stage runs once undisturbed
//! (the reference); then, per kill point, the same command is started in a fresh folder,
//! killed with SIGKILL after a seeded random delay within the reference's running time, and
//! run again to completion. A kill point passes when
//! - every file under a final name right after the kill is complete (equal to the reference's
//!   file of that name, or whole by its format: JSON, JSON lines, Parquet, TFRecord, PNG,
//!   burnpack),
//! - the re-run succeeds and leaves exactly the reference's files, each equal to it (JSON
//!   compared without its timings and with the output folder's own path replaced), and
//! - no temporary file is left behind.
//!
//! Stages run as child processes of this executable (`scbg`), on a small synthetic world and a
//! tiny predictor and generator, so that a sweep of every stage takes minutes.

use std::path::{Path, PathBuf};
use std::process::{Command, Stdio};
use std::time::{Duration, Instant};

use anyhow::{Context, bail, ensure};
use rand::{Rng, SeedableRng};
use serde::Serialize;
use serde_json::Value;

/// A stage the sweep kills.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum KillStage {
    /// `scbg data prepare`.
    Prepare,
    /// `scbg train predictor --resume`.
    TrainPredictor,
    /// `scbg label`.
    Label,
    /// `scbg train generator`.
    TrainGenerator,
    /// `scbg sim --out`.
    Sim,
    /// `scbg eval sim`.
    EvalSim,
}

impl KillStage {
    /// Every stage, in pipeline order.
    pub const ALL: [KillStage; 6] = [
        Self::Prepare,
        Self::TrainPredictor,
        Self::Label,
        Self::TrainGenerator,
        Self::Sim,
        Self::EvalSim,
    ];

    /// The stage's name (`prepare`, `train_predictor`, …).
    pub fn name(self) -> &'static str {
        match self {
            Self::Prepare => "prepare",
            Self::TrainPredictor => "train_predictor",
            Self::Label => "label",
            Self::TrainGenerator => "train_generator",
            Self::Sim => "sim",
            Self::EvalSim => "eval_sim",
        }
    }

    /// The stage of a name.
    pub fn parse(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|s| s.name() == name)
    }
}

/// What to sweep.
#[derive(Debug, Clone)]
pub struct KillOptions {
    /// Working folder (created; its previous sweep's folders are replaced).
    pub work: PathBuf,
    /// Kill points per stage.
    pub kills: usize,
    /// Seeds the kill delays (and the synthetic world).
    pub seed: u64,
    /// Stages to kill.
    pub stages: Vec<KillStage>,
    /// Synthetic scenarios of the small world.
    pub scenarios: usize,
}

/// One stage's results.
#[derive(Debug, Clone, Serialize)]
pub struct KillRow {
    /// The stage.
    pub stage: KillStage,
    /// Kill points tried.
    pub kills: usize,
    /// Of them, how many struck while the stage ran (the others found it finished).
    pub struck: usize,
    /// Re-runs whose outputs equal the reference.
    pub equal: usize,
    /// Files under a final name right after a kill that were neither the reference's file
    /// nor complete.
    pub partial_visible: usize,
    /// Temporary files left after a re-run.
    pub temp_left: usize,
    /// Files after a kill that could be checked neither way (a format the sweep does not
    /// know).
    pub unchecked: usize,
    /// The reference run's wall time, s.
    pub reference_s: f64,
    /// What differed, first few.
    pub problems: Vec<String>,
}

/// The sweep's results.
#[derive(Debug, Clone, Serialize)]
pub struct KillReport {
    /// The seed of the kill delays.
    pub seed: u64,
    /// One row per stage.
    pub rows: Vec<KillRow>,
}

impl KillReport {
    /// Whether every kill point passed.
    pub fn all_passed(&self) -> bool {
        self.rows
            .iter()
            .all(|r| r.equal == r.kills && r.partial_visible == 0 && r.temp_left == 0)
    }

    /// The table the command prints.
    pub fn to_text(&self) -> String {
        let mut s = format!(
            "kill -9 sweep, seed {}\nstage            kills  struck  equal  partial  temp  unchecked  reference\n",
            self.seed
        );
        for r in &self.rows {
            s += &format!(
                "{:<16} {:>5}  {:>6}  {:>5}  {:>7}  {:>4}  {:>9}  {:>8.1} s\n",
                r.stage.name(),
                r.kills,
                r.struck,
                r.equal,
                r.partial_visible,
                r.temp_left,
                r.unchecked,
                r.reference_s
            );
            for p in &r.problems {
                s += &format!("  {p}\n");
            }
        }
        s
    }
}

/// The tiny predictor every stage after `prepare` builds on (trains in seconds).
const TINY_PREDICTOR: &str = include_str!("../../tests/tiny_train.toml");
/// Few sampled futures, a short generator training and few closed-loop rollouts.
const TINY_SETTINGS: &str = "[labels]\nsamples = 2\n\
    [generator]\nepochs = 2\nbatch_size = 8\nrange_steps = 20\n\
    [closed_loop]\nrollouts = 16\n";

/// Runs the sweep.
pub fn kill_sweep(exe: &Path, options: &KillOptions) -> anyhow::Result<KillReport> {
    ensure!(options.kills > 0, "give at least one kill point per stage");
    let work = &options.work;
    std::fs::create_dir_all(work).with_context(|| format!("creating {}", work.display()))?;
    let base = work.join("base");
    if base.exists() {
        std::fs::remove_dir_all(&base).with_context(|| format!("clearing {}", base.display()))?;
    }
    std::fs::create_dir_all(&base)?;
    let path = |name: &str| base.join(name).display().to_string();
    std::fs::write(base.join("predictor.toml"), TINY_PREDICTOR)?;
    std::fs::write(base.join("settings.toml"), TINY_SETTINGS)?;
    run_to_end(
        exe,
        &[
            "synth",
            "--scenarios",
            &options.scenarios.to_string(),
            "--seed",
            &options.seed.to_string(),
            "--scenarios-per-file",
            "4",
            "--out",
            &path("synth"),
        ],
    )?;
    let truth = std::fs::read_to_string(base.join("synth/ground_truth.jsonl"))?;
    let first: Value = serde_json::from_str(truth.lines().next().context("no ground truth")?)?;
    let (a, b) = (first["a_id"].to_string(), first["b_id"].to_string());

    // Each stage's command, given its output folder; the references are made in order, so
    // each stage finds its inputs in `base`.
    let command = |stage: KillStage, out: &str| -> Vec<String> {
        let (synth, truth, cache) = (
            path("synth"),
            path("synth/ground_truth.jsonl"),
            path("prepare"),
        );
        let (predictor, generator) = (path("train_predictor"), path("train_generator"));
        let (tiny, settings) = (path("predictor.toml"), path("settings.toml"));
        let scenario = path("synth/synth-00000.tfrecord");
        let args: Vec<&str> = match stage {
            KillStage::Prepare => vec![
                "data",
                "prepare",
                "--files-per-shard",
                "1",
                "--input",
                &synth,
            ],
            KillStage::TrainPredictor => vec![
                "train",
                "predictor",
                "--resume",
                "--config",
                &tiny,
                "--data",
                &cache,
            ],
            KillStage::Label => vec![
                "label",
                "--model",
                &predictor,
                "--data",
                &cache,
                "--config",
                &settings,
                "--ground-truth",
                &truth,
            ],
            KillStage::TrainGenerator => vec![
                "train",
                "generator",
                "--predictor",
                &predictor,
                "--data",
                &cache,
                "--config",
                &settings,
            ],
            KillStage::Sim => vec![
                "sim",
                "--model",
                &generator,
                "--scenario",
                &scenario,
                "--a",
                &a,
                "--b",
                &b,
                "--config",
                &settings,
            ],
            KillStage::EvalSim => vec![
                "eval",
                "sim",
                "--model",
                &generator,
                "--data",
                &synth,
                "--ground-truth",
                &truth,
                "--split",
                "all",
                "--scenes",
                "3",
                "--wosac-scenes",
                "1",
            ],
        };
        args.into_iter()
            .chain(["--out", out])
            .map(String::from)
            .collect()
    };

    let mut rng = rand_pcg::Pcg64Mcg::seed_from_u64(scbg_base::seed::mix(options.seed, 0x6b11));
    let mut rows = Vec::new();
    // Every stage the chosen ones build on gets its reference; only the chosen are killed.
    let last = options
        .stages
        .iter()
        .map(|s| *s as usize)
        .max()
        .unwrap_or(0);
    for stage in KillStage::ALL.into_iter().take(last + 1) {
        let reference = base.join(stage.name());
        let started = Instant::now();
        run_to_end(
            exe,
            &strings(&command(stage, &reference.display().to_string())),
        )?;
        let reference_s = started.elapsed().as_secs_f64();
        if !options.stages.contains(&stage) {
            continue;
        }
        let mut row = KillRow {
            stage,
            kills: options.kills,
            struck: 0,
            equal: 0,
            partial_visible: 0,
            temp_left: 0,
            unchecked: 0,
            reference_s,
            problems: Vec::new(),
        };
        let runs = work.join(stage.name());
        if runs.exists() {
            std::fs::remove_dir_all(&runs)?;
        }
        for k in 0..options.kills {
            let out = runs.join(format!("kill-{k:03}"));
            let args = command(stage, &out.display().to_string());
            let delay = Duration::from_secs_f64(rng.random_range(0.0..0.95) * reference_s);
            if run_and_kill(exe, &strings(&args), delay)? {
                row.struck += 1;
            }
            let after_kill = files_of(&out);
            for name in after_kill.iter().filter(|n| !is_temp(n)) {
                match complete(&out.join(name), &reference.join(name), &out, &reference) {
                    Check::Complete => {}
                    Check::Unchecked => row.unchecked += 1,
                    Check::Partial(why) => {
                        row.partial_visible += 1;
                        note(
                            &mut row.problems,
                            format!("kill {k}: {name} after the kill: {why}"),
                        );
                    }
                }
            }
            run_to_end(exe, &strings(&args))
                .with_context(|| format!("{} re-run after kill {k}", stage.name()))?;
            let temps = files_of(&out).into_iter().filter(|n| is_temp(n)).count();
            row.temp_left += temps;
            match same_outputs(&out, &reference) {
                Ok(()) if temps == 0 => row.equal += 1,
                Ok(()) => note(
                    &mut row.problems,
                    format!("kill {k}: {temps} temporary file(s) left"),
                ),
                Err(why) => note(&mut row.problems, format!("kill {k}: {why}")),
            }
        }
        rows.push(row);
    }
    Ok(KillReport {
        seed: options.seed,
        rows,
    })
}

fn strings(args: &[String]) -> Vec<&str> {
    args.iter().map(String::as_str).collect()
}

/// Keeps the first few problems of a stage.
fn note(problems: &mut Vec<String>, problem: String) {
    if problems.len() < 5 {
        problems.push(problem);
    }
}

fn child(exe: &Path, args: &[&str]) -> Command {
    let mut cmd = Command::new(exe);
    cmd.args(args)
        .env("SCBG_LOG", "error")
        .stdin(Stdio::null())
        .stdout(Stdio::null());
    cmd
}

/// Runs `exe args` to completion; an error carries its stderr.
fn run_to_end(exe: &Path, args: &[&str]) -> anyhow::Result<()> {
    let out = child(exe, args)
        .stderr(Stdio::piped())
        .output()
        .with_context(|| format!("running {}", exe.display()))?;
    if !out.status.success() {
        bail!(
            "scbg {} failed: {}",
            args.join(" "),
            String::from_utf8_lossy(&out.stderr).trim()
        );
    }
    Ok(())
}

/// Starts `exe args`, kills it with SIGKILL after `delay`; whether it was still running.
fn run_and_kill(exe: &Path, args: &[&str], delay: Duration) -> anyhow::Result<bool> {
    let mut running = child(exe, args)
        .stderr(Stdio::null())
        .spawn()
        .with_context(|| format!("starting {}", exe.display()))?;
    let until = Instant::now() + delay;
    loop {
        if running.try_wait()?.is_some() {
            return Ok(false);
        }
        let now = Instant::now();
        if now >= until {
            break;
        }
        std::thread::sleep((until - now).min(Duration::from_millis(5)));
    }
    // `Child::kill` is SIGKILL on Unix: no handler, no destructor runs.
    running.kill()?;
    running.wait()?;
    Ok(true)
}

/// Names of the regular files under `dir`, relative to it, sorted.
fn files_of(dir: &Path) -> Vec<String> {
    fn walk(root: &Path, dir: &Path, out: &mut Vec<String>) {
        let Ok(entries) = std::fs::read_dir(dir) else {
            return;
        };
        for entry in entries.flatten() {
            let path = entry.path();
            if path.is_dir() {
                walk(root, &path, out);
            } else if let Ok(rel) = path.strip_prefix(root) {
                out.push(rel.display().to_string());
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, &mut out);
    out.sort();
    out
}

/// Whether a file name (its last component) is an atomic writer's temporary name.
fn is_temp(name: &str) -> bool {
    let last = name.rsplit('/').next().unwrap_or(name);
    last.starts_with(".tmp") && last.ends_with(".tmp")
}

enum Check {
    Complete,
    Partial(String),
    Unchecked,
}

/// Whether `file` (under the output folder `out`) is complete: equal to the reference's file
/// of that name, or whole by its format.
fn complete(file: &Path, reference: &Path, out: &Path, reference_dir: &Path) -> Check {
    if reference.is_file() && same_file(file, reference, out, reference_dir).is_ok() {
        return Check::Complete;
    }
    let Ok(bytes) = std::fs::read(file) else {
        return Check::Partial("unreadable".into());
    };
    let ext = file.extension().and_then(|e| e.to_str()).unwrap_or("");
    let whole = match ext {
        "json" => serde_json::from_slice::<Value>(&bytes).is_ok(),
        "jsonl" => {
            bytes.ends_with(b"\n")
                && bytes
                    .split(|b| *b == b'\n')
                    .filter(|l| !l.is_empty())
                    .all(|l| serde_json::from_slice::<Value>(l).is_ok())
        }
        "parquet" => bytes.len() >= 12 && bytes.starts_with(b"PAR1") && bytes.ends_with(b"PAR1"),
        "png" => bytes.ends_with(&[0x49, 0x45, 0x4e, 0x44, 0xae, 0x42, 0x60, 0x82]),
        "tfrecord" => scbg_womd::WomdFile::from_bytes("kill", bytes)
            .map(|f| f.scenes().all(|s| s.is_ok()))
            .unwrap_or(false),
        "bpk" => whole_burnpack(bytes),
        _ => return Check::Unchecked,
    };
    if whole {
        Check::Complete
    } else {
        Check::Partial(format!("an incomplete .{ext} file"))
    }
}

/// Whether `bytes` are a whole burnpack container: its header, metadata and every tensor's
/// data within the file.
fn whole_burnpack(bytes: Vec<u8>) -> bool {
    let Ok(reader) = burn_pack::Reader::from_bytes(burn_pack::Bytes::from_bytes_vec(bytes)) else {
        return false;
    };
    reader
        .into_tensors()
        .is_ok_and(|tensors| tensors.iter().all(|t| t.to_bytes().is_ok()))
}

/// `out` holds exactly `reference`'s files, each equal to it.
fn same_outputs(out: &Path, reference: &Path) -> Result<(), String> {
    let (have, want) = (files_of(out), files_of(reference));
    if have != want {
        let extra: Vec<&String> = have.iter().filter(|n| !want.contains(n)).collect();
        let missing: Vec<&String> = want.iter().filter(|n| !have.contains(n)).collect();
        return Err(format!(
            "files differ: extra {extra:?}, missing {missing:?}"
        ));
    }
    for name in &want {
        same_file(&out.join(name), &reference.join(name), out, reference)
            .map_err(|why| format!("{name}: {why}"))?;
    }
    Ok(())
}

/// Byte-equal files, or JSON equal without timings and with each folder's own path replaced.
fn same_file(a: &Path, b: &Path, a_dir: &Path, b_dir: &Path) -> Result<(), String> {
    let (x, y) = match (std::fs::read(a), std::fs::read(b)) {
        (Ok(x), Ok(y)) => (x, y),
        _ => return Err("unreadable".into()),
    };
    if x == y {
        return Ok(());
    }
    let json = |bytes: &[u8], dir: &Path| -> Option<Value> {
        let text = String::from_utf8_lossy(bytes).replace(&dir.display().to_string(), "<out>");
        let mut v: Value = serde_json::from_str(&text).ok()?;
        drop_timings(&mut v);
        Some(v)
    };
    match (json(&x, a_dir), json(&y, b_dir)) {
        (Some(p), Some(q)) if p == q => Ok(()),
        (Some(_), Some(_)) => Err("JSON differs beyond timings".into()),
        _ => Err(format!(
            "{} bytes differ from the reference's {}",
            x.len(),
            y.len()
        )),
    }
}

/// Removes wall-clock measurements (`seconds`, `*_seconds`, `*_ms`, `elapsed*`) everywhere.
fn drop_timings(v: &mut Value) {
    match v {
        Value::Object(map) => {
            map.retain(|k, _| {
                !(k == "seconds"
                    || k.ends_with("_seconds")
                    || k.ends_with("_ms")
                    || k.starts_with("elapsed"))
            });
            map.values_mut().for_each(drop_timings);
        }
        Value::Array(items) => items.iter_mut().for_each(drop_timings),
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_parse_and_timings_are_ignored() {
        for s in KillStage::ALL {
            assert_eq!(KillStage::parse(s.name()), Some(s));
        }
        assert!(is_temp(".tmpAbC.tmp") && is_temp("sub/.tmpx.tmp") && !is_temp("a.tmp"));
        let mut v = serde_json::json!({"a": 1, "seconds": 2.0, "b": [{"load_ms": 3, "c": 4}]});
        drop_timings(&mut v);
        assert_eq!(v, serde_json::json!({"a": 1, "b": [{"c": 4}]}));
    }

    #[test]
    fn incomplete_files_are_told_from_whole_ones() {
        let dir = tempfile::tempdir().unwrap();
        let none = dir.path().join("none");
        let check = |name: &str, bytes: &[u8]| {
            let p = dir.path().join(name);
            std::fs::write(&p, bytes).unwrap();
            match complete(&p, &none, dir.path(), dir.path()) {
                Check::Complete => "complete",
                Check::Partial(_) => "partial",
                Check::Unchecked => "unchecked",
            }
        };
        assert_eq!(check("a.json", b"{\"a\": [1, 2]}"), "complete");
        assert_eq!(check("b.json", b"{\"a\": [1, "), "partial");
        assert_eq!(check("c.jsonl", b"{}\n{}\n"), "complete");
        assert_eq!(check("d.jsonl", b"{}\n{"), "partial");
        assert_eq!(check("e.parquet", b"PAR1....PAR"), "partial");
        assert_eq!(check("f.tfrecord", &[1, 2, 3]), "partial");
        assert_eq!(check("g.bpk", &[1, 2, 3]), "partial");
        assert_eq!(check("h.bin", &[1, 2, 3]), "unchecked");
    }
}
