//! The demo's acceptance checks, read from the report JSON's seed means, and the leaf-by-leaf
//! seed mean and spread of that JSON.

use std::collections::BTreeMap;

/// One acceptance point as measured.
#[derive(Debug, Clone, PartialEq)]
pub struct Check {
    /// Stable key in report.json's `checks`.
    pub key: &'static str,
    /// Whether it holds.
    pub passed: bool,
    /// What was compared, with the numbers.
    pub text: String,
}

/// The demo's acceptance checks of control and label fidelity on its held-out split, as
/// measured on the seed means (`variants` and `truth_control` as report.json has them); a
/// point whose inputs are missing (e.g. fidelity on real data) is left out.
pub fn acceptance_checks(
    variants: &serde_json::Value,
    truth_control: &serde_json::Value,
    fidelity: Option<&crate::fidelity::Fidelity>,
    closed_loop: Option<&crate::sim_eval::SimEval>,
    closed_loop_ranked: Option<&crate::sim_eval::SimEval>,
) -> Vec<Check> {
    use crate::fidelity::POOLED;
    // A number of the report JSON by path; NaN when missing or null.
    let num = |v: &serde_json::Value, path: &[&str]| -> f64 {
        path.iter()
            .try_fold(v, |v, k| v.get(*k))
            .and_then(serde_json::Value::as_f64)
            .unwrap_or(f64::NAN)
    };
    let mut out = Vec::new();
    let families = |m: &BTreeMap<String, Option<f64>>| -> Vec<(String, f64)> {
        m.iter()
            .filter(|(k, _)| k.as_str() != POOLED)
            .map(|(k, v)| (k.clone(), v.unwrap_or(f64::NAN)))
            .collect()
    };
    let listing = |v: &[(String, f64)]| {
        v.iter()
            .map(|(k, x)| format!("{k} {x:.3}"))
            .collect::<Vec<_>>()
            .join(", ")
    };
    if let Some(f) = fidelity {
        let consistency: Vec<(String, f64)> = f
            .oracle_consistency
            .iter()
            .filter(|(k, _)| k.as_str() != POOLED)
            .map(|(k, (p, _))| (k.clone(), *p))
            .collect();
        out.push(Check {
            key: "oracle_consistency_95",
            passed: !consistency.is_empty() && consistency.iter().all(|(_, p)| *p >= 0.95),
            text: format!(
                "oracle: replaying B's logged future reproduces A's speed within 0.2 m/s in ≥ 95 % of scenes per family ({})",
                listing(&consistency)
            ),
        });
        let logged: BTreeMap<String, Option<f64>> = f
            .logged
            .iter()
            .map(|(k, a)| (k.clone(), a.spearman))
            .collect();
        let logged = families(&logged);
        out.push(Check {
            key: "fidelity_logged_spearman_0_7",
            passed: !logged.is_empty() && logged.iter().all(|(_, r)| *r >= 0.7),
            text: format!(
                "Spearman(ψ_label, ψ_true) ≥ 0.7 on logged futures in every family ({})",
                listing(&logged)
            ),
        });
        let sampled = f
            .sampled
            .get(POOLED)
            .and_then(|a| a.spearman)
            .unwrap_or(f64::NAN);
        out.push(Check {
            key: "fidelity_sampled_spearman_0_7",
            passed: sampled >= 0.7,
            text: format!(
                "Spearman(ψ_label, ψ_true) ≥ 0.7 pooled on sampled futures ({sampled:.3})"
            ),
        });
        let ratio = f
            .logged
            .get(POOLED)
            .and_then(|a| a.spread_ratio)
            .unwrap_or(f64::NAN);
        out.push(Check {
            key: "fidelity_spread_ratio",
            passed: (0.5..=2.0).contains(&ratio),
            text: format!(
                "spread ratio std(ψ_label)/std(ψ_true) of logged futures within [0.5, 2] ({ratio:.3})"
            ),
        });
        let latent = families(&f.spearman_label_latent);
        out.push(Check {
            key: "label_latent_spearman_0_5",
            passed: !latent.is_empty() && latent.iter().all(|(_, r)| *r >= 0.5),
            text: format!(
                "Spearman(ψ_logged, c) ≥ 0.5 in every family ({})",
                listing(&latent)
            ),
        });
    }
    if let Some(t) = truth_control.get("full") {
        let rho = t.get("spearman_quantile_psi_true");
        let pooled = rho.map_or(f64::NAN, |r| num(r, &[POOLED]));
        let per: Vec<(String, f64)> = rho
            .and_then(serde_json::Value::as_object)
            .map(|m| {
                m.iter()
                    .filter(|(k, _)| k.as_str() != POOLED)
                    .map(|(k, v)| (k.clone(), v.as_f64().unwrap_or(f64::NAN)))
                    .collect()
            })
            .unwrap_or_default();
        out.push(Check {
            key: "truth_control_spearman",
            passed: pooled >= 0.6 && !per.is_empty() && per.iter().all(|(_, r)| *r >= 0.4),
            text: format!(
                "full: Spearman(quantile, ψ_true of the generated future) ≥ 0.6 pooled ({pooled:.3}; each example's futures ordered to rise with the quantile {:.3}) and ≥ 0.4 per family ({})",
                num(t, &["spearman_quantile_psi_true_ordered", POOLED]),
                listing(&per)
            ),
        });
    }
    if variants.get("full").is_some() {
        let full = |path: &[&str]| num(&variants["full"], path);
        let (range, arb) = (
            full(&["courtesy_mse_range", "mean"]),
            full(&["courtesy_mse_arbitrary", "mean"]),
        );
        out.push(Check {
            key: "range_below_arbitrary",
            passed: range < arb,
            text: format!(
                "full: CourtesyMSE(range) {range:.3e} < CourtesyMSE(arbitrary) {arb:.3e}"
            ),
        });
        let corr = full(&["corr_quantile"]);
        out.push(Check {
            key: "corr_quantile_at_least_0_6",
            passed: corr >= 0.6,
            text: format!("full: corr(quantile, courtesy) {corr:.3} ≥ 0.6"),
        });
        let high = full(&["corr_quantile_high"]);
        out.push(Check {
            key: "corr_quantile_high_at_least_0_8",
            passed: high >= 0.8,
            text: format!("full: corr(quantile, courtesy) on high-|ψ| pairs {high:.3} ≥ 0.8"),
        });
        if variants.get("baseline").is_some() {
            let base = |path: &[&str]| num(&variants["baseline"], path);
            let (fd, bd) = (
                full(&["courtesy_mse_data", "mean"]),
                base(&["courtesy_mse_data", "mean"]),
            );
            out.push(Check {
                key: "full_courtesy_mse_data_no_worse",
                passed: fd <= bd,
                text: format!("CourtesyMSE(data): full {fd:.3e} ≤ baseline {bd:.3e}"),
            });
            let (ft, bt) = (full(&["traj_ade", "mean"]), base(&["traj_ade", "mean"]));
            out.push(Check {
                key: "full_traj_ade_no_worse",
                passed: ft <= bt,
                text: format!("TrajADE: full {ft:.3} m ≤ baseline {bt:.3} m"),
            });
        }
    }
    if let Some(c) = closed_loop {
        closed_loop_checks(c, &GENERATOR_KEYS, &mut out);
    }
    if let Some(c) = closed_loop_ranked {
        closed_loop_checks(c, &RANKED_KEYS, &mut out);
    }
    out
}

/// Mean and population standard deviation, leaf by leaf, of JSON values of one layout (the
/// report of each seed): objects by key, arrays by position, numbers averaged over the seeds
/// that have one (`null` where none has); other leaves are taken from the first value.
pub fn seed_mean_std(values: &[serde_json::Value]) -> (serde_json::Value, serde_json::Value) {
    use serde_json::Value;
    let Some(first) = values.first() else {
        return (Value::Null, Value::Null);
    };
    match first {
        Value::Object(map) => {
            let (mut mean, mut std) = (serde_json::Map::new(), serde_json::Map::new());
            for key in map.keys() {
                let children: Vec<Value> = values
                    .iter()
                    .map(|v| v.get(key).cloned().unwrap_or(Value::Null))
                    .collect();
                let (m, s) = seed_mean_std(&children);
                mean.insert(key.clone(), m);
                std.insert(key.clone(), s);
            }
            (Value::Object(mean), Value::Object(std))
        }
        Value::Array(items) => {
            let (mut mean, mut std) = (Vec::new(), Vec::new());
            for i in 0..items.len() {
                let children: Vec<Value> = values
                    .iter()
                    .map(|v| v.get(i).cloned().unwrap_or(Value::Null))
                    .collect();
                let (m, s) = seed_mean_std(&children);
                mean.push(m);
                std.push(s);
            }
            (Value::Array(mean), Value::Array(std))
        }
        Value::Number(_) | Value::Null => {
            let nums: Vec<f64> = values.iter().filter_map(Value::as_f64).collect();
            match scbg_generator::eval::MeanStd::of(&nums) {
                Some(m) => (serde_json::json!(m.mean), serde_json::json!(m.std)),
                None => (Value::Null, Value::Null),
            }
        }
        other => (other.clone(), Value::Null),
    }
}

/// The report keys of one closed-loop policy's checks.
struct ClosedLoopKeys {
    /// How the policy is named in the checks' texts.
    label: &'static str,
    spearman: &'static str,
    curve_rises: &'static str,
    collision: &'static str,
    wosac: &'static str,
    /// `None`: the policy is not scored with the knob drawn from its prior.
    wosac_prior: Option<&'static str>,
}

/// The generator's closed-loop checks.
const GENERATOR_KEYS: ClosedLoopKeys = ClosedLoopKeys {
    label: "",
    spearman: "closed_loop_spearman_0_6",
    curve_rises: "closed_loop_curve_rises",
    collision: "closed_loop_b_collision_2pct",
    wosac: "closed_loop_wosac_above_baselines",
    wosac_prior: Some("closed_loop_wosac_prior_above_baselines"),
};

/// The same points with sample and rank driving B.
const RANKED_KEYS: ClosedLoopKeys = ClosedLoopKeys {
    label: " (sample and rank)",
    spearman: "closed_loop_ranked_spearman_0_6",
    curve_rises: "closed_loop_ranked_curve_rises",
    collision: "closed_loop_ranked_b_collision_2pct",
    wosac: "closed_loop_ranked_wosac_above_baselines",
    wosac_prior: None,
};

/// The closed-loop acceptance points of one policy's evaluation.
fn closed_loop_checks(c: &crate::sim_eval::SimEval, keys: &ClosedLoopKeys, out: &mut Vec<Check>) {
    let pooled_value = |m: &crate::sim_eval::PerFamily| m.get("all").copied().flatten();
    let pooled_of =
        |m: &crate::sim_eval::PerFamily| pooled_value(m).map_or("-".into(), |r| format!("{r:.3}"));
    let pooled = pooled_value(&c.curve.spearman_quantile_a_speed);
    out.push(Check {
        key: keys.spearman,
        passed: pooled.is_some_and(|r| r >= 0.6),
        text: format!(
            "closed loop{}: Spearman(quantile, A's realised average speed) ≥ 0.6 pooled ({}; with each scene's level removed {}; within a scene {}; each scene's speeds ordered to rise with the quantile {}){}",
            keys.label,
            crate::sim_eval::fmt_or_na(pooled, 3),
            pooled_of(&c.curve.spearman_quantile_realised_courtesy),
            pooled_of(&c.curve.spearman_within_scene_a_speed),
            pooled_of(&c.curve.spearman_quantile_a_speed_ordered),
            c.world_knob.as_ref().map_or(String::new(), |w| format!(
                "; the world's own B at courtesy c = q on the same scenes: {} pooled, {} with each scene's level removed, {} within a scene, {} ordered",
                pooled_of(&w.spearman_quantile_a_speed),
                pooled_of(&w.spearman_quantile_realised_courtesy),
                pooled_of(&w.spearman_within_scene_a_speed),
                pooled_of(&w.spearman_quantile_a_speed_ordered)
            ))
        ),
    });
    out.push(Check {
        key: keys.curve_rises,
        passed: c.curve.a_speed_curve_rises == Some(true),
        text: format!(
            "closed loop{}: A's mean realised speed rises with the quantile ({})",
            keys.label,
            c.curve
                .per_quantile
                .iter()
                .map(|r| format!("{:.2}", r.a_avg_speed_mps))
                .collect::<Vec<_>>()
                .join(" → ")
        ),
    });
    out.push(Check {
        key: keys.collision,
        passed: c.curve.max_b_collision_rate.is_some_and(|r| r <= 0.02),
        text: format!(
            "closed loop{}: B's collision rate ≤ 2 % at every quantile (max {}; {} in the scenes where B starts clear of every other agent)",
            keys.label,
            crate::sim_eval::fmt_or_na(c.curve.max_b_collision_rate, 3),
            crate::sim_eval::fmt_or_na(c.curve.max_b_collision_rate_clear_start, 3)
        ),
    });
    let meta = |w: Option<&crate::sim_eval::WosacSummary>| {
        w.map_or("-".into(), |w| format!("{:.4}", w.metametric))
    };
    out.push(Check {
        key: keys.wosac,
        passed: c.wosac_above_baselines == Some(true),
        text: format!(
            "closed loop{}: WOSAC meta-metric of scbg {} above constant velocity {} and IDM-only {} (log replay {})",
            keys.label,
            meta(c.wosac_scbg.as_ref()),
            meta(c.baselines.get("constant_velocity").and_then(|b| b.wosac.as_ref())),
            meta(c.baselines.get("idm_only").and_then(|b| b.wosac.as_ref())),
            meta(c.baselines.get("log_replay").and_then(|b| b.wosac.as_ref())),
        ),
    });
    if let Some(key) = keys.wosac_prior {
        out.push(Check {
            key,
            passed: c.wosac_prior_above_baselines == Some(true),
            text: format!(
                "closed loop{}: WOSAC meta-metric of scbg with the knob drawn from its prior {} above constant velocity and IDM-only (minus IDM-only per scene {})",
                keys.label,
                meta(c.wosac_scbg_prior.as_ref()),
                c.wosac_prior_minus_idm
                    .as_ref()
                    .map_or("-".into(), |d| format!("{:+.4} ± {:.4} s.e.", d.mean, d.std_error)),
            ),
        });
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde_json::json;

    #[test]
    fn seed_means_leaf_by_leaf() {
        let (m, s) = seed_mean_std(&[
            json!({"a": {"mean": 1.0}, "q": [1.0, 2.0], "r": null, "name": "x"}),
            json!({"a": {"mean": 3.0}, "q": [3.0, 2.0], "r": 0.5, "name": "x"}),
        ]);
        assert_eq!(
            m,
            json!({"a": {"mean": 2.0}, "q": [2.0, 2.0], "r": 0.5, "name": "x"})
        );
        assert_eq!(
            s,
            json!({"a": {"mean": 1.0}, "q": [1.0, 0.0], "r": 0.0, "name": null})
        );
    }

    #[test]
    fn checks_read_the_seed_means() {
        let v = json!({
            "full": {"courtesy_mse_range": {"mean": 1.0}, "courtesy_mse_arbitrary": {"mean": 2.0},
                     "corr_quantile": 0.7, "corr_quantile_high": 0.5,
                     "courtesy_mse_data": {"mean": 1.0}, "traj_ade": {"mean": 2.0}},
            "baseline": {"courtesy_mse_data": {"mean": 2.0}, "traj_ade": {"mean": 1.0}}
        });
        let t = json!({"full": {"spearman_quantile_psi_true": {"all": 0.7, "merge": 0.5, "cutin": 0.3}}});
        let checks: BTreeMap<&str, bool> = acceptance_checks(&v, &t, None, None, None)
            .into_iter()
            .map(|c| (c.key, c.passed))
            .collect();
        assert!(checks["range_below_arbitrary"]);
        assert!(checks["corr_quantile_at_least_0_6"]);
        assert!(!checks["corr_quantile_high_at_least_0_8"]);
        assert!(checks["full_courtesy_mse_data_no_worse"]);
        assert!(!checks["full_traj_ade_no_worse"]);
        assert!(!checks["truth_control_spearman"]);
        assert!(!checks.contains_key("fidelity_logged_spearman_0_7"));
    }
}
