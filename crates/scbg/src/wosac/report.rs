//! What scoring a submission gives (`wosac.json`), and its text table.

use std::collections::BTreeMap;
use std::fmt::Write;

use scbg_metrics::wosac::{DatasetMetrics, FeatureLikelihoods, ScenarioMetrics};
use scbg_womd::WomdError;
use serde::Serialize;

/// One scored scenario: every number of [`ScenarioMetrics`] (flattened into the object in
/// JSON), where it came from and what it cost.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ScoredScenario {
    /// The scenario's WOSAC numbers.
    #[serde(flatten)]
    pub metrics: ScenarioMetrics,
    /// The shard holding its rollouts (`archive:entry` inside a `.tar.gz`).
    pub shard: String,
    /// The scenario file holding its log.
    pub scenario_file: String,
    /// Wall time of its scoring on one thread (decoding the logged scene, the challenge's
    /// checks, the metrics), seconds.
    pub seconds: f64,
}

/// Something left out, and why.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct Skipped {
    /// The file the problem is in: a shard (`archive:entry` inside a `.tar.gz`), an archive or
    /// a scenario file.
    pub file: String,
    /// The scenario, where one is concerned.
    pub scenario_id: Option<String>,
    /// The kind of problem: the key it is counted under in [`WosacScore::skipped`].
    pub reason: String,
    /// The full message (scenario, joint scene, object, field, record, byte offset).
    pub detail: String,
}

impl Skipped {
    /// A scenario file, or one of its records, that cannot be read.
    pub fn unreadable(e: &WomdError) -> Self {
        Self {
            file: e.path().display().to_string(),
            scenario_id: None,
            reason: format!("unreadable scenario file ({})", e.reason()),
            detail: e.to_string(),
        }
    }
}

/// The WOSAC scores of a submission (`scbg eval wosac`'s `wosac.json`, Python's
/// `scbg.score_wosac`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct WosacScore {
    /// The challenge definition scored (`2025`).
    pub challenge: &'static str,
    /// Scenario files given.
    pub scenario_files: usize,
    /// Distinct scenarios read from them.
    pub scenarios_in_files: usize,
    /// Submission files given (shards or archives).
    pub submission_files: usize,
    /// Shards read (the files themselves, and the shards inside archives).
    pub shards: usize,
    /// Scenarios of the scenario files for which the submission has no rollouts (not scored).
    pub not_submitted: usize,
    /// Every scenario scored, in the order of the submission (shard files sorted by path).
    pub per_scenario: Vec<ScoredScenario>,
    /// Every per-scenario number averaged over the scored scenarios with equal weight, the
    /// buckets recomputed from the averaged likelihoods (`null` when none was scored).
    pub aggregate: Option<DatasetMetrics>,
    /// Things left out, counted by reason.
    pub skipped: BTreeMap<String, usize>,
    /// Each thing left out.
    pub skipped_items: Vec<Skipped>,
    /// Wall time of the whole call, seconds.
    pub seconds: f64,
    /// Mean of the scored scenarios' `seconds` (one thread each).
    pub seconds_per_scenario: Option<f64>,
    /// Threads of the pool that scored the scenarios.
    pub threads: usize,
}

/// Skipped items listed by [`WosacScore::to_text`]; `wosac.json` lists each.
const LISTED: usize = 20;

/// Column headers of the table, in [`FeatureLikelihoods::to_array`] order after `meta`.
const LIKELIHOOD_HEADERS: [&str; 10] = [
    "speed", "accel", "ang_sp", "ang_acc", "nearest", "collide", "ttc", "edge", "offroad", "light",
];

fn num(x: f32, decimals: usize) -> String {
    if x.is_finite() {
        format!("{x:.decimals$}")
    } else {
        "n/a".into()
    }
}

/// One table row: the meta-metric, the ten likelihoods, ADE, minADE, the three rates.
fn row(
    label: &str,
    metametric: f32,
    l: &FeatureLikelihoods,
    ade: [f32; 2],
    rates: [f32; 3],
) -> String {
    let mut s = format!("{label:<18} {:>7}", num(metametric, 4));
    for v in l.to_array() {
        let _ = write!(s, " {:>7}", num(v, 4));
    }
    for v in ade {
        let _ = write!(s, " {:>7}", num(v, 3));
    }
    for v in rates {
        let _ = write!(s, " {:>7}", num(v, 3));
    }
    s
}

impl WosacScore {
    /// Scenarios scored.
    pub fn scored(&self) -> usize {
        self.per_scenario.len()
    }

    /// `skipped: N (n × reason; …)`, or `skipped: nothing`.
    pub fn skipped_line(&self) -> String {
        if self.skipped.is_empty() {
            return "skipped: nothing".into();
        }
        format!(
            "skipped: {} ({})",
            self.skipped_items.len(),
            scbg_base::skips::by_reason_text(&self.skipped)
        )
    }

    /// The table `scbg eval wosac` prints: a row per scenario and the mean, the buckets, the
    /// time, and the first skipped items with their messages.
    pub fn to_text(&self) -> String {
        let mut s = format!(
            "WOSAC {} realism of {} scenario(s) from {} shard(s); {} scenario(s) in {} scenario file(s), {} without rollouts\n",
            self.challenge,
            self.scored(),
            self.shards,
            self.scenarios_in_files,
            self.scenario_files,
            self.not_submitted
        );
        let mut header = format!("{:<18} {:>7}", "scenario", "meta");
        for h in LIKELIHOOD_HEADERS
            .iter()
            .chain(&["ADE_m", "minADE_m", "coll", "offroad", "light"])
        {
            let _ = write!(header, " {h:>7}");
        }
        let _ = writeln!(s, "{header} {:>8}", "seconds");
        for p in &self.per_scenario {
            let m = &p.metrics;
            let _ = writeln!(
                s,
                "{} {:>8.3}",
                row(
                    &m.scenario_id,
                    m.metametric,
                    &m.likelihoods,
                    [
                        m.average_displacement_error_m,
                        m.min_average_displacement_error_m
                    ],
                    [
                        m.simulated_collision_rate,
                        m.simulated_offroad_rate,
                        m.simulated_traffic_light_violation_rate
                    ],
                ),
                p.seconds
            );
        }
        if let Some(a) = &self.aggregate {
            let _ = writeln!(
                s,
                "{}",
                row(
                    &format!("mean of {}", a.num_scenarios),
                    a.metametric,
                    &a.likelihoods,
                    [
                        a.average_displacement_error_m,
                        a.min_average_displacement_error_m
                    ],
                    [
                        a.simulated_collision_rate,
                        a.simulated_offroad_rate,
                        a.simulated_traffic_light_violation_rate
                    ],
                )
            );
            let _ = writeln!(
                s,
                "buckets of the mean likelihoods: kinematic {}, interactive {}, map-based {}",
                num(a.buckets.kinematic, 4),
                num(a.buckets.interactive, 4),
                num(a.buckets.map_based, 4)
            );
        }
        let _ = writeln!(
            s,
            "{:.2} s in all on {} thread(s){}",
            self.seconds,
            self.threads,
            self.seconds_per_scenario.map_or(String::new(), |t| format!(
                "; {:.1} ms per scenario (one thread each)",
                t * 1e3
            ))
        );
        let _ = writeln!(s, "{}", self.skipped_line());
        for k in self.skipped_items.iter().take(LISTED) {
            let _ = writeln!(
                s,
                "  {}{}: {}",
                k.file,
                k.scenario_id
                    .as_ref()
                    .map_or(String::new(), |id| format!(" [{id}]")),
                k.detail
            );
        }
        if self.skipped_items.len() > LISTED {
            let _ = writeln!(
                s,
                "  … and {} more (wosac.json lists each)",
                self.skipped_items.len() - LISTED
            );
        }
        s
    }
}
