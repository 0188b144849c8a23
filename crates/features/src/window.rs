//! 91-step windows (11 history + 80 future by default) cut from scenarios of any length.

use scbg_scene::Scene;

/// Window lengths and the stride for long scenarios.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct WindowConfig {
    /// History steps including the current one (WOMD: 10 past + 1 current).
    pub history_steps: usize,
    /// Future steps after the current one (WOMD: 80, 8 s at 10 Hz).
    pub future_steps: usize,
    /// Steps between window starts in scenarios longer than one window.
    pub stride_steps: usize,
}

impl Default for WindowConfig {
    fn default() -> Self {
        Self {
            history_steps: 11,
            future_steps: 80,
            stride_steps: 10,
        }
    }
}

impl WindowConfig {
    /// Steps of one window: history (including the current step) + future.
    pub fn window_steps(&self) -> usize {
        self.history_steps + self.future_steps
    }
}

/// One window of a scene, identified by its current ("now") step; its history is the
/// `history_steps` ending there and its future the `future_steps` after it.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Window {
    /// The scene step that is "now" (last history step).
    pub current_step: usize,
}

impl Window {
    /// Whether `step` lies in this window's history.
    pub fn history_contains(&self, step: usize, history_steps: usize) -> bool {
        step <= self.current_step && step + history_steps > self.current_step
    }

    /// Scene step of history index `h` (0 = oldest), or `None` before the scene starts.
    pub fn history_step(&self, h: usize, history_steps: usize) -> Option<usize> {
        (self.current_step + h + 1).checked_sub(history_steps)
    }

    /// Scene step of future index `f` (0 = first step after now).
    pub fn future_step(&self, f: usize) -> usize {
        self.current_step + 1 + f
    }
}

/// The windows of a scene.
///
/// - A scene exactly one window long (a WOMD 9.1 s scenario) gives one window at its own
///   `current_step`, provided that leaves room for the history and future.
/// - A longer scene (e.g. a 20 s WOMD scenario, whose `current_time_index` is a placeholder,
///   nuScenes, synthetic) gives windows every `stride_steps`, the first with its history
///   starting at step 0, all fully inside the scene.
/// - A shorter scene gives none.
pub fn windows(scene: &Scene, config: &WindowConfig) -> Vec<Window> {
    let n = scene.num_steps();
    let len = config.window_steps();
    if n < len || config.history_steps == 0 {
        return Vec::new();
    }
    if n == len {
        let c = scene.current_step;
        if c + 1 >= config.history_steps && c + config.future_steps < n {
            return vec![Window { current_step: c }];
        }
        return vec![Window {
            current_step: config.history_steps - 1,
        }];
    }
    (0..=n - len)
        .step_by(config.stride_steps.max(1))
        .map(|start| Window {
            current_step: start + config.history_steps - 1,
        })
        .collect()
}

/// The steps of `window` as a scene of its own, in the layout of a WOMD 9.1 s scenario: the
/// window's history and future steps of every track, timestamp and signal, with the window's
/// current step as the scene's (`history_steps − 1`). Ids, the SDC, the objects of interest
/// and the map are the scene's; prediction targets are kept where they are valid at the
/// window's current step. `None` when the window does not lie inside the scene (every window
/// of [`windows`] does).
pub fn window_scene(scene: &Scene, window: &Window, config: &WindowConfig) -> Option<Scene> {
    let first = window.history_step(0, config.history_steps)?;
    let end = window.future_step(config.future_steps);
    if end > scene.num_steps() || config.history_steps == 0 {
        return None;
    }
    let now = window.current_step;
    let tracks: Vec<scbg_scene::Track> = scene
        .tracks
        .iter()
        .map(|t| {
            Some(scbg_scene::Track {
                id: t.id,
                object_type: t.object_type,
                states: t.states.get(first..end)?.to_vec(),
            })
        })
        .collect::<Option<_>>()?;
    let signals_per_step = if scene.signals_per_step.is_empty() {
        Vec::new()
    } else {
        scene.signals_per_step.get(first..end)?.to_vec()
    };
    let tracks_to_predict = scene
        .tracks_to_predict
        .iter()
        .filter(|t| {
            scene
                .tracks
                .get(t.track_index)
                .and_then(|tr| tr.states.get(now))
                .is_some_and(|s| s.valid)
        })
        .cloned()
        .collect();
    Some(Scene {
        scenario_id: scene.scenario_id.clone(),
        timestamps_secs: scene.timestamps_secs[first..end].to_vec(),
        current_step: now - first,
        sdc_track_index: scene.sdc_track_index,
        tracks,
        objects_of_interest: scene.objects_of_interest.clone(),
        tracks_to_predict,
        map: scene.map.clone(),
        signals_per_step,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn scene_with_steps(n: usize, current: usize) -> Scene {
        Scene {
            timestamps_secs: (0..n).map(|i| i as f64 * 0.1).collect(),
            current_step: current,
            ..Default::default()
        }
    }

    #[test]
    fn one_window_for_womd_length() {
        assert_eq!(
            windows(&scene_with_steps(91, 10), &WindowConfig::default()),
            vec![Window { current_step: 10 }]
        );
    }

    #[test]
    fn sliding_windows_for_long_scenes() {
        let w = windows(&scene_with_steps(198, 10), &WindowConfig::default());
        // Starts 0, 10, ..., 100 (100 + 91 = 191 <= 198; 110 + 91 = 201 > 198).
        assert_eq!(w.len(), 11);
        assert_eq!(w[0].current_step, 10);
        assert_eq!(w[10].current_step, 110);
        assert!(w.iter().all(|w| w.current_step + 80 < 198));
    }

    #[test]
    fn short_scene_has_no_window() {
        assert!(windows(&scene_with_steps(50, 10), &WindowConfig::default()).is_empty());
    }

    #[test]
    fn history_indices() {
        let w = Window { current_step: 10 };
        assert_eq!(w.history_step(0, 11), Some(0));
        assert_eq!(w.history_step(10, 11), Some(10));
        assert!(
            w.history_contains(0, 11) && w.history_contains(10, 11) && !w.history_contains(11, 11)
        );
        let early = Window { current_step: 3 };
        assert_eq!(early.history_step(0, 11), None);
        assert_eq!(early.history_step(7, 11), Some(0));
        assert_eq!(w.future_step(0), 11);
    }

    #[test]
    fn window_scene_is_the_window_in_womd_layout() {
        let mut scene = scene_with_steps(198, 10);
        scene.tracks = vec![scbg_scene::Track {
            id: 7,
            object_type: scbg_scene::ObjectType::Vehicle,
            states: (0..198)
                .map(|i| scbg_scene::AgentState {
                    x_m: i as f64,
                    valid: i >= 40,
                    ..Default::default()
                })
                .collect(),
        }];
        scene.tracks_to_predict = vec![scbg_scene::PredictionTarget {
            track_index: 0,
            difficulty: Default::default(),
        }];
        let config = WindowConfig::default();
        let w = windows(&scene, &config);
        let cut = window_scene(&scene, &w[4], &config).unwrap();
        assert_eq!((cut.num_steps(), cut.current_step), (91, 10));
        assert_eq!(cut.tracks[0].states[0].x_m, 40.0);
        assert_eq!(cut.tracks_to_predict.len(), 1);
        assert!((cut.timestamps_secs[10] - 5.0).abs() < 1e-9);
        cut.validate().unwrap();
        // Not valid at the window's current step: no longer a prediction target.
        let early = window_scene(&scene, &w[0], &config).unwrap();
        assert!(early.tracks_to_predict.is_empty());
        // A window reaching past the scene has no scene.
        assert!(window_scene(&scene, &Window { current_step: 190 }, &config).is_none());
        assert!(window_scene(&scene, &Window { current_step: 3 }, &config).is_none());
    }
}
