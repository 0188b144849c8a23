"""Python call latency of Model.generate on a loaded scene (BENCHMARKS.md records its p50).

    python crates/python/bench_generate.py out/demo/generator_full out/demo/synth/synth-00000.tfrecord
"""

import statistics
import sys
import time

import scbg

model = scbg.Model(sys.argv[1])
scene = scbg.read_scenarios(sys.argv[2])[0]
a = scene.sdc_id
b = [i for i in scene.objects_of_interest if i != a][0]
model.generate(scene, a, b, quantile=0.5)  # loads the pair's context once
times = []
for k in range(2000):
    t = time.perf_counter()
    model.generate(scene, a, b, quantile=0.1 * (1 + k % 9))
    times.append((time.perf_counter() - t) * 1e3)
times.sort()
print(f"Model.generate on a loaded scene: {len(times)} calls, "
      f"p50 {statistics.median(times):.3f} ms, p99 {times[int(0.99 * (len(times) - 1))]:.3f} ms")
