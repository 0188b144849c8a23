//! `eval sim`'s figures.

use std::path::Path;

use super::{QuantileSim, SimEval};

/// The figures: A's realised speed and realised courtesy against the quantile
/// (`sim_courtesy.png`), WOSAC meta-metric against the quantile with the baselines
/// (`sim_realism.png`); none without a simulated scene.
pub fn write_figures(eval: &SimEval, dir: &Path) -> anyhow::Result<()> {
    use scbg_plot::Series;
    std::fs::create_dir_all(dir)?;
    if eval.curve.per_quantile.is_empty() {
        return Ok(());
    }
    let q = |f: &dyn Fn(&QuantileSim) -> f64| -> Vec<(f64, f64)> {
        eval.curve
            .per_quantile
            .iter()
            .map(|r| (f64::from(r.quantile), f(r)))
            .collect()
    };
    let mut courtesy_series = vec![
        Series {
            label: "A's realised avg speed − at q=0.5 (m/s)".into(),
            points: q(&|r| r.realised_courtesy_mps),
            band: Some(
                eval.curve
                    .per_quantile
                    .iter()
                    .map(|r| r.realised_courtesy_std_mps)
                    .collect(),
            ),
        },
        Series {
            label: "B collision rate".into(),
            points: q(&|r| r.b_collision_rate),
            band: None,
        },
    ];
    if let Some(world) = &eval.world_knob {
        courtesy_series.push(Series {
            label: "same, the world's own B at courtesy c = q (m/s)".into(),
            points: world
                .per_quantile
                .iter()
                .map(|r| (f64::from(r.quantile), r.realised_courtesy_mps))
                .collect(),
            band: None,
        });
    }
    scbg_plot::line_chart(
        &courtesy_series,
        "courtesy quantile of B",
        "m/s  |  rate",
        "closed loop: realised courtesy toward A",
        &dir.join("sim_courtesy.png"),
    )?;
    let mut series = vec![Series {
        label: "scbg (32 rollouts around q)".into(),
        points: eval
            .curve
            .per_quantile
            .iter()
            .filter_map(|r| {
                r.wosac
                    .as_ref()
                    .map(|w| (f64::from(r.quantile), f64::from(w.metametric)))
            })
            .collect(),
        band: None,
    }];
    let prior = eval
        .wosac_scbg_prior
        .as_ref()
        .map(|w| ("scbg, knob drawn from its prior".to_string(), w));
    let baselines = eval
        .baselines
        .iter()
        .filter_map(|(name, b)| Some((name.clone(), b.wosac.as_ref()?)));
    for (name, w) in prior.into_iter().chain(baselines) {
        series.push(Series {
            label: name,
            points: vec![
                (0.1, f64::from(w.metametric)),
                (0.9, f64::from(w.metametric)),
            ],
            band: None,
        });
    }
    if series[0].points.is_empty() {
        return Ok(());
    }
    scbg_plot::line_chart(
        &series,
        "courtesy quantile of B",
        "WOSAC meta-metric",
        "closed loop: realism against the courtesy knob",
        &dir.join("sim_realism.png"),
    )?;
    Ok(())
}
