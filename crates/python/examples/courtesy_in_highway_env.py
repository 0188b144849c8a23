"""One courtesy-controlled car inside highway-env: the same episode at three courtesy quantiles.

    python crates/python/examples/courtesy_in_highway_env.py out/demo/generator_full [merge-v0] [seed]

B (scbg) is re-planned every second from highway-env's road and cars (``scbg.sims.highway``);
every other car is highway-env's own. Prints A's mean speed over the 8 s after the takeover for
each quantile, and for highway-env's own B at its low and high courtesy setting. For the full
paired measurement over many seeds and every simulator: ``python -m scbg.sims.measure``.
"""

import sys

import scbg
from scbg.sims import highway

model = scbg.Model(sys.argv[1])
scenario = sys.argv[2] if len(sys.argv) > 2 else "merge-v0"
seed = int(sys.argv[3]) if len(sys.argv) > 3 else 0
print(f"{scenario}: {highway.SCENARIOS[scenario]}")
for q in (0.1, 0.5, 0.9):
    r = highway.episode(model, scenario, seed, {"kind": "scbg", "quantile": q})
    print(f"  scbg B at quantile {q:.1f}: A {r['a_speed_mps']:.2f} m/s, B collided {r['b_collided']}, "
          f"B's plans on the road {r['b_plan_points_on_road'] / r['b_plan_points']:.0%}")
own = highway.YARDSTICKS[scenario]
for level in ("low", "high"):
    r = highway.episode(None, scenario, seed, {"kind": "yardstick", "level": level})
    print(f"  highway-env's B, {own['parameter']} = {own[level]}: A {r['a_speed_mps']:.2f} m/s")
