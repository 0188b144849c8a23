#!/usr/bin/env bash
# Fuzzes every target in turn for SECONDS each (default 600), two at a time, then minimises
# each corpus into fuzz/corpus/<target> (which `cargo test` replays). An input that crashes,
# leaks, runs out of memory (4 GiB) or hangs for over a second stops its target and is saved
# under fuzz/artifacts/<target>/. Prints each target's runs, coverage and corpus size.
#
#   cargo install cargo-fuzz
#   fuzz/run_all.sh [SECONDS]
set -euo pipefail
cd "$(dirname "$0")"
seconds="${1:-600}"
export RUSTC_BOOTSTRAP=1
targets=(decode_records serve_requests configs artefacts label_table scene_arrays)
cargo fuzz build --release
# Seeds the project generates (never tracked): a few synthetic scenarios in WOMD format.
cargo run --release -q --manifest-path ../Cargo.toml -p scbg-cli -- \
  synth --scenarios 4 --scenarios-per-file 1 --out seeds/decode_records >/dev/null
log_dir="$(mktemp -d)"
run() {
  local target="$1"
  mkdir -p "corpus/$target" "work/$target"
  local seeds=()
  [[ -d "seeds/$target" ]] && seeds=("seeds/$target")
  cargo fuzz run --release "$target" "work/$target" "corpus/$target" "${seeds[@]}" -- \
    -max_total_time="$seconds" -timeout=1 -rss_limit_mb=4096 -print_final_stats=1 \
    >"$log_dir/$target.log" 2>&1 || echo "$target: STOPPED, input in artifacts/$target/" >>"$log_dir/failed"
}
for ((i = 0; i < ${#targets[@]}; i += 2)); do
  run "${targets[i]}" & a=$!
  run "${targets[i + 1]}" & b=$!
  wait "$a"; wait "$b"
done
for target in "${targets[@]}"; do
  # The committed corpus becomes the smallest set of inputs with all the coverage found.
  rm -rf "min/$target" && mkdir -p "min/$target"
  cargo fuzz run --release "$target" "min/$target" "corpus/$target" "work/$target" -- \
    -merge=1 -rss_limit_mb=4096 >/dev/null 2>&1
  rm -rf "corpus/$target" && mv "min/$target" "corpus/$target"
  runs=$(grep -o 'stat::number_of_executed_units: *[0-9]*' "$log_dir/$target.log" | grep -o '[0-9]*$' || echo '?')
  cov=$(grep -o 'cov: [0-9]*' "$log_dir/$target.log" | tail -1 | grep -o '[0-9]*' || echo '?')
  echo "$target: ${runs} runs in ${seconds} s, coverage ${cov} edges, $(ls "corpus/$target" | wc -l) inputs kept"
done
if [[ -s "$log_dir/failed" ]]; then cat "$log_dir/failed"; exit 1; fi
