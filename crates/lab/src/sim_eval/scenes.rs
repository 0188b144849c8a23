//! The scenes `eval sim` drives: every scene cut into the windows `data prepare` cuts, each
//! window with its A and B — the pair the log names, else the pair `data prepare` finds — and
//! every scene left out with why.

use std::collections::BTreeMap;

use scbg_features::{PairConfig, PreparedScene, WindowConfig, window_scene, windows};
use scbg_scene::Scene;
use scbg_synth::GroundTruth;
use serde::Serialize;

/// How a simulated scene's A and B were chosen.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize)]
#[serde(rename_all = "snake_case")]
pub enum PairOrigin {
    /// The log names them: A the SDC, B the first other object of interest, both valid at the
    /// current step.
    Named,
    /// `data prepare`'s pair rule: the objects of interest when they are exactly two valid
    /// vehicles ([`scbg_features::select_pairs`]).
    Labelled,
    /// `data prepare`'s pair rule: the mined vehicle pair of closest approach.
    Mined,
}

/// A scene (or a window of one) that is not simulated, and why.
#[derive(Debug, Clone, PartialEq, Eq, Serialize)]
pub struct SkippedScene {
    /// The scene (`<scenario id>@<step>` for a window cut from a longer scene), or the file
    /// and record when the record could not be read.
    pub scenario_id: String,
    /// Why: the key it is counted under in `skipped`.
    pub reason: String,
    /// The full message, where it says more than the reason.
    #[serde(skip_serializing_if = "Option::is_none")]
    pub detail: Option<String>,
}

/// Why a scene shorter than one window is left out.
pub const TOO_SHORT: &str = "shorter than one window (11 history + 80 future steps)";
/// Why a scene without a pair in any of its windows is left out.
pub const NO_PAIR: &str = "no interacting vehicle pair (none named by the log, none mined)";

/// One scene to evaluate: the scene, its ego and controlled agent, its family.
#[derive(Debug, Clone)]
pub struct SimScene {
    /// The scene, or the window cut from a longer one (then in the WOSAC layout: 91 steps,
    /// current step 10; its id `<scenario id>@<step of the window's current step>`).
    pub scene: Scene,
    /// A.
    pub ego: i64,
    /// B.
    pub controlled: i64,
    /// How A and B were chosen.
    pub pair: PairOrigin,
    /// The step of the source scene that is the window's current step, for a window cut from
    /// a longer scene (`None`: the scene is its own window).
    pub window: Option<usize>,
    /// The synthetic ground truth (the reactive rule, and the family).
    pub truth: Option<GroundTruth>,
}

impl SimScene {
    /// A (the SDC) and B (the first other object of interest valid at the current step) of a
    /// scene; `None` when it has no such pair.
    pub fn of(scene: Scene, truth: Option<GroundTruth>) -> Option<Self> {
        let (ego, controlled) = named_pair(&scene)?;
        Some(Self {
            scene,
            ego,
            controlled,
            pair: PairOrigin::Named,
            window: None,
            truth,
        })
    }

    /// The windows of `scene` that `data prepare` cuts (one for a 9.1 s scene, one every 10
    /// steps of a longer one), each with its pair: the one the log names ([`SimScene::of`]),
    /// else the first of `data prepare`'s pairs of the window (the labelled one, else the
    /// mined one of closest approach; the SDC is A when it is one of them, otherwise the
    /// pair's first vehicle). A window without a pair is left out; a scene without any, with
    /// the reason ([`TOO_SHORT`], [`NO_PAIR`]). The ground truth stays with a scene that is its
    /// own window.
    pub fn windows_of(scene: Scene, truth: Option<GroundTruth>) -> Result<Vec<Self>, String> {
        let config = WindowConfig::default();
        let wins = windows(&scene, &config);
        if wins.is_empty() {
            return Err(TOO_SHORT.into());
        }
        let prepared = PreparedScene::from_scene(
            &scene,
            &config,
            &PairConfig::default(),
            scbg::ROAD_SUBSAMPLE,
        )
        .map_err(|_| TOO_SHORT.to_string())?;
        let whole = wins.len() == 1
            && wins[0].current_step == scene.current_step
            && scene.num_steps() == config.window_steps();
        let mut out = Vec::new();
        for (w, window) in wins.iter().enumerate() {
            let mined = || {
                let p = prepared.pairs.get(w)?.first()?;
                let (first, second) = (prepared.tracks[p.first].id, prepared.tracks[p.second].id);
                let sdc = scene.sdc_track_index.map(|i| scene.tracks[i].id);
                let (a, b) = if sdc == Some(second) {
                    (second, first)
                } else {
                    (first, second)
                };
                let origin = match p.source {
                    scbg_features::PairSource::Labelled => PairOrigin::Labelled,
                    scbg_features::PairSource::Mined => PairOrigin::Mined,
                };
                Some((a, b, origin))
            };
            let cut = if whole {
                None
            } else {
                match window_scene(&scene, window, &config) {
                    Some(mut cut) => {
                        cut.scenario_id = format!("{}@{}", scene.scenario_id, window.current_step);
                        Some(cut)
                    }
                    None => continue,
                }
            };
            let view = cut.as_ref().unwrap_or(&scene);
            let Some((ego, controlled, pair)) = named_pair(view)
                .map(|(a, b)| (a, b, PairOrigin::Named))
                .or_else(mined)
            else {
                continue;
            };
            out.push(match cut {
                Some(cut) => Self {
                    scene: cut,
                    ego,
                    controlled,
                    pair,
                    window: Some(window.current_step),
                    truth: None,
                },
                None => Self {
                    scene: scene.clone(),
                    ego,
                    controlled,
                    pair,
                    window: None,
                    truth: truth.clone(),
                },
            });
        }
        if out.is_empty() {
            return Err(NO_PAIR.into());
        }
        Ok(out)
    }

    /// The scenario id of the scene the window was cut from.
    pub fn source_id(&self) -> &str {
        let id = self.scene.scenario_id.as_str();
        match self.window {
            Some(step) => id.strip_suffix(&format!("@{step}")).unwrap_or(id),
            None => id,
        }
    }

    pub(super) fn family(&self) -> String {
        self.truth
            .as_ref()
            .map_or_else(|| "womd".into(), |t| t.family.name().to_string())
    }
}

/// Where the simulated scenes came from (`eval_sim.json` → `sources`).
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct SceneSources {
    /// Scenes of the logs (scenario ids) with at least one window simulated.
    pub scenarios: usize,
    /// Windows cut from longer scenes (or from a scene whose current step leaves no room for
    /// 11 history and 80 future steps) among the simulated scenes.
    pub windows: usize,
    /// The simulated scenes by how their pair was chosen: `named`, `labelled`, `mined`.
    pub pairs: BTreeMap<String, usize>,
}

impl SceneSources {
    /// The sources of the simulated `scenes`; `None` when each is its own window with the
    /// pair its log names.
    pub(super) fn of(scenes: &[&SimScene]) -> Option<Self> {
        if scenes
            .iter()
            .all(|s| s.window.is_none() && s.pair == PairOrigin::Named)
        {
            return None;
        }
        let mut ids: Vec<&str> = scenes.iter().map(|s| s.source_id()).collect();
        ids.sort_unstable();
        ids.dedup();
        let mut pairs = BTreeMap::new();
        for s in scenes {
            let name = match s.pair {
                PairOrigin::Named => "named",
                PairOrigin::Labelled => "labelled",
                PairOrigin::Mined => "mined",
            };
            *pairs.entry(name.to_string()).or_insert(0) += 1;
        }
        Some(Self {
            scenarios: ids.len(),
            windows: scenes.iter().filter(|s| s.window.is_some()).count(),
            pairs,
        })
    }
}

/// The first scenes of `scenes` that come from the first `max` logged scenes (all the windows
/// of each).
pub(super) fn first_logged(scenes: &[SimScene], max: usize) -> &[SimScene] {
    let mut logged = 0;
    let mut end = 0;
    for (i, s) in scenes.iter().enumerate() {
        if i == 0 || s.source_id() != scenes[i - 1].source_id() {
            logged += 1;
            if logged > max {
                break;
            }
        }
        end = i + 1;
    }
    &scenes[..end]
}

/// The order in which scenes are taken for WOSAC realism: each logged scene's first window
/// before any scene's second, and so on (in the order given otherwise), so that a few long
/// scenes do not take every place.
pub(super) fn spread_over_logged(scenes: &[SimScene]) -> Vec<usize> {
    let mut rank = Vec::with_capacity(scenes.len());
    for (i, s) in scenes.iter().enumerate() {
        let r = match i {
            0 => 0,
            _ if s.source_id() == scenes[i - 1].source_id() => rank[i - 1] + 1,
            _ => 0,
        };
        rank.push(r);
    }
    let mut order: Vec<usize> = (0..scenes.len()).collect();
    order.sort_by_key(|&i| (rank[i], i));
    order
}

/// The pair the log names: the SDC and the first other object of interest, both valid at the
/// current step.
fn named_pair(scene: &Scene) -> Option<(i64, i64)> {
    let sdc = scene.sdc_track_index?;
    let valid = |i: usize| {
        scene
            .tracks
            .get(i)
            .and_then(|t| t.states.get(scene.current_step))
            .is_some_and(|s| s.valid)
    };
    if !valid(sdc) {
        return None;
    }
    let ego = scene.tracks[sdc].id;
    let controlled = scene
        .objects_of_interest
        .iter()
        .copied()
        .find(|&id| id != ego && scene.track_index(id).is_some_and(valid))?;
    Some((ego, controlled))
}

/// Scenes left out, counted by reason and listed.
#[derive(Debug, Default)]
pub(super) struct Skips {
    pub(super) counts: BTreeMap<String, usize>,
    pub(super) scenes: Vec<SkippedScene>,
}

impl Skips {
    /// Counts and lists `scenario_id` under `reason`.
    pub(super) fn add(&mut self, scenario_id: &str, reason: String, detail: Option<String>) {
        *self.counts.entry(reason.clone()).or_insert(0) += 1;
        self.scenes.push(SkippedScene {
            scenario_id: scenario_id.to_string(),
            reason,
            detail,
        });
    }

    /// Counts and lists `scenario_id` under `prefix` and the reason of `error`.
    pub(super) fn error(&mut self, prefix: &str, scenario_id: &str, error: &anyhow::Error) {
        let message = format!("{error:#}");
        let reason = format!("{prefix}{}", reason_of(&message, scenario_id));
        self.add(scenario_id, reason, Some(message));
    }
}

/// The reason an error counts under: its message without the scene's id, every number as `#`
/// (so that the same failure in two scenes counts once).
pub(super) fn reason_of(message: &str, scenario_id: &str) -> String {
    let base = scenario_id.split('@').next().unwrap_or(scenario_id);
    let mut text = message.to_string();
    for id in [scenario_id, base] {
        if !id.is_empty() {
            text = text.replace(id, "");
        }
    }
    let mut out = String::with_capacity(text.len());
    let mut in_number = false;
    for c in text.chars() {
        let digit = c.is_ascii_digit() || (in_number && c == '.');
        if digit && !in_number {
            out.push('#');
        }
        if !digit {
            out.push(c);
        }
        in_number = digit;
    }
    out.replace("scenario : ", "")
        .replace("scene : ", "")
        .replace("  ", " ")
        .trim()
        .to_string()
}

/// The scenes of WOMD files for `eval sim`: each scene's windows with their pairs
/// ([`SimScene::windows_of`]) and its synthetic ground truth when `truth` has it, on the split
/// asked (by scenario id, with the predictor's validation fraction), until `max` scenes with a
/// pair are found (each with all its windows). Returns them with every scene left out and why (a record that cannot be read is one
/// too, named by file and record).
pub fn load_scenes(
    inputs: &[String],
    truth: Option<&[GroundTruth]>,
    split: crate::predictor::SplitSelection,
    validation_fraction: f64,
    max: usize,
) -> anyhow::Result<(Vec<SimScene>, Vec<SkippedScene>)> {
    let index = truth.map(crate::fidelity::TruthIndex::new);
    let mut scenes = Vec::new();
    let mut skipped = Vec::new();
    // Logged scenes with a pair so far.
    let mut with_pair = 0;
    let unreadable = |name: String, e: &scbg_womd::WomdError| {
        tracing::warn!("skipped: {e}");
        SkippedScene {
            scenario_id: name,
            reason: format!("unreadable ({})", e.reason()),
            detail: Some(e.to_string()),
        }
    };
    'files: for file in crate::inputs::expand(inputs)? {
        let womd = match scbg_womd::WomdFile::open(&file) {
            Ok(f) => f,
            Err(e) => {
                skipped.push(unreadable(file.display().to_string(), &e));
                continue;
            }
        };
        for (record, scene) in womd.scenes().enumerate() {
            if with_pair >= max {
                break 'files;
            }
            let scene = match scene {
                Ok(s) => s,
                Err(e) => {
                    skipped.push(unreadable(
                        format!("{} record {record}", file.display()),
                        &e,
                    ));
                    continue;
                }
            };
            if split == crate::predictor::SplitSelection::Validation
                && scbg_train::data::split_of(&scene.scenario_id, validation_fraction)
                    != scbg_train::data::Split::Validation
            {
                continue;
            }
            let t = index
                .as_ref()
                .and_then(|i| i.get(&scene.scenario_id))
                .cloned();
            let id = scene.scenario_id.clone();
            match SimScene::windows_of(scene, t) {
                Ok(w) => {
                    with_pair += 1;
                    scenes.extend(w);
                }
                Err(reason) => skipped.push(SkippedScene {
                    scenario_id: id,
                    reason,
                    detail: None,
                }),
            }
        }
    }
    Ok((scenes, skipped))
}

#[cfg(test)]
mod tests {
    use super::{PairOrigin, SimScene, first_logged, reason_of, spread_over_logged};

    fn sim_scene(id: &str, window: Option<usize>) -> SimScene {
        SimScene {
            scene: scbg_scene::Scene {
                scenario_id: window.map_or(id.to_string(), |w| format!("{id}@{w}")),
                ..Default::default()
            },
            ego: 1,
            controlled: 2,
            pair: PairOrigin::Mined,
            window,
            truth: None,
        }
    }

    #[test]
    fn logged_scenes_count_whole_and_realism_takes_first_windows_first() {
        let scenes = [
            sim_scene("a", Some(10)),
            sim_scene("a", Some(20)),
            sim_scene("b", None),
            sim_scene("c", Some(10)),
            sim_scene("c", Some(30)),
        ];
        assert_eq!(scenes[1].source_id(), "a");
        assert_eq!(first_logged(&scenes, 2).len(), 3);
        assert_eq!(first_logged(&scenes, 0).len(), 0);
        assert_eq!(first_logged(&scenes, 9).len(), 5);
        assert_eq!(spread_over_logged(&scenes), [0, 2, 3, 1, 4]);
    }

    #[test]
    fn reasons_leave_out_ids_and_numbers() {
        assert_eq!(
            reason_of(
                "scenario 4d32a9@40: agent 1234 is not valid at the current step 10",
                "4d32a9@40"
            ),
            "agent # is not valid at the current step #"
        );
        assert_eq!(
            reason_of("agent 7 at step 30: plan failed: B 7 has 0.5 m", "x"),
            "agent # at step #: plan failed: B # has # m"
        );
    }
}
