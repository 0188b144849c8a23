"""A courtesy-controlled car inside highway-env's merge road, among its own IDM cars.

highway-env (https://github.com/Farama-Foundation/HighwayEnv, from PyPI) simulates a two-lane
highway with an on-ramp; its vehicles drive with IDM + MOBIL. Here one highway car (B, the car
ahead of highway-env's ego in its lane) is driven by scbg instead: every 10 steps (1 s) the
simulator's recent history and its road network — converted to scbg's map each episode (lane
centre lines, and road edges where the lanes have solid lines) — become a scene,
`Model.generate` plans B's next 8 s at a courtesy quantile toward the car behind it (A,
highway-env's ego, driven by IDM), and B follows that plan. Everything else is highway-env's
own: the other cars react to B as they would to any car. (The ramp's merging car was the first
choice for B; the demo's generator, trained on synthetic ramps, does not follow highway-env's
sine-shaped ramp and never reaches the highway within 8 s, so it met nobody.)

    python crates/python/examples/highway_merge.py out/demo/generator_full [--episodes 12] [--png out.png]

prints, per quantile, the mean speed of highway-env's own cars and of A over the 8 s after the
scene's current step.
"""

import argparse

import numpy as np

import scbg

STEPS_HISTORY = 11  # 1 s at 10 Hz, the current step included
STEPS_FUTURE = 80  # 8 s
LENGTH, WIDTH = 5.0, 2.0  # highway-env's vehicle box


def _flip(x, y):
    """highway-env's frame (y to the right of travel) → scbg's (y to the left)."""
    return x, -y


def road_map(road):
    """Lane centre lines and road edges (solid lines) of a highway-env road, scbg's frame."""
    from highway_env.road.lane import LineType

    lanes, edges = [], []
    for lane in road.network.lanes_list():
        s = np.arange(0.0, lane.length + 1e-9, 2.0)
        lanes.append(np.array([_flip(*lane.position(t, 0.0)) for t in s]))
        for side, lat in ((0, -0.5), (1, 0.5)):
            if lane.line_types[side] == LineType.CONTINUOUS_LINE:
                w = lane.width_at(0.0)
                edges.append(np.array([_flip(*lane.position(t, lat * w)) for t in s]))
    return lanes, edges


def state_row(v):
    x, y = _flip(*v.position)
    h = -v.heading
    return [x, y, h, v.speed * np.cos(h), v.speed * np.sin(h), LENGTH, WIDTH]


def episode(model, quantile, seed, replan_every=10):
    """One episode: returns (mean speed of highway-env's cars but B, mean speed of A)."""
    import gymnasium
    import highway_env  # noqa: F401  (registers the environments)
    from highway_env.vehicle.behavior import IDMVehicle

    env = gymnasium.make("merge-v0", config={"simulation_frequency": 10, "policy_frequency": 10})
    env.reset(seed=seed)
    road = env.unwrapped.road
    # highway-env's ego follows actions; make it one of the simulator's own IDM cars instead.
    ego = road.vehicles[0]
    road.vehicles[0] = IDMVehicle(road, ego.position, heading=ego.heading, speed=ego.speed)
    cars = list(road.vehicles)
    lanes, edges = road_map(road)
    dt = 1.0 / 10
    history = [[state_row(v) for v in cars]]
    for _ in range(STEPS_HISTORY - 1):  # the history, up to the current step
        road.act()
        road.step(dt)
        history.append([state_row(v) for v in cars])
    # A: highway-env's ego; B: the nearest highway car ahead of it (in its lane if any).
    a = 0
    ax = cars[a].position[0]
    ahead = [i for i, v in enumerate(cars) if i != a and v.position[0] > ax and v.lane_index[0] != "j"]
    same = [i for i in ahead if cars[i].lane_index[2] == cars[a].lane_index[2]]
    b = min(same or ahead, key=lambda i: cars[i].position[0])
    ids = np.arange(1, len(cars) + 1, dtype=np.int64)
    speeds, a_speeds, plan, plan_start = [], [], None, 0
    for k in range(STEPS_FUTURE):
        if k % replan_every == 0:
            recent = np.array(history[-STEPS_HISTORY:])  # [steps, agents, 7]
            states = np.zeros((len(cars), STEPS_HISTORY + STEPS_FUTURE, 7))
            states[:, :STEPS_HISTORY] = recent.transpose(1, 0, 2)
            valid = np.zeros(states.shape[:2], bool)
            valid[:, :STEPS_HISTORY] = True
            scene = scbg.Scene.from_arrays(
                f"highway-merge-{seed}", ids, states, valid, current_step=STEPS_HISTORY - 1,
                sdc_id=int(ids[a]), objects_of_interest=[int(ids[a]), int(ids[b])],
                lanes=lanes, road_edges=edges)
            plan = model.generate(scene, int(ids[a]), int(ids[b]), quantile=quantile)["world_xy_m"]
            plan_start = k
        road.act()
        road.step(dt)
        # B follows its plan (scbg's frame back to highway-env's).
        p = plan[k - plan_start]
        prev = plan[k - plan_start - 1] if k > plan_start else history[-1][b][:2]
        d = np.array([p[0] - prev[0], -(p[1] - prev[1])])
        cars[b].position = np.array([p[0], -p[1]])
        cars[b].speed = float(np.hypot(*d) / dt)
        if np.hypot(*d) > 1e-3:
            cars[b].heading = float(np.arctan2(d[1], d[0]))
        cars[b].on_state_update()  # its lane, as the other cars see it
        history.append([state_row(v) for v in cars])
        speeds.append(np.mean([v.speed for i, v in enumerate(cars) if i != b]))
        a_speeds.append(cars[a].speed)
    env.close()
    return float(np.mean(speeds)), float(np.mean(a_speeds))


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("model")
    ap.add_argument("--episodes", type=int, default=12)
    ap.add_argument("--quantiles", type=float, nargs="+", default=[0.1, 0.5, 0.9])
    ap.add_argument("--png", help="write a figure of the speeds against the quantile")
    args = ap.parse_args()
    model = scbg.Model(args.model)
    rows = []
    for q in args.quantiles:
        res = np.array([episode(model, q, seed) for seed in range(args.episodes)])
        rows.append((q, res[:, 0].mean(), res[:, 0].std(), res[:, 1].mean(), res[:, 1].std()))
        print(f"quantile {q:.1f}: highway-env cars {rows[-1][1]:.3f} ± {rows[-1][2]:.3f} m/s, "
              f"A {rows[-1][3]:.3f} ± {rows[-1][4]:.3f} m/s ({args.episodes} episodes)")
    if args.png:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt

        qs = [r[0] for r in rows]
        plt.figure(figsize=(5, 3.2))
        plt.errorbar(qs, [r[1] for r in rows], [r[2] for r in rows], marker="o", label="highway-env's cars")
        plt.errorbar(qs, [r[3] for r in rows], [r[4] for r in rows], marker="s", label="A (the car behind B)")
        plt.xlabel("courtesy quantile of the scbg-driven car B")
        plt.ylabel("mean speed over 8 s (m/s)")
        plt.legend()
        plt.tight_layout()
        plt.savefig(args.png, dpi=120)


if __name__ == "__main__":
    main()
