#!/usr/bin/env python3
"""Runs scbg's shardable jobs as Ray tasks: one task per shard, each running the `scbg` CLI.

    python deploy/ray/scbg_ray.py [--address auto] [--scbg PATH] [--cpus-per-task 1] STAGE ...

Stages (the extra arguments after `--` go to every shard's scbg command unchanged):

    prepare --input GLOB... --out CACHE --shards N   # scbg data prepare --shard-index i --num-shards N
    label   --model P --data CACHE --out DIR --shards N
    sim     --model G --data FILE_OR_DIR... --out DIR --shards N   # scbg eval sim, files split

Merging follows each command's own contract: `prepare` and `label` write their shards into one
shared output folder (the file names carry the shard), then one `scbg` run without
`--num-shards` finds every shard finished, reads them back, and writes the manifest (prepare)
or the summary (label). `sim` shards write `DIR/shard-i/eval_sim.json`; the merge sums the
scene counts, averages the per-quantile means weighted by scenes, takes the worst collision
rate, and keeps every shard's report (`DIR/eval_sim_shards.json`). Each stage also writes
`ray_<stage>.json`: per task, the command, its exit status and wall time.

Ray is the engine: `ray.init(address=...)` joins a running cluster (`--address auto`, or a
`ray://` address), or starts a local one. Every task gets `--cpus-per-task` CPUs and scbg's
thread pool is pinned to that many (`RAYON_NUM_THREADS`), so tasks do not oversubscribe a node.
The output folders must be on storage every node sees (NFS, a mounted bucket).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import ray


@ray.remote
def run_scbg(scbg: str, argv: list[str], threads: int) -> dict:
    """One shard: runs `scbg argv` and reports how it went (never raises)."""
    env = dict(os.environ, RAYON_NUM_THREADS=str(threads), SCBG_LOG="warn")
    started = time.time()
    proc = subprocess.run([scbg, *argv], capture_output=True, text=True, env=env)
    return {
        "argv": argv,
        "returncode": proc.returncode,
        "seconds": round(time.time() - started, 3),
        "node": ray.util.get_node_ip_address(),
        "stderr_tail": proc.stderr[-2000:],
    }


def run_shards(scbg: str, argvs: list[list[str]], cpus: int) -> list[dict]:
    """Runs every shard as a Ray task; raises if any failed (naming it)."""
    task = run_scbg.options(num_cpus=cpus)
    results = ray.get([task.remote(scbg, argv, cpus) for argv in argvs])
    failed = [r for r in results if r["returncode"] != 0]
    if failed:
        lines = [f"scbg {' '.join(r['argv'])} -> {r['returncode']}\n{r['stderr_tail']}" for r in failed]
        raise SystemExit(f"{len(failed)} of {len(results)} shard(s) failed:\n" + "\n".join(lines))
    return results


def run_local(scbg: str, argv: list[str]) -> None:
    """The merge step, on the driver."""
    proc = subprocess.run([scbg, *argv], capture_output=True, text=True, env=dict(os.environ, SCBG_LOG="warn"))
    if proc.returncode != 0:
        raise SystemExit(f"merge: scbg {' '.join(argv)} -> {proc.returncode}\n{proc.stderr[-2000:]}")


def write_json(path: Path, value) -> None:
    """Writes atomically (temp file, then rename)."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(value, indent=2) + "\n")
    tmp.replace(path)


def tfrecord_files(inputs: list[str]) -> list[str]:
    """Files of `inputs` (folders give their `*.tfrecord*` files), sorted."""
    files: list[str] = []
    for item in inputs:
        p = Path(item)
        if p.is_dir():
            files += [str(f) for f in sorted(p.iterdir()) if f.is_file() and ".tfrecord" in f.name]
        elif p.is_file():
            files.append(str(p))
        else:
            raise SystemExit(f"sim: no such file or folder: {item}")
    if not files:
        raise SystemExit(f"sim: no TFRecord files in {inputs}")
    return sorted(set(files))


def stage_prepare(a, extra: list[str]) -> dict:
    base = ["data", "prepare", "--input", *a.input, "--out", a.out, *extra]
    shards = run_shards(a.scbg, [base + ["--shard-index", str(i), "--num-shards", str(a.shards)] for i in range(a.shards)], a.cpus_per_task)
    run_local(a.scbg, base)  # every shard is finished: resumes all, writes the whole manifest
    manifest = json.loads((Path(a.out) / "manifest.json").read_text())
    return {"tasks": shards, "total": manifest["total"], "cache_shards": len(manifest["shards"])}


def stage_label(a, extra: list[str]) -> dict:
    base = ["label", "--model", a.model, "--data", a.data, "--out", a.out, *extra]
    shards = run_shards(a.scbg, [base + ["--shard-index", str(i), "--num-shards", str(a.shards)] for i in range(a.shards)], a.cpus_per_task)
    run_local(a.scbg, base)  # reads every table back, writes summary.json
    summary = json.loads((Path(a.out) / "summary.json").read_text())
    return {"tasks": shards, "rows": summary["rows"], "pairs_roles": summary["pairs_roles"]}


def merge_sim(reports: list[dict]) -> dict:
    """One report from per-shard `eval_sim.json`s: counts summed, means weighted by scenes."""
    scenes = sum(r["scenes"] for r in reports)
    if scenes == 0:
        raise SystemExit("sim: no shard evaluated a scene")
    # Shards that simulated nothing have no rows; a value a shard could not measure is null
    # (e.g. off-road without road edges) and leaves that shard out of its mean.
    measured = [r for r in reports if r["scenes"] > 0]
    quantiles = [q["quantile"] for q in measured[0]["per_quantile"]]
    per_quantile = []
    for k, q in enumerate(quantiles):
        row = {"quantile": q}
        for key in ["a_avg_speed_mps", "realised_courtesy_mps", "b_collision_rate", "b_offroad_rate", "b_mean_abs_jerk_mps3", "b_progress_m"]:
            known = [(r["per_quantile"][k][key], r["scenes"]) for r in measured if r["per_quantile"][k][key] is not None]
            weight = sum(n for _, n in known)
            row[key] = sum(v * n for v, n in known) / weight if weight else None
        per_quantile.append(row)
    speeds = [row["a_avg_speed_mps"] for row in per_quantile]
    skipped: dict[str, int] = {}
    skipped_scenes: list[dict] = []
    for r in reports:
        for why, n in r.get("skipped", {}).items():
            skipped[why] = skipped.get(why, 0) + n
        skipped_scenes.extend(r.get("skipped_scenes", []))
    collision = [r["max_b_collision_rate"] for r in measured if r["max_b_collision_rate"] is not None]
    return {
        "scenes": scenes,
        "skipped": skipped,
        "skipped_scenes": skipped_scenes,
        "shards": len(reports),
        "per_quantile": per_quantile,
        "a_speed_curve_rises": all(b >= a for a, b in zip(speeds, speeds[1:])),
        "max_b_collision_rate": max(collision) if collision else None,
    }


def stage_sim(a, extra: list[str]) -> dict:
    files = tfrecord_files(a.data)
    n = min(a.shards, len(files))
    groups = [files[i::n] for i in range(n)]
    out = Path(a.out)
    argvs = [["eval", "sim", "--model", a.model, "--data", *g, "--out", str(out / f"shard-{i:05}"), *extra] for i, g in enumerate(groups)]
    shards = run_shards(a.scbg, argvs, a.cpus_per_task)
    reports = [json.loads((out / f"shard-{i:05}" / "eval_sim.json").read_text()) for i in range(n)]
    merged = merge_sim(reports)
    write_json(out / "eval_sim_merged.json", merged)
    write_json(out / "eval_sim_shards.json", reports)
    return {"tasks": shards, "scenes": merged["scenes"], "files": len(files)}


def main(argv: list[str]) -> None:
    extra: list[str] = []
    if "--" in argv:
        i = argv.index("--")
        argv, extra = argv[:i], argv[i + 1 :]
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--address", default=None, help="Ray cluster to join (default: start a local one)")
    p.add_argument("--num-cpus", type=int, default=None, help="CPUs of a local cluster")
    p.add_argument("--scbg", default=shutil.which("scbg") or "scbg", help="the scbg binary (on every node)")
    p.add_argument("--cpus-per-task", type=int, default=1)
    sub = p.add_subparsers(dest="stage", required=True)
    s = sub.add_parser("prepare")
    s.add_argument("--input", nargs="+", required=True)
    s.add_argument("--out", required=True)
    s.add_argument("--shards", type=int, required=True)
    s = sub.add_parser("label")
    s.add_argument("--model", required=True)
    s.add_argument("--data", required=True)
    s.add_argument("--out", required=True)
    s.add_argument("--shards", type=int, required=True)
    s = sub.add_parser("sim")
    s.add_argument("--model", required=True)
    s.add_argument("--data", nargs="+", required=True)
    s.add_argument("--out", required=True)
    s.add_argument("--shards", type=int, required=True)
    a = p.parse_args(argv)
    if a.shards < 1:
        p.error("--shards must be at least 1")
    ray.init(address=a.address, num_cpus=a.num_cpus, include_dashboard=False, log_to_driver=False)
    try:
        started = time.time()
        record = {"prepare": stage_prepare, "label": stage_label, "sim": stage_sim}[a.stage](a, extra)
        record["seconds"] = round(time.time() - started, 3)
        record["ray_nodes"] = len(ray.nodes())
        write_json(Path(a.out) / f"ray_{a.stage}.json", record)
        print(json.dumps({k: v for k, v in record.items() if k != "tasks"}))
    finally:
        ray.shutdown()


if __name__ == "__main__":
    main(sys.argv[1:])
