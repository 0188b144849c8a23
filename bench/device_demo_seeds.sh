#!/bin/bash
# Eight `scbg demo` runs side by side on a device machine's 16 CPU cores (no GPU used), two
# threads each: data seeds 0-3, each with one graph per training step (`--data-parallel-chunks 1`)
# and with two data-parallel chunks (the demo's default). Paired by seed, they say whether two
# chunks cost label fidelity or control (docs/findings.md, "Data-parallel chunks"). Carries
# target/devcarry/scbg.xz (a stripped `cargo build --release -p scbg-cli`, xz). Stops at a deadline
# ($DEADLINE seconds) and keeps what each run wrote. On the H100 machine's Xeon, eight runs side by
# side took ~2x as long per epoch as one demo on a 2-core EPYC: a 600 s call reaches epoch ~20.
set -u
W=$(mktemp -d)
LOG=${OUT:-$W}/log.txt
exec > >(tee -a "$LOG") 2>&1
T0=$(date +%s)
DEADLINE=${DEADLINE:-560}
lscpu | grep -E "^Model name|^CPU\(s\)"
mkdir -p $W/bin && xz -dc target/devcarry/scbg.xz > $W/bin/scbg && chmod +x $W/bin/scbg
export SCBG_REAL_DATA=/nonexistent
D=$W/d; mkdir -p $D
for s in 0 1 2 3; do
  for c in 1 2; do
    $W/bin/scbg --threads 2 demo --out $D/s${s}_c$c --seed $s --data-parallel-chunks $c \
      > $D/s${s}_c$c.log 2>&1 &
  done
done
# One archive, replaced whole each time: a call returns only a few files from $OUT.
collect() {
  (cd $D && tar czf $OUT/runs.tgz.tmp $(ls -d s*_c?/report.json s*_c?/predictor.toml \
    s*_c?/labels*/summary.json s*_c?.log 2>/dev/null)) && mv $OUT/runs.tgz.tmp $OUT/runs.tgz
}
# Collect every 20 s: a run cut short by the call's limit still leaves its latest files.
while [ $(( $(date +%s) - T0 )) -lt $DEADLINE ] && [ -n "$(jobs -r)" ]; do sleep 20; collect; done
echo "stopped at $(( $(date +%s) - T0 )) s; running: $(jobs -r | wc -l)"
collect
ls -la $OUT
