"""scbg inside highway-env (from PyPI): the conversion, the episodes and the measurement's numbers."""

import math
import os

import numpy as np
import pytest

from scbg.sims import measure


def _highway():
    try:
        import highway_env  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("highway-env is not installed (pip install highway-env)")
    from scbg.sims import highway

    return highway


def test_the_road_converts_to_scbg_frame_with_the_acceleration_lane_merging():
    highway = _highway()
    ep = highway._Episode("merge-v0", 0)
    try:
        road = ep.road
        assert len(ep.lanes) == len(road.network.lanes_list()) == len(ep.lane_types)
        assert set(ep.lane_types) == {"freeway"}
        # Every centre line point, flipped back, lies on a lane of highway-env's road.
        for line in ep.lanes:
            for p in line[:: max(1, len(line) // 8)]:
                assert highway.on_road(road, [p[0], -p[1]]), p
        # The acceleration lane (b, c, 2) ends on the right highway lane (b, c, 1): y = 4 m in
        # highway-env's frame, -4 m in scbg's; the straight highway lanes are untouched.
        accel = [line for line in ep.lanes if abs(line[0][1] + 8.0) < 1e-6 and line[0][0] == 230.0]
        assert len(accel) == 1 and np.allclose(accel[0][-1], [310.0, -4.0]), accel
        assert any(np.allclose(line[-1], [310.0, -8.0 + 4.0]) for line in ep.lanes)
        assert ep.edges and ep.lines
        # A car's state row is in scbg's frame: y and heading negated.
        v = ep.cars[0]
        row = highway._state_row(v)
        assert row[0] == v.position[0] and row[1] == -v.position[1]
        assert math.isclose(row[2], -v.heading)
        assert math.isclose(math.hypot(row[3], row[4]), v.speed, rel_tol=1e-9)
    finally:
        ep.close()


def test_b_changes_lanes_only_with_room_behind_it():
    """The gap acceptance B follows its plans by: merge-v0's ramp car, on the acceleration lane,
    may enter the right highway lane with nobody there near it, not with a car alongside it nor
    with a faster car close behind it there (one that would have to brake over 7 m/s²)."""
    highway = _highway()
    ep = highway._Episode("merge-v0", 0)
    try:
        lanes = ep.road.network
        accel, right = ("b", "c", 2), ("b", "c", 1)
        b, other = ep.road.vehicles[0], ep.road.vehicles[1]
        ep.road.vehicles[:] = [b, other]
        ep.b = b

        def place(v, lane, s_m, speed):
            v.position = lanes.get_lane(lane).position(s_m, 0.0)
            v.heading, v.speed = 0.0, speed
            v.on_state_update()

        place(b, accel, 30.0, 20.0)
        # Aiming at the right lane ahead is a lane change into it; along its own lane, none.
        assert highway._lane_change(ep, lanes.get_lane(right).position(40.0, 0.0)) == right
        assert highway._lane_change(ep, lanes.get_lane(accel).position(40.0, 0.0)) is None
        place(other, right, 0.0, 20.0)  # 30 m behind at B's speed
        assert highway._room_to_enter(ep, right)
        place(other, right, 28.0, 20.0)  # alongside
        assert not highway._room_to_enter(ep, right)
        place(other, right, 15.0, 30.0)  # 15 m behind, 10 m/s faster: needs 12.1 m of 10
        assert not highway._room_to_enter(ep, right)
        place(other, right, 10.0, 30.0)  # 20 m behind: 15 m of gap
        assert highway._room_to_enter(ep, right)
        place(other, accel, 15.0, 30.0)  # in B's own lane: not the lane it enters
        assert highway._room_to_enter(ep, right)
    finally:
        ep.close()


def test_an_episode_is_paired_and_deterministic(trained):
    highway = _highway()
    model, _ = trained
    low = highway.episode(model, "intersection-v0", 3, {"kind": "scbg", "quantile": 0.1})
    high = highway.episode(model, "intersection-v0", 3, {"kind": "scbg", "quantile": 0.9})
    own = highway.episode(None, "intersection-v0", 3, {"kind": "yardstick", "level": "high"})
    # The arms of one seed share the takeover step, A and B.
    assert low["t0_s"] == high["t0_s"] == own["t0_s"] and low["t0_s"] > 0
    assert low["a_id"] == high["a_id"] == own["a_id"] != low["b_id"] == high["b_id"]
    assert low["b_plan_points"] == 80 * 4 and own["b_plan_points"] == 0
    assert 0 <= low["b_plan_points_on_road"] <= low["b_plan_points"]
    assert 0 <= low["b_steps_on_road"] <= low["b_steps"] == 80
    assert highway.episode(model, "intersection-v0", 3, {"kind": "scbg", "quantile": 0.1}) == low


def test_highway_envs_own_courtesy_moves_a_at_the_intersection():
    """The yardstick is a yardstick: B always yielding to A lets A drive faster than B never
    yielding, on the paired mean over seeds."""
    highway = _highway()
    deltas = []
    for seed in range(6):
        never = highway.episode(None, "intersection-v0", seed, {"kind": "yardstick", "level": "low"})
        always = highway.episode(None, "intersection-v0", seed, {"kind": "yardstick", "level": "high"})
        deltas.append(always["a_speed_mps"] - never["a_speed_mps"])
    assert np.mean(deltas) > 0.3, deltas


def _taken_over(highway, model, scenario, seed, quantile=0.5):
    """An episode of ``scenario`` at its takeover step, B following scbg's plan: ``(ep, stats)``."""
    ep = highway._Episode(scenario, seed)
    for _ in range(highway.HISTORY_STEPS):
        ep.step()
    while (pair := highway._pair(ep)) is None:
        ep.step()
    ep.a, ep.b = pair
    stats = {"b_plan_points": 0, "b_plan_points_on_road": 0, "b_raw_plan_points_on_road": 0,
             "b_held_steps": 0}
    highway._follow_plan(ep, model, quantile, stats)
    return ep, stats


def test_b_in_contact_is_crashed_and_brakes_to_a_stop_as_highway_envs_cars_do(trained):
    """highway-env moves two cars about to touch apart by an impact, and each car's own step
    crashes it; B's step, which follows scbg's plan, does the same, and B then brakes to a stop
    without re-planning."""
    highway = _highway()
    model, _ = trained
    ep, stats = _taken_over(highway, model, "highway-v0", 0)
    try:
        ep.step()
        v0, planned = float(ep.b.speed), stats["b_plan_points"]
        ep.b.impact = np.array([0.0, 0.2])
        for _ in range(2 * highway.REPLAN_STEPS):
            ep.step()
        assert ep.b.crashed and ep.b.impact is None
        assert ep.b.speed < 0.05 * v0 and stats["b_plan_points"] == planned
    finally:
        ep.close()


def test_the_intersections_right_of_way_sees_where_b_goes(trained):
    """highway-env's intersection predicts each car along its route from the route's first road;
    B, driven by scbg, drops the roads it has finished as highway-env's cars do, so the
    prediction starts where B is."""
    highway = _highway()
    model, _ = trained
    ep, _ = _taken_over(highway, model, "intersection-v0", 3)
    try:
        start = ep.b.lane_index[:2]
        for _ in range(highway.MEASURE_STEPS):
            ep.step()
            if ep.b.lane_index[:2] != start:
                break
        assert ep.b.lane_index[:2] != start, "B never left its first road"
        assert ep.b.route[0][:2] == ep.b.lane_index[:2]
        predicted = np.array(ep.b.predict_trajectory_constant_speed(np.array([0.25]))[0][0])
        assert np.hypot(*(predicted - ep.b.position)) < 0.25 * ep.b.speed + 1.0
    finally:
        ep.close()


def test_bad_requests_are_named():
    highway = _highway()
    with pytest.raises(ValueError, match="unknown highway-env scenario 'merge-v9'"):
        highway.episode(None, "merge-v9", 0, {"kind": "default"})
    with pytest.raises(ValueError, match=r"quantile must be a number in \[0, 1\]"):
        highway.episode(None, "merge-v0", 0, {"kind": "scbg", "quantile": 1.5})
    with pytest.raises(ValueError, match="needs a model"):
        highway.episode(None, "merge-v0", 0, {"kind": "scbg", "quantile": 0.5})
    with pytest.raises(ValueError, match="level must be"):
        highway.episode(None, "merge-v0", 0, {"kind": "yardstick", "level": "medium"})
    with pytest.raises(ValueError, match="unknown scenario 'nope'"):
        measure._module("nope")


def test_spearman_handles_ties_and_constants():
    assert measure.spearman([1, 2, 3], [10, 20, 30]) == pytest.approx(1.0)
    assert measure.spearman([1, 2, 3], [3, 2, 1]) == pytest.approx(-1.0)
    assert measure.spearman([1, 2, 3, 4], [1, 1, 2, 2]) == pytest.approx(0.894427, abs=1e-6)
    assert math.isnan(measure.spearman([1, 2, 3], [5, 5, 5]))


def _record(speed, collided=False):
    return {"a_speed_mps": speed, "b_collided": collided, "b_plan_points": 80,
            "b_plan_points_on_road": 40, "b_steps": 80, "b_steps_on_road": 80}


def test_the_summary_is_paired_within_episodes():
    # Two episodes at very different speeds; within each, A rises with the quantile in the
    # first and does not respond in the second.
    seeds = []
    for base, slope in ((30.0, 1.0), (5.0, 0.0)):
        arms = {f"q{q:.1f}": _record(base + slope * q) for q in measure.QUANTILES}
        if slope == 0.0:  # B collides at q 0.9 of the unresponsive episode
            arms["q0.9"] = _record(base, True)
        arms.update(yardstick_low=_record(base), yardstick_high=_record(base + 0.5, True),
                    default=_record(base))
        seeds.append({"scenario": "s", "seed": len(seeds), "arms": arms})
    seeds.append({"scenario": "s", "seed": 2, "skipped": "never met"})
    s = measure.summarise(seeds)
    assert s["episodes"] == 2 and s["skipped"] == [{"seed": 2, "reason": "never met"}]
    assert s["effect_mps"] == pytest.approx(0.4)
    assert s["yardstick_effect_mps"] == pytest.approx(0.5)
    # The yardstick's high arm collided in both: no collision-free episode is left to it.
    assert s["effect_collision_free_mps"] == pytest.approx(0.8)  # the first episode alone
    assert math.isnan(s["yardstick_effect_collision_free_mps"])
    assert s["responsive_share"] == 0.5 and s["yardstick_responsive_share"] == 1.0
    assert s["spearman_responsive"] == pytest.approx(1.0)
    assert s["b_collision_rate"] == 0.1 and s["yardstick_b_collision_rate"] == 0.5
    assert s["b_plan_on_road_share"] == 0.5 and s["b_on_road_share"] == 1.0
    assert "| s | 2 |" in measure.table({"s": s}, {})
    assert math.isnan(s["yardstick_spearman_responsive"])  # two settings: no ranking


def test_the_yardsticks_own_spearman_ranks_its_settings_within_episodes():
    # Five settings: A rises with them in one episode, falls in another, and does not
    # respond in a third, which is left out.
    seeds = []
    for slope in (1.0, -1.0, 0.0):
        arms = {f"q{q:.1f}": _record(10.0) for q in measure.QUANTILES}
        for i, level in enumerate(measure.YARDSTICK_LEVELS):
            name = measure.arm_name({"kind": "yardstick", "level": level})
            arms[name] = _record(10.0 + slope * i)
        arms["default"] = _record(10.0)
        seeds.append({"scenario": "s", "seed": len(seeds), "arms": arms})
    s = measure.summarise(seeds)
    assert sorted(s["a_speed_mps"], key=str)[-1] == "yardstick_low"
    assert s["yardstick_spearman_responsive"] == pytest.approx(0.0)
    assert s["yardstick_responsive_share"] == pytest.approx(2 / 3)
    assert s["yardstick_effect_mps"] == pytest.approx(0.0)
    assert s["responsive_share"] == 0.0 and math.isnan(s["spearman_responsive"])


def test_a_yardstick_setting_between_its_ends():
    from scbg.sims import check_arm, yardstick_value

    highway = _highway()
    braking = highway.YARDSTICKS["merge-v0"]
    assert yardstick_value(braking, "low") == 8.0 and yardstick_value(braking, 1.0) == 0.5
    assert yardstick_value(braking, 0.5) == pytest.approx(4.25)
    # A right of way is graded by A's lead at the conflict: B yields at a lead over 1.5 s at a
    # quarter of the way, at any lead at three quarters.
    right_of_way = highway.YARDSTICKS["intersection-v0"]
    assert yardstick_value(right_of_way, 0.25) == pytest.approx(1.5)
    assert yardstick_value(right_of_way, 0.75) == pytest.approx(-1.5)
    with pytest.raises(ValueError, match="two settings only"):
        yardstick_value({"parameter": "p", "low": "off", "high": "on"}, 0.5)
    check_arm({"kind": "yardstick", "level": 0.25})
    for bad in (1.5, -0.1, True, float("nan")):
        with pytest.raises(ValueError, match="level must be"):
            check_arm({"kind": "yardstick", "level": bad})
    assert [a.get("level") for a in measure.arms("intersection-v0")][5:] == ["low", 0.25, 0.5, 0.75, "high", None]
    assert len(measure.arms("merge-v0")) == 11


def test_a_cars_way_starts_where_it_is_at_its_lanes_end():
    """highway-env drops a route's head 2.5 m before the lane ends, while the car's lane is
    still the old one: its way still starts at the car and runs on along the route."""
    highway = _highway()
    ep = highway._Episode("intersection-v0", 0)
    try:
        car = next(v for v in ep.road.vehicles if getattr(v, "route", None) and len(v.route) > 1)
        lane = ep.road.network.get_lane(car.lane_index)
        car.position = lane.position(lane.length - 1.0, 0.0)
        car.follow_road()  # the route's head goes, the lane stays
        assert car.route[0][:2] != car.lane_index[:2]
        way = highway._way(car)
        assert np.hypot(*(way[0] - car.position)) < 0.5
        assert np.hypot(*(way[5] - car.position)) == pytest.approx(10.0, abs=1.5)
    finally:
        ep.close()


def test_the_graded_right_of_way_yields_to_an_a_that_arrives_first():
    """Halfway between never and always, B yields exactly when A reaches the conflict first; a
    quarter of the way, only to an A more than 1.5 s ahead; the ends are never and always."""
    from types import SimpleNamespace

    highway = _highway()

    def yields(level, lead_s):
        a, b = object(), object()
        road = SimpleNamespace(respect_priorities=lambda v1, v2: None)
        ep = SimpleNamespace(scenario="intersection-v0", a=a, b=b, road=road, lead_s=lead_s)
        highway._apply_yardstick(ep, level)
        return road.respect_priorities(a, b) is b

    assert yields(0.5, 1.0) and not yields(0.5, -1.0)
    assert not yields(0.25, 1.0) and yields(0.25, 2.0)
    assert not yields("low", 2.0) and yields("high", -2.0)


def test_conflict_pairs_are_cars_whose_ways_meet_ahead_of_a():
    """intersection-v0 and roundabout-v0: B's way meets A's ahead of A within the pairing's
    lead; a car on A's own way (A itself, or one behind it in its lane) is never B."""
    highway = _highway()
    from highway_env.vehicle.behavior import IDMVehicle

    for scenario in ("intersection-v0", "roundabout-v0"):
        ep = highway._Episode(scenario, 0)
        try:
            for _ in range(highway.HISTORY_STEPS):
                ep.step()
            a, b = highway._pair(ep)
            lead_s = highway._meeting_lead_s(a, b)
            assert abs(lead_s) <= highway.PAIR_LEAD_S and b.lane_index[0] != a.lane_index[0]
            apart_m, along_m, _ = highway._along_way(highway._way(b, highway.PAIR_REACH_M),
                                                     highway._way(a, highway.PAIR_REACH_M))
            assert apart_m.min() < highway.PAIR_GAP_M and along_m[apart_m.argmin()] >= 0.0
            assert highway._meeting_lead_s(a, a) is None
            lane = ep.road.network.get_lane(a.lane_index)
            s_a, _ = lane.local_coordinates(a.position)
            behind = IDMVehicle(ep.road, lane.position(s_a - 10.0, 0.0), lane.heading_at(s_a - 10.0), a.speed)
            behind.route = list(a.route or [])
            assert highway._meeting_lead_s(a, behind) is None
        finally:
            ep.close()


def test_the_release_models_knob_moves_a_behind_b_on_the_highway(release):
    """highway-v0, B the car ahead of A in its lane: at courtesy quantile 0.9 A drives faster
    than at 0.1 on the paired mean over episodes (same seed, only the quantile changes), no
    episode goes clearly the wrong way, and B's followed plans stay on highway-env's road."""
    _highway()
    deltas, on_road = measure.paired_effect(release, "highway-v0", range(12))
    assert np.mean(deltas) > 0.1 and min(deltas) > -0.1, deltas
    assert on_road >= 0.85, on_road


def test_the_ramp_car_waits_for_room_instead_of_side_swiping_a(release_member, release):
    """merge-v0 seeds where one model's plan moves B into A alongside (seed 0 at q 0.9, seed 1 at
    q 0.1): B waits in its lane until it has room, and merges without a collision; the release
    ensemble merges there without one too."""
    highway = _highway()
    for seed, quantile in ((0, 0.9), (1, 0.1)):
        arm = {"kind": "scbg", "quantile": quantile}
        r = highway.episode(release_member, "merge-v0", seed, arm)
        assert r["b_held_steps"] > 0 and not r["b_collided"] and r["b_reached_goal"], (seed, r)
        r = highway.episode(release, "merge-v0", seed, arm)
        assert not r["b_collided"] and r["b_reached_goal"], (seed, r)
