//! Figure composition of the SCBG evaluation: Fig. 4 (quantile → achieved ψ per variant),
//! Fig. 5a (three held-out cases with B generated at five quantiles) and Fig. 5b (A's expected
//! speed vs quantile), in the paper's layout.

use std::path::Path;

use scbg_generator::eval::{EVAL_QUANTILES, VariantEval};
use scbg_generator::{Example, Scbg};
use scbg_scene::Pose2;

use crate::generator::LoadedScbg;

/// The variant's name in figures (the bundled font has no circled digits).
fn plot_label(name: &str) -> &str {
    match name {
        "baseline" => "(1) baseline",
        "aug" => "(1)+(2) augmentation",
        "full" => "(1)+(2)+(3) courtesy loss",
        "ranked" => "sample and rank (no generator)",
        other => other,
    }
}

/// Fig. 4 (quantile → achieved ψ per variant), Fig. 5a (three cases with B generated at five
/// quantiles, last variant) and Fig. 5b (A's expected speed vs quantile for those cases).
pub(crate) fn write_figures(
    dir: &Path,
    data: &Path,
    variants: &[(String, VariantEval)],
    loaded: &[LoadedScbg],
    examples: &[&Example],
) -> anyhow::Result<Vec<String>> {
    let mut written = Vec::new();
    // Fig. 4: the high-courtesy subset as in the paper, all pairs when it is empty.
    let use_high = variants
        .iter()
        .all(|(_, v)| !v.per_quantile_high.is_empty());
    let series: Vec<scbg_plot::Series> = variants
        .iter()
        .map(|(name, v)| {
            let curve = if use_high {
                &v.per_quantile_high
            } else {
                &v.per_quantile
            };
            scbg_plot::Series {
                label: format!("{} (mean ± std)", plot_label(name)),
                points: curve
                    .iter()
                    .map(|p| (f64::from(p.quantile), p.achieved_psi.mean))
                    .collect(),
                band: Some(curve.iter().map(|p| p.achieved_psi.std).collect()),
            }
        })
        .collect();
    let name = "fig4_quantile_courtesy.png";
    scbg_plot::line_chart(
        &series,
        "input quantile",
        "courtesy of the generated trajectory, ψ (m/s)",
        if use_high {
            "Fig. 4: quantile → courtesy (high-courtesy pairs)"
        } else {
            "Fig. 4: quantile → courtesy (all pairs)"
        },
        &dir.join(name),
    )?;
    written.push(name.to_string());

    // Fig. 5: the three held-out pairs with the largest |ψ_logged|, distinct scenarios.
    let mut order: Vec<usize> = (0..examples.len()).collect();
    order.sort_by(|&i, &j| {
        examples[j].psi[0]
            .abs()
            .total_cmp(&examples[i].psi[0].abs())
    });
    let mut cases: Vec<usize> = Vec::new();
    for i in order {
        if cases.len() == 3 {
            break;
        }
        if cases
            .iter()
            .all(|&c| examples[c].scenario_id != examples[i].scenario_id)
        {
            cases.push(i);
        }
    }
    let last = loaded.last().expect("at least one model");
    let scbg: &Scbg = &last.scbg;
    let quantiles = [0.1f32, 0.3, 0.5, 0.7, 0.9];
    let roads = case_roads(
        data,
        cases.iter().map(|&i| examples[i].scenario_id.as_str()),
    )?;
    let mut speed_series = Vec::new();
    for (k, &i) in cases.iter().enumerate() {
        let e = examples[i];
        let ranges = scbg_generator::eval::predicted_ranges(&scbg.range, &[e], &last.device);
        let (lo, hi) = ranges[0];
        let nine: Vec<f32> = EVAL_QUANTILES
            .iter()
            .map(|&q| scbg_generator::psi_for_quantile(q, lo, hi))
            .collect();
        let measured = scbg_generator::eval::generate_and_measure(
            &scbg.generator,
            &scbg.predictor,
            &[e],
            std::slice::from_ref(&nine),
            scbg.labels.reward,
            &last.device,
        );
        speed_series.push(scbg_plot::Series {
            label: format!("case {} ({})", k + 1, e.scenario_id),
            points: EVAL_QUANTILES
                .iter()
                .zip(&measured.e_cond[0])
                .map(|(&q, &v)| (f64::from(q), f64::from(v)))
                .collect(),
            band: None,
        });
        // Everything in A's frame.
        let b_pose = Pose2::new(
            f64::from(e.a_from_b[1]),
            f64::from(e.a_from_b[2]),
            f64::from(e.a_from_b[0]),
        );
        let in_a = |pts: &[[f32; 2]]| -> Vec<(f64, f64)> {
            pts.iter()
                .map(|p| b_pose.world_from_agent(f64::from(p[0]), f64::from(p[1])))
                .collect()
        };
        let a_future: Vec<(f64, f64)> =
            e.a.future_valid
                .iter()
                .enumerate()
                .filter(|(_, v)| **v)
                .map(|(s, _)| {
                    (
                        f64::from(e.a.future_xy_m[2 * s]),
                        f64::from(e.a.future_xy_m[2 * s + 1]),
                    )
                })
                .collect();
        let b_logged: Vec<[f32; 2]> = e.futures_b[0]
            .iter()
            .zip(&e.logged_valid)
            .filter(|(_, v)| **v)
            .map(|(p, _)| *p)
            .collect();
        let line = |label: String, rgb: (u8, u8, u8), points: Vec<(f64, f64)>| scbg_plot::Line {
            label,
            rgb,
            points,
        };
        let mut lines = vec![
            line("A logged".into(), (220, 20, 30), a_future),
            line("B logged".into(), (60, 60, 60), in_a(&b_logged)),
        ];
        for (qi, q) in quantiles.iter().enumerate() {
            let j = EVAL_QUANTILES
                .iter()
                .position(|x| (x - q).abs() < 1e-6)
                .expect("quantile in the evaluation grid");
            let shade = 230 - (qi as u8) * 45;
            lines.push(line(
                format!(
                    "B q={q:.1} (ψ {:+.3}, A {:.2} m/s)",
                    measured.psi[0][j], measured.e_cond[0][j]
                ),
                (shade / 3, shade / 2 + 40, 255 - qi as u8 * 20),
                in_a(&measured.futures_b[0][j]),
            ));
        }
        let background: Vec<Vec<(f64, f64)>> = roads
            .get(e.scenario_id.as_str())
            .into_iter()
            .flatten()
            .map(|line| {
                line.iter()
                    .map(|&(x, y)| e.a.world_from_agent.agent_from_world(x, y))
                    .collect()
            })
            .collect();
        let name = format!("fig5a_case{}.png", k + 1);
        scbg_plot::trajectories(
            &background,
            &lines,
            &format!(
                "Fig. 5a case {}: {} ({} variant, A's frame)",
                k + 1,
                e.scenario_id,
                last.checkpoint.variant.name()
            ),
            &dir.join(&name),
        )?;
        written.push(name);
    }
    if !speed_series.is_empty() {
        let name = "fig5b_quantile_speed.png";
        scbg_plot::line_chart(
            &speed_series,
            "input quantile",
            "A's expected average speed given ŷ_B (m/s)",
            "Fig. 5b: quantile → A's expected speed",
            &dir.join(name),
        )?;
        written.push(name.to_string());
    }
    Ok(written)
}

/// Polylines, world frame, metres.
type Polylines = Vec<Vec<(f64, f64)>>;

/// World-frame road polylines of the given scenarios, by scenario id (one scan of the cache).
fn case_roads<'a>(
    data: &Path,
    ids: impl Iterator<Item = &'a str>,
) -> anyhow::Result<std::collections::HashMap<&'a str, Polylines>> {
    let mut wanted: std::collections::HashMap<&str, Polylines> =
        ids.map(|id| (id, Vec::new())).collect();
    if wanted.is_empty() {
        return Ok(wanted);
    }
    let dataset = scbg_features::cache::PreparedDataset::open(data)?;
    let mut found = 0;
    for i in 0..dataset.len() {
        let scene = dataset.scene(i)?;
        let Some(road) = wanted.get_mut(scene.scenario_id.as_str()) else {
            continue;
        };
        let [ox, oy] = scene.origin_xy_m;
        *road = scene
            .road
            .iter()
            .map(|r| {
                r.xy_m
                    .iter()
                    .map(|p| (ox + f64::from(p[0]), oy + f64::from(p[1])))
                    .collect()
            })
            .collect();
        found += 1;
        if found == wanted.len() {
            break;
        }
    }
    Ok(wanted)
}
