"""The SUMO harness (scbg.sims.sumo): frame conversions, B on the road, determinism, the
yardstick's direction and bad requests. Needs eclipse-sumo, libsumo and sumolib."""

import math

import numpy as np
import pytest

from scbg import sims
from scbg.sims import measure, sumo


def _run_until(traci, ids, steps):
    history = []
    for _ in range(steps):
        traci.simulationStep()
        if all(v in traci.vehicle.getIDList() for v in ids):
            history.append({v: sumo.vehicle_state(traci, v) for v in traci.vehicle.getIDList()})
    return history[-sumo.HISTORY_STEPS:]


def test_heading_convention():
    # SUMO: degrees clockwise from north; scbg: radians counter-clockwise from +x.
    for angle, heading in ((0.0, math.pi / 2), (90.0, 0.0), (180.0, -math.pi / 2), (45.0, math.pi / 4)):
        assert sumo.heading_from_sumo_angle(angle) == pytest.approx(heading, abs=1e-12)
        assert sumo.sumo_angle_from_heading(heading) == pytest.approx(angle % 360.0, abs=1e-9)
    assert abs(sumo.heading_from_sumo_angle(270.0)) == pytest.approx(math.pi)


def test_scene_positions_are_sumo_centres():
    """A car driving east and one driving north, converted into a scene: centres (SUMO gives
    the front bumper), headings and velocities as the lanes' geometry says."""
    road = sumo.road_map("sumo-4way")
    traci = sumo.start_sumo("sumo-4way", 0)
    try:
        traci.vehicle.add("A", "eastbound", typeID="car", depart="0", departSpeed="10")
        traci.vehicle.add("B", "northbound", typeID="car", depart="0", departSpeed="8")
        history = _run_until(traci, ("A", "B"), 30)
        pos = {v: traci.vehicle.getLanePosition(v) for v in ("A", "B")}
        speed = {v: traci.vehicle.getSpeed(v) for v in ("A", "B")}
        length = traci.vehicle.getLength("A")
        scene, a, b = sumo.scene_from_history("sumo-4way", history, "A", "B", road)
    finally:
        traci.close()
    states, valid = scene.states()
    ids = list(scene.ids)
    now = scene.current_step
    assert valid[:, : now + 1].all() and not valid[:, now + 1 :].any()
    # w_in's lane runs from x = -250 along y = -1.75; s_in's from y = -250 along x = 1.75.
    sa, sb = states[ids.index(a), now], states[ids.index(b), now]
    assert sa[:2] == pytest.approx([-250.0 + pos["A"] - length / 2, -1.75], abs=1e-6)
    assert sb[:2] == pytest.approx([1.75, -250.0 + pos["B"] - length / 2], abs=1e-6)
    assert sa[2] == pytest.approx(0.0, abs=1e-6) and sb[2] == pytest.approx(math.pi / 2, abs=1e-6)
    assert sa[3:5] == pytest.approx([speed["A"], 0.0], abs=1e-5)
    assert sb[3:5] == pytest.approx([0.0, speed["B"]], abs=1e-5)
    assert sa[5:7] == pytest.approx([4.8, 1.9], abs=1e-6)


def test_b_is_put_where_its_plan_says():
    """Following a plan point: SUMO's B (converted back to a centre) is at the point, with the
    plan's speed; a point beside the lane is mapped onto it."""
    traci = sumo.start_sumo("sumo-4way", 0)
    try:
        traci.vehicle.add("B", "northbound", typeID="car", depart="0", departSpeed="10")
        history = _run_until(traci, ("B",), 5)
        traci.vehicle.setSpeedMode("B", 0)
        start = np.array(history[-1]["B"][:2])
        plan = start + np.outer(np.arange(1, 81), [0.0, 1.2])  # 12 m/s north along the lane
        plan[1:, 0] += 0.6  # beside the lane centre from the second point on
        follower = sumo._PlanFollower(plan, start)
        for j in range(3):
            follower.step(traci, j, history[-1]["B"], [])
            traci.simulationStep()
            history.append({"B": sumo.vehicle_state(traci, "B")})
            x, y, h, vx, vy = history[-1]["B"][:5]
            assert (x, y) == pytest.approx((start[0], plan[j, 1]), abs=1e-6)
            assert h == pytest.approx(math.pi / 2, abs=1e-6)
            assert math.hypot(vx, vy) == pytest.approx(float(np.hypot(*(plan[j] - (plan[j - 1] if j else start)))) / 0.1, rel=1e-6)
    finally:
        traci.close()


def _row(x, y, heading, speed, length=4.8, width=1.9):
    return (x, y, heading, speed * math.cos(heading), speed * math.sin(heading), length, width)


def test_crossing_rule_holds_b_only_for_a_car_that_cannot_stop():
    """B drives north along x = 0 towards a road along y = 20. A car on that road that can no
    longer stop short of B's path holds B before the crossing; one far enough to stop, one that
    has passed, one driving beside B, and any car once B could not stop in time, do not."""
    path = np.column_stack([np.zeros(61), np.arange(61.0)])
    arc = sims.arc_lengths(path)
    b = _row(0.0, 0.0, math.pi / 2, 8.0)
    # 13 m/s needs 6.5 + 12.1 m to stop: at 15 m before B's path it cannot.
    near = _row(-15.0 - 3.85, 20.0, 0.0, 13.0)
    hold = sims.crossing_hold_m(path, arc, 0.0, b, [near])
    # B's centre stays where its box (half its length ahead) keeps clear of the car's half
    # width, with the margin on both.
    assert hold == pytest.approx(20.0 - 0.5 * (1.9 + 4.8) - 2 * sims.CROSS_MARGIN_M, abs=0.5)
    assert sims.held_speed_mps(hold, 0.0, 0.1) == pytest.approx(math.sqrt(2 * sims.B_BRAKE_MPS2 * hold))
    assert sims.held_speed_mps(hold, hold + 1.0, 0.1) == 0.0
    far = _row(-40.0, 20.0, 0.0, 13.0)
    passed = _row(8.0, 20.0, 0.0, 13.0)
    beside = _row(3.5, 5.0, math.pi / 2, 13.0)
    assert sims.crossing_hold_m(path, arc, 0.0, b, [far, passed, beside]) == math.inf
    # A standing car in the way: it cannot stop short of a B already in its way, nor clear it.
    assert sims.crossing_hold_m(path, arc, 0.0, b, [_row(0.0, 20.0, 0.0, 0.0)]) < 20.0
    # B 3 m before the hold at 8 m/s needs 4 m to stop at its hardest: it goes on, committed
    # (it clears the car's way rather than slow down in it where no right of way rules).
    assert sims.crossing_hold_m(path, arc, hold - 3.0, b, [near]) == math.inf
    assert sims.crossing_rule(path, arc, hold - 3.0, b, [near]) == (math.inf, True)
    assert sims.crossing_rule(path, arc, 0.0, b, [near]) == (pytest.approx(hold), False)
    assert sims.crossing_rule(path, arc, hold - 3.0, b, [far, passed, beside]) == (math.inf, False)


def test_crossing_rule_follows_a_turning_car_along_its_way():
    """A car beside B's path, heading the same way, that turns left across it: along its
    heading it never crosses B's path, along the way its simulator says it drives it does, and
    B is held short of where that way crosses."""
    path = np.column_stack([np.zeros(61), np.arange(61.0)])
    arc = sims.arc_lengths(path)
    b = _row(0.0, 0.0, math.pi / 2, 8.0)
    turner = _row(10.0, 25.0, math.pi / 2, 13.0)
    assert sims.crossing_hold_m(path, arc, 0.0, b, [turner]) == math.inf
    angle = np.linspace(0.0, math.pi / 2, 20)  # a quarter circle of 10 m about (0, 25), then west
    way = np.vstack([np.column_stack([10.0 * np.cos(angle), 25.0 + 10.0 * np.sin(angle)]),
                     np.column_stack([-np.arange(2.0, 40.0, 2.0), np.full(19, 35.0)])])
    hold = sims.crossing_hold_m(path, arc, 0.0, b, [turner], ways=[way])
    # B's box clears the way's half width (plus margins) before y = 35, where the way crosses.
    assert 35.0 - 0.5 * (1.9 + 4.8) - 3.0 < hold < 35.0 - 0.5 * (1.9 + 4.8)
    # A car given no way is taken along its heading.
    assert sims.crossing_hold_m(path, arc, 0.0, b, [turner], ways=[None]) == math.inf


def test_the_follow_guard_eases_behind_a_faster_car_and_stops_for_a_standing_one():
    """B at 26 m/s with a car cutting in 4 m ahead: plain IDM would brake at about 245 m/s²; the
    guard brakes briefly (a faster car pulls away) and never past B's hardest braking. Behind a
    standing car it brakes its hardest; with the road clear, or far behind a car, B keeps its
    plan."""
    step = 0.1
    faster = sims.guarded_speed_mps(30.0, 26.0, 4.0, 26.9, step)
    assert 26.0 - sims.GUARD_MAX_BRAKE_MPS2 * step <= faster < 26.0
    assert (26.0 - faster) / step < 8.0
    standing = sims.guarded_speed_mps(30.0, 26.0, 4.0, 0.0, step)
    assert standing == pytest.approx(26.0 - sims.GUARD_MAX_BRAKE_MPS2 * step)
    assert sims.guarded_speed_mps(27.0, 26.0, math.inf, 0.0, step) == 27.0
    assert sims.guarded_speed_mps(26.3, 26.0, 200.0, 26.0, step) == 26.3
    # The leader is the first car near B's path ahead, its gap taken bumper to bumper where the
    # path passes it, its speed the part along the path; a car 5 m aside is none.
    path = np.column_stack([np.arange(0.0, 40.0), np.zeros(40)])
    samples = sims.path_samples(path, sims.arc_lengths(path))
    gap, v = sims.leader_on_path(samples, 0.0, [[25.0, 0.0], [10.0, 5.0]], [[12.0, 0.0], [3.0, 0.0]], [4.8, 4.8])
    assert gap == pytest.approx(25.0 - 4.8) and v == pytest.approx(12.0)
    gap, v = sims.leader_on_path(samples, 2.0, [[25.0, 1.0]], [[-8.0, 0.0]], [4.8])
    assert gap == pytest.approx(23.0 - 4.8) and v == 0.0  # coming towards B
    # A much faster car just ahead still leaves B its jam distance: B brakes.
    assert sims.guarded_speed_mps(11.0, 10.0, 0.5, 25.0, step) < 10.0


def test_scbg_b_waits_for_a_priority_car_it_would_hit(release):
    """At the junction, the release model's least courteous B plans to drive into A's path at
    seeds 9, 11 and 24: the crossing rule holds it, and it does not collide."""
    for seed in (9, 11, 24):
        r = sumo.episode(release, "sumo-4way", seed, {"kind": "scbg", "quantile": 0.1})
        assert not r["b_collided"] and r["b_held_steps"] > 0, (seed, r)


def test_scbg_b_stays_on_the_road_and_episodes_repeat(trained):
    model, _ = trained
    # Plan points within the 8 s: each plan's points up to the end of the 8 s.
    points = sum(sumo.FUTURE_STEPS - k for k in range(0, sumo.FUTURE_STEPS, sumo.REPLAN_EVERY))
    for scenario in sumo.SCENARIOS:
        steps = on_road = 0
        for seed in (0, 1):
            for q in (0.1, 0.9):
                r = sumo.episode(model, scenario, seed, {"kind": "scbg", "quantile": q})
                assert r["b_steps"] == 80 and r["b_plan_points"] == points, r
                assert 0 <= r["b_plan_points_on_road"] <= r["b_plan_points"]
                assert r["a_id"] == "A" and r["b_id"] == "B" and r["t0_s"] > 1.1
                assert math.isfinite(r["a_speed_mps"]) and r["a_speed_mps"] > 0
                steps += r["b_steps"]
                on_road += r["b_steps_on_road"]
        assert on_road >= 0.98 * steps, (scenario, on_road, steps)
        again = [sumo.episode(model, scenario, 1, {"kind": "scbg", "quantile": 0.9}) for _ in range(2)]
        assert again[0] == again[1]
        assert again[0] == sumo.episode(model, scenario, 1, {"kind": "scbg", "quantile": 0.9})
        # The takeover is the seed's, whoever drives B after it.
        assert sumo.episode(None, scenario, 1, {"kind": "default"})["t0_s"] == again[0]["t0_s"]


def test_yardstick_high_courtesy_lets_a_drive_faster():
    """SUMO's own B at its high courtesy setting never slows A more than at its low one, and
    over these seeds A is faster on the paired mean (at the junction seeds 1 and 6 respond, on
    the on-ramp six of the eight)."""
    for scenario in sumo.SCENARIOS:
        effects = []
        for seed in range(8):
            low = sumo.episode(None, scenario, seed, {"kind": "yardstick", "level": "low"})
            high = sumo.episode(None, scenario, seed, {"kind": "yardstick", "level": "high"})
            assert low["b_plan_points"] == high["b_plan_points"] == 0
            effects.append(high["a_speed_mps"] - low["a_speed_mps"])
        assert min(effects) > -1e-9, (scenario, effects)
        assert np.mean(effects) > 0.02, (scenario, effects)


def test_bad_requests_raise_value_error(trained):
    model, _ = trained
    with pytest.raises(ValueError, match="unknown SUMO scenario 'sumo-roundabout'"):
        sumo.episode(model, "sumo-roundabout", 0, {"kind": "default"})
    for q in (1.5, -0.1, float("nan"), "0.5", None):
        with pytest.raises(ValueError, match=r"quantile must be a number in \[0, 1\]"):
            sumo.episode(model, "sumo-4way", 0, {"kind": "scbg", "quantile": q})
    with pytest.raises(ValueError, match="level must be 'low', 'high' or a number"):
        sumo.episode(model, "sumo-onramp", 0, {"kind": "yardstick", "level": "medium"})
    with pytest.raises(ValueError, match="kind 'scbg', 'yardstick' or 'default'"):
        sumo.episode(model, "sumo-onramp", 0, {"kind": "idm"})
    with pytest.raises(ValueError, match="needs a model"):
        sumo.episode(None, "sumo-onramp", 0, {"kind": "scbg", "quantile": 0.5})
    with pytest.raises(ValueError, match=r"replan_every must be an integer in \[1, 80\]"):
        sumo.episode(model, "sumo-onramp", 0, {"kind": "scbg", "quantile": 0.5}, replan_every=0)


def test_the_release_models_knob_moves_a_at_the_junction(release):
    """At SUMO's priority junction, B at courtesy quantile 0.9 lets A drive faster than at 0.1,
    on the paired mean over episodes (same seed, same start, only the quantile changes), and
    B's plans stay on SUMO's road."""
    deltas, on_road = measure.paired_effect(release, "sumo-4way", range(8))
    assert np.mean(deltas) > 0.0, deltas
    assert on_road >= 0.98, on_road
