#!/bin/bash
# The GPU and many-core checks of BENCHMARKS.md ("Predictor training", "On the H100 machine").
# Not part of the test suite: it needs an NVIDIA GPU with its Vulkan
# driver, PyTorch with CUDA, and binaries built beforehand on the build machine:
#
#   cargo build --release -p scbg-cli --features vulkan            # -> .dev/scbg-vk.xz
#   cargo build --release -p scbg-cli --features vulkan,gpu-fusion # -> .dev/scbg-vkf.xz
#   cargo test --release -p scbg-cli -p scbg-model \
#       --features scbg-cli/vulkan,scbg-model/vulkan --test gpu --no-run  # -> .dev/gpu-test.xz
#   (strip each, then `xz -c BIN > .dev/NAME.xz`; copy out/demo/predictor.toml to .dev/)
#
# Where the machine lacks the Vulkan loader, unpack libvulkan1 (and the GL libraries) first.
# Sections run in priority order, each under its own time limit; the log goes to $OUT/log.txt.
# Scratch files go to a fresh temporary folder ($W).
set -u
W=$(mktemp -d)
LOG=${OUT:-$W}/log.txt
exec > >(tee -a "$LOG") 2>&1
T0=$(date +%s)
sec() { echo; echo "=== [$(( $(date +%s) - T0 )) s] $*"; }
sec env
nvidia-smi --query-gpu=name,driver_version,memory.total,clocks.max.sm --format=csv
lscpu | grep -E "^Model name|^CPU\(s\)|^Thread|^Core|^Socket|^L3"
grep -o -w -E "avx2|avx512f|avx512_bf16|amx_tile|amx_bf16" /proc/cpuinfo | sort | uniq -c
mkdir -p $W/bin
for b in scbg-vk gpu-test scbg-vkf; do [ -f .dev/$b.xz ] && xz -dc .dev/$b.xz > $W/bin/$b && chmod +x $W/bin/$b; done
ls -la $W/bin
S=$W/bin/scbg-vk; V=$S; F=$W/bin/scbg-vkf
export SCBG_REAL_DATA=/nonexistent
PY=python3

sec "gpu test (forward + backward on vulkan vs flex)"
ls /usr/share/vulkan/icd.d /etc/vulkan/icd.d /usr/local/nvidia/share/vulkan/icd.d 2>&1 | head
timeout 90 $W/bin/gpu-test --test-threads 1 > $W/gt.txt 2>&1; cat $W/gt.txt | tail -12
if grep -q "no GPU answers" $W/gt.txt; then
  echo "retrying with the NVIDIA ICD named explicitly"
  export VK_DRIVER_FILES=$(ls /usr/local/nvidia/share/vulkan/icd.d/*.json /usr/share/vulkan/icd.d/nvidia*.json /etc/vulkan/icd.d/nvidia*.json 2>/dev/null | head -1)
  echo "VK_DRIVER_FILES=$VK_DRIVER_FILES"
  timeout 90 $W/bin/gpu-test --test-threads 1 2>&1 | tail -12
fi

sec "scbg vulkan, paper, batch 32 and 256"
timeout 100 $S bench train --backend vulkan --presets cpu-small,paper --batch 32 --steps 10 --warmup 2
timeout 100 $S bench train --backend vulkan --presets paper --batch 256 --steps 10 --warmup 2

sec "pytorch cuda, paper, batch 32 and 256"
timeout 60 $PY bench/pytorch_reference.py --preset cpu-small --preset paper --device cuda --batch 32 --steps 20 --warmup 3
timeout 60 $PY bench/pytorch_reference.py --preset paper --device cuda --batch 256 --steps 20 --warmup 3

sec "cpu thread scaling, paper, batch 32 (scbg flex, pytorch cpu)"
for t in 1 2 4 8 16; do
  RAYON_NUM_THREADS=$t timeout 60 $S bench train --backend flex --presets paper --steps 4
  [ $t -ge 2 ] && RAYON_NUM_THREADS=$t timeout 60 $S bench train --backend flex --presets paper --steps 4 --chunks $t
  timeout 60 $PY bench/pytorch_reference.py --preset paper --threads $t --steps 4
done
RAYON_NUM_THREADS=16 timeout 60 $S bench train --backend flex --presets paper --steps 4 --chunks 8

sec "demo predictor epoch: data"
D=$W/d; mkdir -p $D
timeout 60 $S synth --scenarios 1500 --counterfactuals 3 --out $D/synth > /dev/null
timeout 60 $S data prepare --input $D/synth --out $D/cache --files-per-shard 4 > /dev/null
timeout 60 $S data prepare --input $D/synth/counterfactual --out $D/cache_cf --files-per-shard 4 > /dev/null
du -sh $D/cache $D/cache_cf
for run in flex:1 flex:8 flex:16 vulkan:1; do
  be=${run%:*}; ch=${run#*:}
  sed -e "s|^backend = .*|backend = \"$be\"|" -e "s|^epochs = .*|epochs = 1|" -e "s|^counterfactual_cache = .*|counterfactual_cache = \"$D/cache_cf\"\ndata_parallel_chunks = $ch|" .dev/predictor.toml > $D/p_$be$ch.toml
  sec "demo predictor, 1 epoch, $be, $ch chunk(s), $(nproc) cores"
  timeout 150 $S train predictor --config $D/p_$be$ch.toml --data $D/cache --out $D/pred_$be$ch 2>&1 | grep -v -E "^\s*$" | tail -4
  grep -o '"seconds": *[0-9.]*' $D/pred_$be$ch/*.json 2>/dev/null | head -3
done

sec "vulkan + fusion + autotune, batch 32"
timeout 110 $F bench train --backend vulkan --presets cpu-small,paper --batch 32 --steps 10 --warmup 5 | tee $W/f32.txt
sec "vulkan + fusion + autotune, paper, batch 256"
timeout 90 $F bench train --backend vulkan --presets paper --batch 256 --steps 10 --warmup 5

sec "vulkan (no fusion), phase split, paper, batch 32 and 256"
timeout 50 $V bench train --backend vulkan --presets paper --batch 32 --steps 3 --warmup 1
timeout 50 $V bench train --backend vulkan --presets paper --batch 256 --steps 3 --warmup 1

sec "cpu: data-parallel with the tree sum, paper, batch 32"
for tc in 4:4 8:8 16:8 16:16; do
  t=${tc%:*}; c=${tc#*:}
  RAYON_NUM_THREADS=$t timeout 40 $V bench train --backend flex --presets paper --steps 4 --chunks $c
done
RAYON_NUM_THREADS=16 MALLOC_MMAP_THRESHOLD_=33554432 MALLOC_TRIM_THRESHOLD_=4294967296 timeout 40 $V bench train --backend flex --presets paper --steps 4 --chunks 8
RAYON_NUM_THREADS=16 timeout 40 $V bench train --backend flex --presets paper --steps 4 --chunks 1
sec done
