//! The demo report as text: report.md (Table II, the seed means, the fidelity and closed-loop
//! sections) and the one-screen summary printed at the end of a run.

use std::path::Path;

use super::DemoReport;

impl DemoReport {
    /// report.md.
    pub fn to_markdown(&self) -> String {
        let fig5a: String = self
            .scbg
            .figures
            .iter()
            .filter(|f| f.starts_with("fig5a"))
            .map(|f| format!("![{f}](figures/{f})\n"))
            .collect();
        format!(
            "# scbg demo report\n\nData: {} scenarios, {} windows, {} interacting pairs (skipped: {:?}).\n\n\
             ## Predictor (paper Table I layout, held-out scenarios)\n\n{}\n\
             ## Courtesy labels (paper Fig. 3)\n\n{} labelled futures ({} logged); ψ std within a pair role (the part B's future decides): {:.4}.\n\n![psi](figures/psi_histogram.png)\n\n\
             Ground-truth check — Spearman(ψ of the logged future, latent courtesy of the generator):\n\n{}\n\n\
             Fidelity — ψ_label against ψ_true, the synthetic simulator's counterfactual oracle (held-out scenes; the scatter shows every scene):\n\n{}\n\
             ## SCBG generator (paper Table II layout, held-out pairs)\n\n{}\n\
             ### First seed in detail\n\n{}\n\
             Acceptance checks (as measured):\n\n{}\n\n\
             ### Fig. 4 — input quantile → courtesy of the generated trajectory\n\n![fig4](figures/fig4_quantile_courtesy.png)\n\n\
             ### Fig. 5a — B generated at quantiles 0.1…0.9 (full variant), A's logged future in red\n\n{}\n\
             ### Fig. 5b — A's expected speed vs quantile\n\n![fig5b](figures/fig5b_quantile_speed.png)\n\n\
             ## Closed loop (beyond the paper)\n\n{}{}\n\
             ![scene](figures/scene.png)\n\nRun time: {:.0} s.\n",
            self.data.scenarios,
            self.data.windows,
            self.data.pairs,
            self.data.skipped,
            self.predictor.to_markdown(),
            self.labels.futures,
            self.labels.logged,
            self.labels.psi_within_pair_std,
            if self.label_summary.spearman_latent.is_empty() {
                "(no synthetic ground truth for this data)".to_string()
            } else {
                self.label_summary
                    .spearman_latent
                    .iter()
                    .map(|(f, r)| {
                        format!(
                            "- {f}: {} (n = {})",
                            r.rho.map_or("-".into(), |r| format!("{r:.3}")),
                            r.n
                        )
                    })
                    .collect::<Vec<_>>()
                    .join("\n")
            },
            self.fidelity.as_ref().map_or(
                "(no synthetic ground truth for this data)\n".to_string(),
                |f| format!(
                    "{}\n![fidelity](figures/psi_fidelity.png)\n{}",
                    f.to_markdown(),
                    self.fidelity_stage1.as_ref().map_or(String::new(), |f| format!(
                        "\nThe predictor before the reaction siblings joined its training:\n\n{}",
                        f.to_markdown()
                    ))
                )
            ),
            self.seed_mean_markdown(),
            self.scbg.to_markdown(),
            self.check_list
                .iter()
                .map(|c| format!("- [{}] {}", if c.passed { "x" } else { " " }, c.text))
                .collect::<Vec<_>>()
                .join("\n"),
            fig5a,
            self.closed_loop
                .as_ref()
                .map_or("(skipped)\n".to_string(), |c| closed_loop_markdown(
                    c, "figures"
                )),
            self.closed_loop_ranked
                .as_ref()
                .map_or(String::new(), |c| format!(
                    "\n### Sample and rank in closed loop\n\n{}",
                    closed_loop_markdown(c, "figures/closed_loop_ranked")
                )),
            self.seconds
        )
    }

    /// The seed-mean table: every number `mean ± std` over the generator seeds.
    pub fn seed_mean_markdown(&self) -> String {
        let cell = |variant: &str, path: &[&str], truth: bool| -> String {
            let (m, s) = if truth {
                (&self.truth_control, &self.truth_control_seed_std)
            } else {
                (&self.variants, &self.variants_seed_std)
            };
            let get = |v: &serde_json::Value| {
                path.iter()
                    .try_fold(&v[variant], |v, k| v.get(*k))
                    .and_then(serde_json::Value::as_f64)
            };
            match (get(m), get(s)) {
                (Some(m), Some(s)) if m.abs() < 0.01 && m != 0.0 => format!("{m:.2e} ± {s:.1e}"),
                (Some(m), Some(s)) => format!("{m:.3} ± {s:.3}"),
                _ => "-".into(),
            }
        };
        // A column per family the run drew.
        let families: Vec<&str> = scbg_synth::Family::ALL
            .map(scbg_synth::Family::name)
            .into_iter()
            .filter(|f| {
                self.truth_control.as_object().is_some_and(|m| {
                    m.values()
                        .any(|v| v["spearman_quantile_psi_true"].get(*f).is_some())
                })
            })
            .collect();
        let mut out = format!(
            "Mean ± standard deviation over {} generator seeds ({:?}):\n\n| model | CourtesyMSE *data* | CourtesyMSE *range* | CourtesyMSE *arbitrary* | TrajADE (m) | corr(q, ψ) all | corr(q, ψ) high | Spearman(q, ψ_true) all | {} | within an example |\n|---|---|---|---|---|---|---|---|{}---|\n",
            self.generator_seeds.len(),
            self.generator_seeds,
            families.join(" | "),
            "---|".repeat(families.len()),
        );
        let names = self
            .variants
            .as_object()
            .map(|m| m.keys().cloned().collect::<Vec<_>>());
        for name in ["baseline", "aug", "full", scbg_generator::ranked::RANKED] {
            if !names.as_ref().is_some_and(|n| n.iter().any(|k| k == name)) {
                continue;
            }
            let rho = |k: &str| cell(name, &["spearman_quantile_psi_true", k], true);
            let per_family: Vec<String> = families.iter().map(|f| rho(f)).collect();
            out += &format!(
                "| {name} | {} | {} | {} | {} | {} | {} | {} | {} | {} |\n",
                cell(name, &["courtesy_mse_data", "mean"], false),
                cell(name, &["courtesy_mse_range", "mean"], false),
                cell(name, &["courtesy_mse_arbitrary", "mean"], false),
                cell(name, &["traj_ade", "mean"], false),
                cell(name, &["corr_quantile"], false),
                cell(name, &["corr_quantile_high"], false),
                rho(crate::fidelity::POOLED),
                per_family.join(" | "),
                cell(
                    name,
                    &["spearman_within_example", crate::fidelity::POOLED],
                    true
                ),
            );
        }
        let world = self
            .truth_control_world
            .iter()
            .map(|w| ("the world's own B at c = q (yardstick)", w));
        let selection = self
            .truth_control_selection
            .iter()
            .flat_map(|sel| sel.yardsticks());
        let candidates = self
            .truth_control_candidates
            .iter()
            .flat_map(|sel| sel.candidate_yardsticks());
        for (label, w) in world.chain(selection).chain(candidates) {
            let rho = |k: &str| {
                w.spearman_quantile_psi_true
                    .get(k)
                    .copied()
                    .flatten()
                    .map_or("-".into(), |x| format!("{x:.3}"))
            };
            let per_family: Vec<String> = families.iter().map(|f| rho(f)).collect();
            out += &format!(
                "| {label} | | | | | | | {} | {} | {} |\n",
                rho(crate::fidelity::POOLED),
                per_family.join(" | "),
                w.spearman_within_example
                    .get(crate::fidelity::POOLED)
                    .map_or("-".into(), |x| format!("{x:.3}")),
            );
        }
        out
    }

    /// The one-screen summary printed at the end of a run.
    pub fn summary_text(&self, report_md: &Path) -> String {
        let mut s = format!(
            "\n=== scbg demo: done in {:.0} s ===\ndata: {} scenarios, {} pairs\n",
            self.seconds, self.data.scenarios, self.data.pairs
        );
        for (name, t) in &self.predictor.rows {
            let m = &t.by_time[2].1;
            s += &format!(
                "{name:<36} minADE@8s {:>6}  MR@8s {:>6}\n",
                m.min_ade.map_or("-".into(), |v| format!("{v:.2}")),
                m.miss_rate
                    .map_or("-".into(), |v| format!("{:.1}%", 100.0 * v))
            );
        }
        for (f, r) in &self.label_summary.spearman_latent {
            s += &format!(
                "Spearman(ψ, latent courtesy) {f:<9} {} (n = {})\n",
                r.rho.map_or("-".into(), |r| format!("{r:.3}")),
                r.n
            );
        }
        if let Some(f) = &self.fidelity {
            s += "fidelity of ψ_label against the simulator's ψ_true (held-out scenes):\n";
            s += &f.to_markdown();
        }
        if let Some(f) = &self.fidelity_stage1 {
            s += "the predictor's before the reaction siblings joined its training:\n";
            s += &f.to_markdown();
        }
        s += &self.seed_mean_markdown();
        for c in &self.check_list {
            s += &format!("[{}] {}\n", if c.passed { "ok" } else { "MISS" }, c.text);
        }
        s += &format!("report: {}", report_md.display());
        s
    }
}

/// The closed-loop section of report.md (`figures`: where its two figures are, relative to it).
fn closed_loop_markdown(c: &crate::sim_eval::SimEval, figures: &str) -> String {
    use crate::sim_eval::fmt_or_na;
    let meta = |w: Option<&crate::sim_eval::WosacSummary>| {
        w.map_or("n/a".into(), |w| {
            format!(
                "{:.4} | {:.3} | {:.3} | {:.3} | {:.3}",
                w.metametric, w.kinematic, w.interactive, w.map_based, w.collision_rate
            )
        })
    };
    if c.curve.scenes == 0 {
        return format!(
            "No held-out scene could be simulated; {}.\n",
            c.skipped_line()
        );
    }
    let mut out = format!(
        "{} drives B (re-planning every {} steps from the simulated history, kinematic bicycle with a safety guard) among reactive agents ({}) on {} held-out scenes.\n\n\
         | quantile | A's realised speed (m/s) | realised courtesy (m/s) | B collision | B off-road | WOSAC meta | kinematic | interactive | map | collision rate |\n|---|---|---|---|---|---|---|---|---|---|\n",
        if c.policy == crate::choices::Policy::Ranked.name() {
            "Sample and rank (the full variant's predictor and labels: B's sampled future of the quantile's rank)"
        } else {
            "The full generator"
        },
        c.replan_every,
        if c.world_knob.is_some() {
            "the synthetic world's rule"
        } else {
            "IDM along their logged paths"
        },
        c.curve.scenes
    );
    for r in &c.curve.per_quantile {
        out += &format!(
            "| {:.1} | {:.2} ± {:.2} | {:.3} ± {:.3} | {:.3} | {} | {} |\n",
            r.quantile,
            r.a_avg_speed_mps,
            r.a_avg_speed_std_mps,
            r.realised_courtesy_mps,
            r.realised_courtesy_std_mps,
            r.b_collision_rate,
            fmt_or_na(r.b_offroad_rate, 3),
            r.wosac
                .as_ref()
                .map_or("n/a | n/a | n/a | n/a | n/a".into(), |w| meta(Some(w)))
        );
    }
    for (name, b) in &c.baselines {
        out += &format!(
            "| {name} | {} | – | {} | {} | {} |\n",
            fmt_or_na(b.a_avg_speed_mps, 2),
            fmt_or_na(b.b_collision_rate, 3),
            fmt_or_na(b.b_offroad_rate, 3),
            meta(b.wosac.as_ref())
        );
    }
    let fmt = |m: &crate::sim_eval::PerFamily| {
        m.iter()
            .map(|(k, v)| format!("{k} {}", v.map_or("-".into(), |v| format!("{v:.3}"))))
            .collect::<Vec<_>>()
            .join(", ")
    };
    out += &format!(
        "\nSpearman(quantile, A's realised speed): {}. Spearman(quantile, realised courtesy): {}. Within a scene (mean of each scene's Spearman(quantile, A's realised speed), 0 where it does not respond): {}; responsive scenes: {}. With each scene's speeds ordered to rise with the quantile (a perfect knob's with these outcomes): {}. scbg WOSAC over its quantiles: {}.\n\n\
         ![closed-loop courtesy]({figures}/sim_courtesy.png)\n![closed-loop realism]({figures}/sim_realism.png)\n",
        fmt(&c.curve.spearman_quantile_a_speed),
        fmt(&c.curve.spearman_quantile_realised_courtesy),
        fmt(&c.curve.spearman_within_scene_a_speed),
        fmt(&c.curve.responsive_fraction),
        fmt(&c.curve.spearman_quantile_a_speed_ordered),
        meta(c.wosac_scbg.as_ref())
    );
    out += &format!("\n{}.\n", c.realism_line());
    out += &format!("\n{}.\n", c.curve.collision_line());
    out += &format!("\n{}.\n", c.curve.offroad_line());
    if !c.skipped.is_empty() {
        out += &format!("\n{}.\n", c.skipped_line());
    }
    if let Some(sources) = &c.sources {
        out += &format!(
            "\nThe scenes: {} windows of {} logged scenes ({} cut from longer scenes); pairs {}.\n",
            c.curve.scenes,
            sources.scenarios,
            sources.windows,
            sources
                .pairs
                .iter()
                .map(|(k, n)| format!("{k} {n}"))
                .collect::<Vec<_>>()
                .join(", ")
        );
    }
    if let Some(w) = &c.world_knob {
        out += &format!(
            "\nThe ceiling: the same {} scenes with B driven by the synthetic world's own rule at courtesy c = q (a B faithful to its courtesy). A's realised speed per quantile: {}. Spearman(quantile, A's realised speed): {}. Spearman(quantile, realised courtesy): {}. Within a scene: {}; responsive scenes: {}. Ordered within each scene: {}. B collision rate at most {}.\n",
            w.scenes,
            w.per_quantile
                .iter()
                .map(|r| format!("{:.1}: {:.2}", r.quantile, r.a_avg_speed_mps))
                .collect::<Vec<_>>()
                .join(", "),
            fmt(&w.spearman_quantile_a_speed),
            fmt(&w.spearman_quantile_realised_courtesy),
            fmt(&w.spearman_within_scene_a_speed),
            fmt(&w.responsive_fraction),
            fmt(&w.spearman_quantile_a_speed_ordered),
            fmt_or_na(w.max_b_collision_rate, 3)
        );
    }
    out
}
