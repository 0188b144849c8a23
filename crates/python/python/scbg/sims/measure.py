"""Does the courtesy knob do what it says inside a foreign simulator? The paired measurement.

For every scenario and seed, the same episode (same start, same takeover step, same A and B) is
run once per arm: B driven by scbg at courtesy quantiles 0.1 … 0.9, and B driven by the
simulator's own model at five settings of its own courtesy parameter from low to high (the
yardstick; a right of way graded by A's lead at the conflict) and at its default. The knob is
judged *within* each episode (only the quantile changes), against what the simulator's own
idea of courtesy does to A in the same episodes: its effect, and its own within-episode
Spearman, the ceiling of what a monotone courtesy setting reaches there.

    python -m scbg.sims.measure MODEL [--scenarios merge-v0 sumo-onramp ...] [--episodes 30]
                                      [--jobs N] [--out DIR]

writes ``DIR/results.json`` (every episode of every arm), ``DIR/table.md`` and
``DIR/figure.png`` (A's paired mean speed against the quantile, one panel per scenario, the
yardstick's settings from low to high beside it; needs matplotlib), and prints the table.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor

import numpy as np

QUANTILES = (0.1, 0.3, 0.5, 0.7, 0.9)
# The yardstick's settings, as fractions of the way from its low to its high setting (a right of
# way, graded by A's lead at the conflict; one that is not graded has the two ends alone).
YARDSTICK_LEVELS = ("low", 0.25, 0.5, 0.75, "high")
RESPONSE_MPS = 0.05  # A "responds" when its speeds differ by more than this across the arms


def _module(scenario):
    from . import highway, sumo

    for mod in (highway, sumo):
        if scenario in mod.SCENARIOS:
            return mod
    known = sorted(list(highway.SCENARIOS) + list(sumo.SCENARIOS))
    raise ValueError(f"unknown scenario {scenario!r}: expected one of {known}")


def all_scenarios():
    from . import highway, sumo

    return list(highway.SCENARIOS) + list(sumo.SCENARIOS)


def yardstick_levels(scenario):
    """The yardstick's settings measured in ``scenario``: five where it is graded."""
    from . import graded

    return YARDSTICK_LEVELS if graded(yardsticks_of([scenario])[scenario]) else ("low", "high")


def arms(scenario):
    """Every arm of one episode of ``scenario``, in order."""
    out = [{"kind": "scbg", "quantile": q} for q in QUANTILES]
    out += [{"kind": "yardstick", "level": level} for level in yardstick_levels(scenario)]
    return out + [{"kind": "default"}]


def arm_name(arm):
    if arm["kind"] == "scbg":
        return f"q{arm['quantile']:.1f}"
    if arm["kind"] == "yardstick":
        level = arm["level"]
        return f"yardstick_{level}" if isinstance(level, str) else f"yardstick_{level:.2f}"
    return "default"


_MODEL = None


def _load(model_dir, policy="generator"):
    global _MODEL
    import scbg

    _MODEL = scbg.Model(model_dir, policy=policy) if model_dir else None


def run_seed(scenario, seed):
    """Every arm of one seed: ``{"seed", "scenario", "arms": {name: record}}``, or the reason
    the seed was skipped."""
    import warnings

    warnings.filterwarnings("ignore")
    mod = _module(scenario)
    out = {"scenario": scenario, "seed": seed, "arms": {}}
    try:
        for arm in arms(scenario):
            out["arms"][arm_name(arm)] = mod.episode(_MODEL, scenario, seed, arm)
    except RuntimeError as e:  # the seed never brought A and B together: a counted skip
        out = {"scenario": scenario, "seed": seed, "skipped": str(e)}
    return out


def paired_effect(model, scenario, seeds, low=0.1, high=0.9):
    """A's speed with B at quantile ``high`` minus at ``low``, per seed (each pair of episodes the
    same but for the quantile), and the share of B's followed plan points on the road over both.
    The quick form of the measurement, for a test or a first look."""
    mod = _module(scenario)
    deltas, on, points = [], 0, 0
    for seed in seeds:
        lo = mod.episode(model, scenario, seed, {"kind": "scbg", "quantile": low})
        hi = mod.episode(model, scenario, seed, {"kind": "scbg", "quantile": high})
        deltas.append(hi["a_speed_mps"] - lo["a_speed_mps"])
        on += lo["b_plan_points_on_road"] + hi["b_plan_points_on_road"]
        points += lo["b_plan_points"] + hi["b_plan_points"]
    return deltas, on / points if points else float("nan")


def spearman(x, y):
    """Spearman's rank correlation with average ranks for ties; NaN when either is constant."""

    def ranks(v):
        v = np.asarray(v, float)
        order = np.argsort(v, kind="mergesort")
        r = np.empty(len(v))
        i = 0
        while i < len(v):
            j = i
            while j + 1 < len(v) and v[order[j + 1]] == v[order[i]]:
                j += 1
            r[order[i:j + 1]] = (i + j) / 2.0
            i = j + 1
        return r

    rx, ry = ranks(x), ranks(y)
    if rx.std() == 0 or ry.std() == 0:
        return float("nan")
    return float(np.corrcoef(rx, ry)[0, 1])


def _mean_ci(v):
    v = np.asarray(v, float)
    if len(v) == 0:
        return float("nan"), float("nan")
    half = 1.96 * v.std(ddof=1) / math.sqrt(len(v)) if len(v) > 1 else float("nan")
    return float(v.mean()), float(half)


def summarise(seeds):
    """One scenario's numbers from its seeds' records (pure: the table and the tests use it)."""
    done = [s for s in seeds if "arms" in s]
    qs = [arm_name({"kind": "scbg", "quantile": q}) for q in QUANTILES]
    # The yardstick's arms, from its low to its high setting.
    ys_names = sorted({n for s in done for n in s["arms"] if n.startswith("yardstick_")}, key=_level_order)
    speed = {name: np.array([s["arms"][name]["a_speed_mps"] for s in done])
             for name in qs + ys_names + ["default"]}
    per_episode = np.array([[s["arms"][n]["a_speed_mps"] for n in qs] for s in done]).reshape(len(done), len(qs))
    responsive = (per_episode.max(axis=1) - per_episode.min(axis=1) > RESPONSE_MPS) if len(done) else np.zeros(0, bool)
    rhos = [spearman(QUANTILES, row) for row, r in zip(per_episode, responsive) if r]
    # The same for the yardstick where it has more than two settings (its own ceiling).
    ys_rows = np.array([[s["arms"][n]["a_speed_mps"] for n in ys_names] for s in done]).reshape(len(done), len(ys_names))
    ys_responsive = (ys_rows.max(axis=1) - ys_rows.min(axis=1) > RESPONSE_MPS) if len(done) else np.zeros(0, bool)
    ys_rhos = ([spearman(range(len(ys_names)), row) for row, r in zip(ys_rows, ys_responsive) if r]
               if len(ys_names) > 2 else [])
    ys_delta = speed["yardstick_high"] - speed["yardstick_low"]
    effect, effect_ci = _mean_ci(speed[qs[-1]] - speed[qs[0]])
    ys_effect, ys_ci = _mean_ci(ys_delta)

    def clean(low, high):  # the episodes where B collided in neither end arm
        return np.array([not (s["arms"][low]["b_collided"] or s["arms"][high]["b_collided"]) for s in done], bool)

    clean_effect, _ = _mean_ci((speed[qs[-1]] - speed[qs[0]])[clean(qs[0], qs[-1])])
    ys_clean_effect, _ = _mean_ci(ys_delta[clean("yardstick_low", "yardstick_high")])

    def rate(names, key):
        vals = [bool(s["arms"][n][key]) for s in done for n in names]
        return float(np.mean(vals)) if vals else float("nan")

    plan_pts = sum(s["arms"][n]["b_plan_points"] for s in done for n in qs)
    plan_on = sum(s["arms"][n]["b_plan_points_on_road"] for s in done for n in qs)
    steps = sum(s["arms"][n]["b_steps"] for s in done for n in qs)
    steps_on = sum(s["arms"][n]["b_steps_on_road"] for s in done for n in qs)
    reached = [s["arms"][n].get("b_reached_goal") for s in done for n in qs]
    reached = [r for r in reached if r is not None]
    return {
        "episodes": len(done),
        "skipped": [{"seed": s["seed"], "reason": s["skipped"]} for s in seeds if "skipped" in s],
        "a_speed_mps": {n: float(v.mean()) if len(v) else float("nan") for n, v in speed.items()},
        "effect_mps": effect,
        "effect_ci95_mps": effect_ci,
        "yardstick_effect_mps": ys_effect,
        "yardstick_effect_ci95_mps": ys_ci,
        "effect_collision_free_mps": clean_effect,
        "yardstick_effect_collision_free_mps": ys_clean_effect,
        "responsive_share": float(responsive.mean()) if len(done) else float("nan"),
        "yardstick_responsive_share": float(ys_responsive.mean()) if len(done) else float("nan"),
        "spearman_responsive": _nanmean(rhos),
        "yardstick_spearman_responsive": _nanmean(ys_rhos),
        "b_collision_rate": rate(qs, "b_collided"),
        "yardstick_b_collision_rate": rate(ys_names, "b_collided"),
        "b_plan_on_road_share": plan_on / plan_pts if plan_pts else float("nan"),
        "b_on_road_share": steps_on / steps if steps else float("nan"),
        "b_reached_goal_share": float(np.mean(reached)) if reached else None,
    }


def _level_order(name):
    """Sorts yardstick arm names (``yardstick_low``, ``yardstick_0.25``, …) from low to high."""
    level = name.removeprefix("yardstick_")
    return {"low": 0.0, "high": 1.0}[level] if level in ("low", "high") else float(level)


def _nanmean(v):
    return float(np.nanmean(v)) if v and not all(map(math.isnan, v)) else float("nan")


def _f(x, fmt="{:.2f}"):
    return "n/a" if x is None or (isinstance(x, float) and math.isnan(x)) else fmt.format(x)


def table(summaries, yardsticks):
    head = ("| scenario | episodes | A at q 0.1 / 0.5 / 0.9 (m/s) | effect q0.9−q0.1 (m/s) | "
            "yardstick | yardstick effect high−low (m/s) | effect without B's collisions (scbg / yardstick) | "
            "responsive (scbg / yardstick) | "
            "Spearman, responsive (scbg / yardstick) | B collisions (scbg / yardstick) | "
            "B plan on road | B on road |")
    rows = [head, "|" + "---|" * 12]
    for name, s in summaries.items():
        a = s["a_speed_mps"]
        ys = yardsticks.get(name, {})
        rows.append(
            f"| {name} | {s['episodes']} | {_f(a['q0.1'])} / {_f(a['q0.5'])} / {_f(a['q0.9'])} | "
            f"{_f(s['effect_mps'], '{:+.2f}')} ± {_f(s['effect_ci95_mps'])} | "
            f"{ys.get('parameter', '?')} {ys.get('low', '')} → {ys.get('high', '')} | "
            f"{_f(s['yardstick_effect_mps'], '{:+.2f}')} ± {_f(s['yardstick_effect_ci95_mps'])} | "
            f"{_f(s['effect_collision_free_mps'], '{:+.2f}')} / {_f(s['yardstick_effect_collision_free_mps'], '{:+.2f}')} | "
            f"{_f(s['responsive_share'], '{:.0%}')} / {_f(s['yardstick_responsive_share'], '{:.0%}')} | "
            f"{_f(s['spearman_responsive'])} / {_f(s.get('yardstick_spearman_responsive'))} | "
            f"{_f(s['b_collision_rate'], '{:.1%}')} / {_f(s['yardstick_b_collision_rate'], '{:.1%}')} | "
            f"{_f(s['b_plan_on_road_share'], '{:.1%}')} | {_f(s['b_on_road_share'], '{:.1%}')} |")
    return "\n".join(rows)


def figure(summaries, path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    n = len(summaries)
    cols = min(4, n)
    rows = -(-n // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.8 * rows), squeeze=False)
    for ax in axes.flat[n:]:
        ax.axis("off")
    for ax, (name, s) in zip(axes.flat, summaries.items()):
        a = s["a_speed_mps"]
        ax.plot(QUANTILES, [a[arm_name({"kind": "scbg", "quantile": q})] for q in QUANTILES],
                "o-", label="scbg B at quantile q")
        own = sorted((n for n in a if n.startswith("yardstick_")), key=_level_order)
        ax.plot(np.linspace(QUANTILES[0], QUANTILES[-1], len(own)), [a[n] for n in own], "s--",
                color="tab:green", label="own model, low → high courtesy")
        ax.set_title(f"{name} ({s['episodes']} ep.)", fontsize=9)
        ax.set_xlabel("B's courtesy quantile", fontsize=8)
        ax.set_ylabel("A's mean speed, 8 s (m/s)", fontsize=8)
        ax.tick_params(labelsize=7)
    axes.flat[0].legend(fontsize=6)
    fig.tight_layout()
    fig.savefig(path, dpi=110)


def yardsticks_of(names):
    from . import highway, sumo

    out = {}
    for n in names:
        for mod in (highway, sumo):
            if n in mod.YARDSTICKS:
                out[n] = mod.YARDSTICKS[n]
    return out


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("model", help="an scbg generator folder (out/demo/generator_full) or ensemble folder (models/courtesy)")
    ap.add_argument("--scenarios", nargs="+", help="default: every scenario of every simulator")
    ap.add_argument("--episodes", type=int, default=30, help="seeds per scenario")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--out", default="out/sims")
    ap.add_argument("--policy", choices=["generator", "ranked"], default="generator",
                    help="how a courtesy becomes B's future: the learned generator, or sample "
                    "and rank (B's sampled futures and their lane moves, ranked by ψ label)")
    args = ap.parse_args(argv)
    scenarios = args.scenarios or all_scenarios()
    for s in scenarios:
        _module(s)  # unknown names fail before anything runs
    os.makedirs(args.out, exist_ok=True)
    started = time.time()
    tasks = [(s, seed) for s in scenarios for seed in range(args.episodes)]
    import multiprocessing

    ctx = multiprocessing.get_context("spawn")  # a fresh interpreter per worker: highway-env
    with ProcessPoolExecutor(args.jobs, mp_context=ctx, initializer=_load,
                             initargs=(args.model, args.policy)) as pool:
        results = list(pool.map(run_seed, *zip(*tasks)))
    by_scenario = {s: [r for r in results if r["scenario"] == s] for s in scenarios}
    summaries = {s: summarise(v) for s, v in by_scenario.items()}
    ys = yardsticks_of(scenarios)
    text = table(summaries, ys)
    seconds = time.time() - started
    with open(os.path.join(args.out, "results.json"), "w") as f:
        json.dump({"model": args.model, "policy": args.policy, "quantiles": QUANTILES,
                   "seconds": seconds,
                   "yardsticks": ys, "summaries": summaries, "episodes": results}, f, indent=1)
    with open(os.path.join(args.out, "table.md"), "w") as f:
        f.write(text + "\n")
    try:
        figure(summaries, os.path.join(args.out, "figure.png"))
    except ImportError:
        print("matplotlib is not installed: no figure", file=sys.stderr)
    print(text)
    print(f"{len(tasks)} seeds in {seconds:.0f} s; {args.out}/results.json")


if __name__ == "__main__":
    main()
