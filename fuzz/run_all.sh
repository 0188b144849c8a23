#!/usr/bin/env bash
# Fuzzes every target in turn, then minimises each corpus into fuzz/corpus/<target> (which
# `cargo test` replays). An input that crashes, leaks, runs out of memory (4 GiB) or hangs for
# over a second is saved under fuzz/artifacts/<target>/; once fixed, it goes to
# fuzz/regressions/<target>/ (named by its SHA-1), which `cargo test` replays too. Prints each
# target's runs, time, coverage and corpus size.
#
#   cargo install cargo-fuzz
#   fuzz/run_all.sh [SECONDS]             # each target for SECONDS (default 600), two at a time
#   fuzz/run_all.sh --runs N [--workers W] [--cap SECONDS] [--sanitizer address|none]
#
# With --runs, each target in turn runs N inputs in all in libFuzzer's fork mode over W worker
# processes (default: the number of cores), or for --cap seconds at most; it goes on past a
# crash, hang or out-of-memory input, saves each and counts them. --sanitizer none builds
# without the address sanitizer (4–40 times the runs per second).
set -euo pipefail
cd "$(dirname "$0")"
seconds=600 runs="" workers="$(nproc)" cap=0 sanitizer=address
while (($#)); do
  case "$1" in
    --runs) runs="$2"; shift 2 ;;
    --workers) workers="$2"; shift 2 ;;
    --cap) cap="$2"; shift 2 ;;
    --sanitizer) sanitizer="$2"; shift 2 ;;
    *) seconds="$1"; shift ;;
  esac
done
targets=(decode_records serve_requests configs artefacts label_table scene_arrays)
RUSTC_BOOTSTRAP=1 cargo fuzz build --release --sanitizer "$sanitizer" --target-dir "target-$sanitizer"
bin="$PWD/target-$sanitizer/x86_64-unknown-linux-gnu/release"
# Seeds the project generates (never tracked): a few synthetic scenarios in WOMD format. Built
# without RUSTC_BOOTSTRAP, which would make cargo rebuild the workspace from scratch.
cargo run --release -q --manifest-path ../Cargo.toml -p scbg-cli -- \
  synth --scenarios 4 --scenarios-per-file 1 --out seeds/decode_records >/dev/null
limits=(-timeout=1 -rss_limit_mb=4096)
log_dir="$(mktemp -d)"
run() {
  local target="$1"
  mkdir -p "corpus/$target" "work/$target" "artifacts/$target"
  local seeds=()
  [[ -d "seeds/$target" ]] && seeds=("$PWD/seeds/$target")
  local dirs=("$PWD/work/$target" "$PWD/corpus/$target" "${seeds[@]}")
  local artifacts="$PWD/artifacts/$target/" started=$SECONDS
  if [[ -n "$runs" ]]; then
    "$bin/$target" "${dirs[@]}" "${limits[@]}" -runs="$runs" -max_total_time="$cap" \
      -fork="$workers" -ignore_crashes=1 -ignore_timeouts=1 -ignore_ooms=1 \
      -artifact_prefix="$artifacts" >"$log_dir/$target.log" 2>&1 || true
  else
    "$bin/$target" "${dirs[@]}" "${limits[@]}" -max_total_time="$seconds" -print_final_stats=1 \
      -artifact_prefix="$artifacts" >"$log_dir/$target.log" 2>&1 || true
  fi
  echo $((SECONDS - started)) >"$log_dir/$target.seconds"
}
if [[ -n "$runs" ]]; then
  for target in "${targets[@]}"; do run "$target"; done
else
  for ((i = 0; i < ${#targets[@]}; i += 2)); do
    run "${targets[i]}" & a=$!
    run "${targets[i + 1]}" & b=$!
    wait "$a"; wait "$b"
  done
fi
failed=0
for target in "${targets[@]}"; do
  # The committed corpus becomes the smallest set of inputs with all the coverage found.
  rm -rf "min/$target" && mkdir -p "min/$target"
  "$bin/$target" "min/$target" "corpus/$target" "work/$target" -merge=1 -rss_limit_mb=4096 \
    >"$log_dir/$target.merge" 2>&1
  rm -rf "corpus/$target" && mv "min/$target" "corpus/$target"
  # Mutations of the generated seeds (whole scenarios, ~50 KB each) stay out of the repository.
  [[ "$target" == decode_records ]] && find "corpus/$target" -type f -size +16k -delete
  log="$log_dir/$target.log"
  if [[ -n "$runs" ]]; then
    # Fork mode's last status line: "#RUNS: cov: … oom/timeout/crash: O/T/C …".
    status=$(grep -a 'oom/timeout/crash' "$log" | tail -1)
    done_runs=$(sed -E 's/^#([0-9]+).*/\1/' <<<"$status")
    faults=$(grep -o 'oom/timeout/crash: [0-9/]*' <<<"$status" | cut -d' ' -f2)
  else
    done_runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log" | grep -o '[0-9]*$')
    faults=""
  fi
  # The kept corpus's coverage, as the merge measured it.
  cov=$(grep -o '[0-9]* new coverage edges' "$log_dir/$target.merge" | grep -o '^[0-9]*' | tail -1)
  echo "$target: ${done_runs:-?} runs in $(cat "$log_dir/$target.seconds") s, coverage ${cov:-?} edges, $(ls "corpus/$target" | wc -l) inputs kept${faults:+, out-of-memory/hang/crash $faults}"
  if grep -aq 'Test unit written to' "$log"; then
    grep -ah 'Test unit written to' "$log" | sed "s/^/$target: /"
    failed=1
  fi
done
exit "$failed"
