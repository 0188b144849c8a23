"""scbg drives one car (B) inside highway-env, among highway-env's own IDM + MOBIL cars.

highway-env (https://github.com/Farama-Foundation/HighwayEnv, ``pip install highway-env``)
simulates highways, merges, intersections and roundabouts. Each episode here:

1. builds one of highway-env's environments with a seed, and replaces its action-driven ego by
   one of the simulator's own IDM cars, so that every car but B is highway-env's;
2. lets highway-env drive everyone until the *takeover step* ``t0``: the first step at which the
   scenario's B is close to the place where it meets A (the same step in every arm of a seed);
3. from ``t0`` on, drives B by the arm: scbg at a courtesy quantile (B re-planned every 2 s, as
   scbg's own closed loop re-plans it, from the last 1.1 s of every car and highway-env's road
   network, converted to an scbg scene with :func:`scbg.Scene.from_arrays`; B follows the plan
   point by point, kept in lane with :meth:`scbg.Scene.keep_in_lane` as scbg's own closed loop
   keeps it), or
   highway-env's own model at a low or high setting of its own courtesy parameter (the
   yardstick), or highway-env's default;
4. measures A's mean speed over the 8 s after ``t0``, B's collisions and whether B and its plans
   stay on the road.

Frames: highway-env's y axis points to the right of travel; scbg's to the left. Positions are
converted by flipping y, headings by negating them.

Scenarios (``SCENARIOS``): ``merge-v0`` (B the ramp car, A the highway car it meets),
``highway-v0`` (B the car ahead of A in A's lane), ``highway-v0-cutin`` (B a car beside A that
changes into A's lane ahead of it), ``intersection-v0`` (B a car whose path crosses A's) and
``roundabout-v0`` (B a car whose way meets A's, from another road, nearest in time to A: mostly
one circulating while A enters).
"""

from __future__ import annotations

import numpy as np

import scbg

from . import (CROSS_LOOKAHEAD_M, CROSS_REACH_M, GUARD_LOOKAHEAD_M, _along_way, arc_lengths as _arc, check_arm,
               crossing_rule, guarded_speed_mps, held_speed_mps, leader_on_path, path_samples, point_at as _at,
               yardstick_value)

STEP_SECS = 0.1
HISTORY_STEPS = 11  # 1.1 s, the current step included
MEASURE_STEPS = 80  # 8 s after the takeover
REPLAN_STEPS = 20  # B re-planned every 2 s, as scbg's own closed loop re-plans the generator's B
LANE_KEEPING_M = 0.25  # B follows its plan kept in lane, as scbg's own closed loop does
LENGTH_M, WIDTH_M = 5.0, 2.0  # highway-env's vehicle box
MAX_WARMUP_STEPS = 400
# intersection and roundabout: A and B reach the place where their ways meet at most PAIR_LEAD_S
# apart, the first of them PAIR_HORIZON_S from it; ways meet where their centre lines come closer
# than PAIR_GAP_M (a car's width plus a metre: the roundabout's two ring lanes, 4 m apart, do not).
PAIR_LEAD_S = 3.0
PAIR_HORIZON_S = 6.0
PAIR_GAP_M = 3.0
PAIR_REACH_M = 120.0

SCENARIOS = {
    "merge-v0": "highway-env's on-ramp: B the ramp car merging, A the right-lane highway car it meets",
    "highway-v0": "highway-env's 4-lane highway: B the car ahead of A in A's lane",
    "highway-v0-cutin": "highway-env's 4-lane highway: B a car beside A changing into A's lane ahead of it",
    "intersection-v0": "highway-env's unsignalised 4-way junction: B a car whose path crosses A's",
    "roundabout-v0": "highway-env's roundabout: B a car whose way meets A's, mostly one circulating while A "
                     "enters",
}

# highway-env's own idea of B's courtesy toward A, per scenario: the parameter set on B from the
# takeover on, at a low and a high courtesy.
YARDSTICKS = {
    "merge-v0": {"parameter": "LANE_CHANGE_MAX_BRAKING_IMPOSED", "low": 8.0, "high": 0.5,
                 "note": "MOBIL's limit on the braking B's lane change may impose on its new follower (m/s²)"},
    "highway-v0": {"parameter": "POLITENESS", "low": 0.0, "high": 1.0,
                   "note": "MOBIL's politeness: the weight B gives its followers' gain when it changes lanes"},
    "highway-v0-cutin": {"parameter": "LANE_CHANGE_MAX_BRAKING_IMPOSED", "low": 8.0, "high": 0.5,
                         "note": "MOBIL's limit on the braking B's lane change may impose on its new follower (m/s²)"},
    "intersection-v0": {"parameter": "yields", "low": "never", "high": "always", "lead_s": 2 * PAIR_LEAD_S,
                        "note": "highway-env's priority rule, per car: B never yields / B always yields to A; "
                                "between, B yields when A's lead at the conflict exceeds 6 × (0.5 − level) s"},
    "roundabout-v0": {"parameter": "yields", "low": "never", "high": "always", "lead_s": 2 * PAIR_LEAD_S,
                      "note": "B never waits / B waits at the conflict until A has passed it; "
                              "between, B waits when A's lead at the conflict exceeds 6 × (0.5 − level) s"},
}

_LANE_TYPES = {
    "merge-v0": "freeway",
    "highway-v0": "freeway",
    "highway-v0-cutin": "freeway",
    "intersection-v0": "surface_street",
    "roundabout-v0": "surface_street",
}

_ENV_CONFIG = {
    "merge-v0": ("merge-v0", {}),
    "highway-v0": ("highway-v0", {"vehicles_count": 20, "lanes_count": 3, "vehicles_density": 2.0}),
    "highway-v0-cutin": ("highway-v0", {"vehicles_count": 20, "lanes_count": 3, "vehicles_density": 2.0}),
    "intersection-v0": ("intersection-v0", {"initial_vehicle_count": 6, "spawn_probability": 0.0}),
    "roundabout-v0": ("roundabout-v0", {}),
}


def _imports():
    try:
        import gymnasium
        import highway_env  # noqa: F401  (registers the environments)
    except ImportError as e:  # pragma: no cover - depends on the user's environment
        raise ImportError("scbg.sims.highway needs highway-env: pip install highway-env") from e
    gymnasium.logger.min_level = 40  # highway-env's environments warn that v0 has a v1 on every make
    return gymnasium


def _idm_class_defaults():
    from highway_env.vehicle.behavior import IDMVehicle

    names = [n for n in vars(IDMVehicle) if n.isupper()]
    return {n: getattr(IDMVehicle, n) for n in names}


_IDM_DEFAULTS = None


def _restore_idm_defaults():
    """intersection-v0 changes IDMVehicle's class attributes for the whole process; every
    episode starts from highway-env's own defaults."""
    global _IDM_DEFAULTS
    from highway_env.vehicle.behavior import IDMVehicle

    if _IDM_DEFAULTS is None:
        _IDM_DEFAULTS = _idm_class_defaults()
    for k, v in _IDM_DEFAULTS.items():
        setattr(IDMVehicle, k, v)


def _flip(p):
    return np.array([p[0], -p[1]])


TAPER_M = 40.0  # a lane ending beside a neighbour merges into it over its last 40 m


def _ends_beside(network, index):
    """The neighbour lane a lane merges into: the lane ends (nothing continues it at its index
    while its neighbour's road does continue) and has a neighbour to one side; else None."""
    _from, _to, _id = index
    nxt = network.graph.get(_to, {})
    if any(len(lanes) > _id for lanes in nxt.values()):
        return None
    for side in (_id - 1, _id + 1):
        if 0 <= side < len(network.graph[_from][_to]) and any(len(lanes) > side for lanes in nxt.values()):
            return network.get_lane((_from, _to, side))
    return None


def road_map(road, lane_type):
    """highway-env's road network as scbg's map (scbg's frame): lane centre lines every 2 m,
    road edges where a lane side has a continuous line, road lines (broken white) where it is
    striped, and the scenario's lane type.

    A lane that ends beside a neighbouring lane (merge-v0's acceleration lane, ending at a wall)
    is drawn merging into that neighbour over its last ``TAPER_M``: that is how an on-ramp's
    lane runs in WOMD's maps and in scbg's synthetic world, and the only way a lane-following
    model can read that the lane's cars must merge."""
    from highway_env.road.lane import LineType

    network = road.network
    lanes, edges, lines = [], [], []
    for _from, to_dict in network.graph.items():
        for _to, ids in to_dict.items():
            for _id, lane in enumerate(ids):
                s = np.linspace(0.0, lane.length, max(2, int(np.ceil(lane.length / 2.0)) + 1))
                into = _ends_beside(network, (_from, _to, _id))
                if into is None:
                    centre = [lane.position(t, 0.0) for t in s]
                else:
                    start = lane.length - TAPER_M

                    def point(t):
                        if t <= start:
                            return lane.position(t, 0.0)
                        w = min((t - start) / TAPER_M, 1.0)
                        w = 0.5 - 0.5 * np.cos(np.pi * w)
                        target = into.position(*into.local_coordinates(lane.position(t, 0.0))[:1], 0.0)
                        return (1.0 - w) * lane.position(t, 0.0) + w * target

                    centre = [point(t) for t in s]
                lanes.append(np.array([_flip(p) for p in centre]))
                for side, lat in ((0, -0.5), (1, 0.5)):
                    kind = lane.line_types[side]
                    if kind in (LineType.CONTINUOUS_LINE, LineType.STRIPED):
                        line = np.array([_flip(lane.position(t, lat * lane.width_at(t))) for t in s])
                        (edges if kind == LineType.CONTINUOUS_LINE else lines).append(line)
    return lanes, edges, lines, [lane_type] * len(lanes)


def _row(v):
    """A car's state row in highway-env's own frame: x, y, heading, vx, vy, length, width."""
    h = float(v.heading)
    return [v.position[0], v.position[1], h, v.speed * np.cos(h), v.speed * np.sin(h), LENGTH_M, WIDTH_M]


def _state_row(v):
    """:func:`_row` in scbg's frame (y and headings flipped)."""
    x, y, h, vx, vy, length, width = _row(v)
    return [x, -y, -h, vx, -vy, length, width]


def on_road(road, xy_highway):
    """Whether a point (highway-env's frame) lies on some lane of the road."""
    index = road.network.get_closest_lane_index(np.asarray(xy_highway, float))
    lane = road.network.get_lane(index)
    return bool(lane.on_lane(np.asarray(xy_highway, float)))


class _Episode:
    """One episode's simulator, cars, history and the chosen A and B."""

    def __init__(self, scenario, seed):
        gymnasium = _imports()
        from highway_env.vehicle.behavior import IDMVehicle

        _restore_idm_defaults()
        env_id, config = _ENV_CONFIG[scenario]
        config = dict(config, simulation_frequency=10, policy_frequency=10)
        self.env = gymnasium.make(env_id, config=config)
        self.env.reset(seed=seed)
        self.scenario = scenario
        self.road = self.env.unwrapped.road
        self.rng = np.random.default_rng(seed)
        # The ego follows actions; make it one of highway-env's own IDM cars on the same route.
        ego = self.env.unwrapped.vehicle
        k = self.road.vehicles.index(ego)
        idm = IDMVehicle.create_from(ego)
        idm.route = list(getattr(ego, "route", None) or []) or None
        if hasattr(ego, "target_lane_index"):
            idm.target_lane_index = ego.target_lane_index
        idm.target_speed = max(ego.speed, getattr(ego, "target_speed", ego.speed))
        self.road.vehicles[k] = idm
        self.ego = idm
        if scenario == "merge-v0":
            self._jitter()
        self.lanes, self.edges, self.lines, self.lane_types = road_map(self.road, _LANE_TYPES[scenario])
        self.history = []  # [step][car] state rows, in the order of self.cars
        self.cars = list(self.road.vehicles)
        self.a = self.b = None
        self.lead_s = None  # intersection and roundabout: A's lead where the ways of A and B meet
        self._record()

    def _jitter(self):
        """merge-v0's own start varies little with the seed (a few metres; the other
        environments draw their traffic at random): every car but the ego is moved along its
        lane by up to ±12 m and its speed changed by up to ±2 m/s, drawn from the seed, so that
        seeds are different situations."""
        for v in self.road.vehicles:
            if v is self.ego:
                continue
            lane = self.road.network.get_lane(v.lane_index)
            s_m, _ = lane.local_coordinates(v.position)
            s_m = float(np.clip(s_m + self.rng.uniform(-12.0, 12.0), 0.0, lane.length))
            v.position = lane.position(s_m, 0.0)
            v.heading = lane.heading_at(s_m)
            v.speed = max(0.0, v.speed + self.rng.uniform(-2.0, 2.0))
            v.on_state_update()

    def _record(self):
        # Cars that appear later (spawned) are not followed: the scene is the cars at reset.
        self.history.append([_state_row(v) for v in self.cars])

    def step(self):
        self.road.act()
        self.road.step(STEP_SECS)
        self._record()

    def close(self):
        self.env.close()

    # ---- the scene scbg sees ----

    def scene(self, steps_done):
        recent = np.array(self.history[-HISTORY_STEPS:])  # [steps, cars, 7]
        n = recent.shape[1]
        states = np.zeros((n, HISTORY_STEPS + MEASURE_STEPS, 7))
        states[:, :HISTORY_STEPS] = recent.transpose(1, 0, 2)
        valid = np.zeros(states.shape[:2], bool)
        valid[:, :HISTORY_STEPS] = True
        ids = np.arange(1, n + 1, dtype=np.int64)
        a, b = self.cars.index(self.a) + 1, self.cars.index(self.b) + 1
        return scbg.Scene.from_arrays(
            f"highway-env-{self.scenario}-{steps_done}", ids, states, valid,
            current_step=HISTORY_STEPS - 1, sdc_id=a, objects_of_interest=[a, b],
            lanes=self.lanes, road_edges=self.edges, road_lines=self.lines,
            lane_types=self.lane_types), a, b


# ---- scenario set-ups: when to take over, and which cars are A and B ----


def _lane_x(v):
    return float(v.position[0])


# merge-v0's acceleration lane runs from x = 230 m (the ramp's end) to 310 m (a wall).
MERGE_TAKEOVER_X_M = 240.0


def _merge_pair(ep):
    """merge-v0: B = the ramp car once it is on the acceleration lane; A = the right-lane
    highway car nearest behind it (the one whose gap B merges into)."""
    ramp = [v for v in ep.cars if v.lane_index[0] in ("j", "k") or v.lane_index[2] == 2]
    if not ramp:
        return None
    b = ramp[0]
    if not (b.lane_index[:2] == ("b", "c") and _lane_x(b) >= MERGE_TAKEOVER_X_M):
        return None
    right = [v for v in ep.cars if v is not b and v.lane_index[2] == 1 and v.lane_index[0] != "j"
             and _lane_x(b) - 60.0 < _lane_x(v) < _lane_x(b) + 10.0]
    if not right:
        return None
    a = min(right, key=lambda v: abs(_lane_x(v) - _lane_x(b) + 10.0))
    return a, b


def _highway_pair(ep, cut_in):
    """highway-v0: A = the ego; B = the car ahead of it in its lane (follow), or the nearest car
    in a neighbouring lane a little ahead of it, which then changes into A's lane (cut-in)."""
    a = ep.ego
    lane = a.lane_index
    if cut_in:
        side = [v for v in ep.cars if v is not a and abs(v.lane_index[2] - lane[2]) == 1
                and 5.0 < _lane_x(v) - _lane_x(a) < 30.0]
        if not side:
            return None
        return a, min(side, key=lambda v: _lane_x(v) - _lane_x(a))
    ahead = [v for v in ep.cars if v is not a and v.lane_index[2] == lane[2]
             and 0.0 < _lane_x(v) - _lane_x(a) < 60.0]
    if not ahead:
        return None
    return a, min(ahead, key=lambda v: _lane_x(v) - _lane_x(a))


def _meeting_lead_s(a, b):
    """Where the ways of A and B (:func:`_way`, out to :data:`PAIR_REACH_M`) first meet along
    B's, B's lead (s) over A there: B's time to the meeting place less A's, each at its speed
    now; None where B starts on A's way, the ways do not meet, or they meet behind A."""
    way_a, way_b = _way(a, PAIR_REACH_M), _way(b, PAIR_REACH_M)
    if way_a is None or way_b is None:
        return None
    apart_m, along_a_m, _ = _along_way(way_b, way_a)
    meets = apart_m < PAIR_GAP_M
    if not meets.any() or meets[0]:
        return None
    i = int(meets.argmax())
    if along_a_m[i] < 0.0:
        return None
    t_a = along_a_m[i] / max(float(a.speed), 1.0)
    t_b = _arc(way_b)[i] / max(float(b.speed), 1.0)
    if max(t_a, t_b) > PAIR_HORIZON_S:
        return None
    return t_b - t_a


def _conflict_pair(ep):
    """intersection-v0 / roundabout-v0: A = the ego; B = the car from another road whose way
    meets A's ahead of A nearest in time to A (:func:`_meeting_lead_s`), once the first of them
    is :data:`PAIR_HORIZON_S` from the meeting place and B's lead is within
    :data:`PAIR_LEAD_S`."""
    a = ep.ego
    leads = {v: _meeting_lead_s(a, v) for v in ep.cars if v is not a and v.lane_index[0] != a.lane_index[0]}
    leads = {v: t for v, t in leads.items() if t is not None and abs(t) <= PAIR_LEAD_S}
    if not leads:
        return None
    return a, min(leads, key=lambda v: abs(leads[v]))


def _pair(ep):
    if ep.scenario == "merge-v0":
        return _merge_pair(ep)
    if ep.scenario == "highway-v0":
        return _highway_pair(ep, cut_in=False)
    if ep.scenario == "highway-v0-cutin":
        return _highway_pair(ep, cut_in=True)
    return _conflict_pair(ep)


# ---- the arms ----


def _apply_yardstick(ep, level):
    ys = YARDSTICKS[ep.scenario]
    value = yardstick_value(ys, level)
    b, a = ep.b, ep.a
    if ys["parameter"] == "yields":
        if level not in ("low", "high"):  # graded: decided once, by A's lead at the takeover
            value = "always" if ep.lead_s > value else "never"
        road = ep.road
        if hasattr(road, "respect_priorities"):
            rule = road.respect_priorities

            def respect(v1, v2):
                if {v1, v2} == {a, b}:
                    return b if value == "always" else a
                return rule(v1, v2)

            road.respect_priorities = respect
        if ep.scenario == "roundabout-v0" and value == "always":
            _make_b_wait_for_a(ep)
        return
    setattr(b, ys["parameter"], value)


def _make_b_wait_for_a(ep):
    """The roundabout's courteous arm: B treats A as a car ahead of it until A has passed B."""
    a, b = ep.a, ep.b
    act = b.act

    def act_waiting(action=None):
        act(action)
        ahead = np.dot(a.position - b.position, [np.cos(b.heading), np.sin(b.heading)])
        if ahead > -LENGTH_M and np.linalg.norm(a.position - b.position) < 40.0:
            acc = b.acceleration(ego_vehicle=b, front_vehicle=a)
            b.action["acceleration"] = min(b.action["acceleration"], acc)

    b.act = act_waiting


# B's gap acceptance, the rule of scbg's own closed loop (and of the synthetic world's least
# courteous B): B changes into a lane only when no car there is alongside it and the car behind
# it there can stay behind braking at most GAP_BRAKE_MPS2 after GAP_REACTION_S; until then it
# keeps to its lane at the plan's timing, behind the follow-distance guard. Where its plan crosses
# another road, the same rule holds it before the crossing (:func:`scbg.sims.crossing_rule`).
GAP_BRAKE_MPS2 = 7.0
GAP_REACTION_S = 0.5
GAP_REACH_M = 60.0  # cars farther than this from B are never in the way of its lane change
CATCH_UP_MPS2 = 3.0  # after a hold B catches up with its plan's timing at IDM's acceleration
# B's path tracker: pure pursuit of a point this far ahead along the plan, yaw rate bounded.
TRACK_LOOKAHEAD_M = 4.0
TRACK_LOOKAHEAD_S = 0.6
TRACK_YAW_RATE = 0.8  # rad/s


def _leader_gap(ep, samples, s):
    """:func:`scbg.sims.leader_on_path` among highway-env's cars and obstacles (merge-v0's wall
    at the end of the acceleration lane)."""
    others = [v for v in list(ep.road.vehicles) + list(ep.road.objects) if v is not ep.b]
    return leader_on_path(samples, s, [v.position for v in others], [v.velocity for v in others],
                          [LENGTH_M] * len(others))


def _lane_change(ep, target):
    """The lane B's pursuit of ``target`` changes into (a lane beside B's, on the same road
    segment), or None while the target is in B's own lane or B turns onto another road."""
    b = ep.b
    here = ep.road.network.get_lane(b.lane_index)
    s_m, lateral_m = here.local_coordinates(np.asarray(target, float))
    if abs(lateral_m) <= 0.5 * here.width_at(s_m):
        return None
    to = ep.road.network.get_closest_lane_index(np.asarray(target, float), b.heading)
    return to if to[:2] == b.lane_index[:2] and to != b.lane_index else None


def _room_to_enter(ep, lane_index):
    """Whether B may enter lane ``lane_index`` now (:data:`GAP_BRAKE_MPS2`): no car of that lane
    alongside it, and the car behind it there can stay behind."""
    b = ep.b
    lane = ep.road.network.get_lane(lane_index)
    s_b, _ = lane.local_coordinates(b.position)
    for v in ep.road.vehicles:
        if v is b or np.hypot(*(v.position - b.position)) > GAP_REACH_M:
            continue
        s_v, lateral_m = lane.local_coordinates(v.position)
        if abs(lateral_m) > 0.5 * lane.width_at(s_v):
            continue
        ahead_m = s_b - s_v
        if abs(ahead_m) < LENGTH_M:
            return False
        closing = float(v.speed - b.speed)
        if ahead_m > 0.0 and closing > 0.0:
            needed = closing * GAP_REACTION_S + closing * closing / (2.0 * GAP_BRAKE_MPS2)
            if ahead_m - LENGTH_M < needed:
                return False
    return True


def _way(v, reach_m=CROSS_REACH_M):
    """The path (highway-env's frame) car ``v`` will drive from where it is, along its route as
    highway-env itself predicts it, every 2 m up to ``reach_m`` (cut where
    highway-env's guess of a lane on the route's next road fails); None for a car without a
    lane."""
    lane = getattr(v, "lane", None)
    if lane is None:
        return None
    s_m, _ = lane.local_coordinates(v.position)
    route = list(getattr(v, "route", None) or [])
    # highway-env drops a route's head 2.5 m before the lane ends and names its lane by its
    # road only: the route from the lane the car is on.
    if route and route[0][:2] == v.lane_index[:2]:
        route = [v.lane_index] + route[1:]
    elif route and route[0][0] == v.lane_index[1]:
        route = [v.lane_index] + route
    else:
        route = route or [v.lane_index]
    network = v.road.network
    way = []
    for d in np.arange(0.0, reach_m + 1e-9, 2.0):
        try:
            way.append(network.position_heading_along_route(route, s_m + d, 0.0, v.lane_index)[0])
        except (IndexError, KeyError):  # a lane id the route's next road lacks
            break
    return np.array(way) if len(way) >= 2 else None


def _drop_finished_roads(v):
    """Drops the roads ``v`` has finished from the front of its route, as highway-env's own cars
    do on reaching a lane's end (``RoadNetwork.next_lane``). The intersection's right of way
    predicts each car along its route from the route's first road (``ControlledVehicle.
    predict_trajectory_constant_speed``): with its spawn road still first, B's predicted path
    lies back where it entered and no car ever yields to it."""
    route = getattr(v, "route", None)
    roads = [r[:2] for r in route or []]
    if v.lane_index is not None and v.lane_index[:2] in roads:
        del route[:roads.index(v.lane_index[:2])]


def _lookahead(speed_mps):
    """How far ahead of B's progress its path tracker aims, metres."""
    return max(TRACK_LOOKAHEAD_M, speed_mps * TRACK_LOOKAHEAD_S)


def _follow_plan(ep, model, quantile, stats):
    """B follows scbg's plan (inside highway-env's own step, so collisions are checked where B
    really is): along the plan's path, kept in lane, on the plan's timing, but never faster than
    the follow-distance guard allows behind a car in its way, steered by pure pursuit."""
    b = ep.b
    state = {"path": None, "arc": None, "s": 0.0, "k": 0, "since": 0}

    def replan():
        scene, a_id, b_id = ep.scene(len(ep.history))
        raw = np.asarray(model.generate(scene, a_id, b_id, quantile=quantile)["world_xy_m"], float)
        kept = scene.keep_in_lane(raw, LANE_KEEPING_M, agent_id=b_id)
        flip = np.array([1.0, -1.0])  # back to highway-env's frame
        path = np.vstack([b.position, kept * flip])
        arc = _arc(path)
        state.update(path=path, arc=arc, samples=path_samples(path, arc), s=0.0, k=0)
        stats["b_plan_points"] += len(kept)
        stats["b_plan_points_on_road"] += sum(on_road(ep.road, p) for p in kept * flip)
        stats["b_raw_plan_points_on_road"] += sum(on_road(ep.road, p) for p in raw * flip)

    def act(action=None):
        if state["path"] is None or state["since"] >= REPLAN_STEPS:
            replan()
            state["since"] = 0

    own_step = b.step

    def step(dt):
        if b.crashed or b.impact is not None:
            # highway-env's collision check found B in contact (or about to be, which moves both
            # cars apart by an impact): B is crashed, and brakes to a stop as its own cars do.
            b.action = {"steering": 0.0, "acceleration": -float(b.speed)}
            own_step(dt)
            return
        path, arc = state["path"], state["arc"]
        k = min(state["k"] + 1, len(arc) - 1)
        planned = max(arc[k] - state["s"], 0.0) / dt  # the speed that keeps the plan's timing
        v = float(b.speed)
        if state["s"] < arc[k - 1] - 1e-6:  # behind the plan's timing after a hold: catch up
            planned = min(planned, v + CATCH_UP_MPS2 * dt)
        def aim(speed_mps):  # the path point the tracker heads for from B's progress
            return _at(path, arc, min(state["s"] + _lookahead(speed_mps), arc[-1]))[0]

        samples, s_guard, here = state["samples"], state["s"], None
        into = _lane_change(ep, aim(planned))
        if into is not None and not _room_to_enter(ep, into):
            # No room yet: on along B's own lane, the guard watching that lane.
            here = ep.road.network.get_lane(b.lane_index)
            s_here, _ = here.local_coordinates(b.position)
            samples = np.array([here.position(s_here + i, 0.0) for i in range(int(GUARD_LOOKAHEAD_M) + 1)])
            s_guard = 0.0
            stats["b_held_steps"] += 1
        gap, v_lead = _leader_gap(ep, samples, s_guard)
        planned = guarded_speed_mps(planned, v, gap, v_lead, dt)
        if here is None:  # where B's plan crosses another road, the crossing rule
            cars = [u for u in ep.road.vehicles if u is not b
                    and np.hypot(*(u.position - b.position)) < CROSS_REACH_M + CROSS_LOOKAHEAD_M]
            hold, committed = crossing_rule(path, arc, state["s"], _row(b), [_row(u) for u in cars],
                                            ways=[_way(u) for u in cars])
            limit = held_speed_mps(hold, state["s"], dt) if np.isfinite(hold) else np.inf
            if planned > limit:
                planned = limit
                stats["b_held_steps"] += 1
            elif committed and not hasattr(ep.road, "respect_priorities"):
                # Too late to stop, on a road without a right of way (the roundabout: its cars
                # see B only once it is on their lane, so one entering does not yield to B): B
                # goes on at its speed, the follow-distance guard still ruling, rather than slow
                # down in the way of a car that cannot stop. Where highway-env's road yields by
                # priority (the intersection), B keeps to its plan.
                planned = max(planned, guarded_speed_mps(v, v, gap, v_lead, dt))
        state["s"] = min(state["s"] + planned * dt, arc[-1])
        # Pure pursuit of the path (a lane change is steered, not jumped): head for the path
        # point a look-ahead beyond B's progress (B's own lane's while held), turning at most
        # TRACK_YAW_RATE.
        if here is None:
            target = aim(planned)
        else:
            target = here.position(s_here + _lookahead(planned), 0.0)
        d = target - b.position
        if np.hypot(*d) > 1e-3 and planned > 0.0:
            turn = (np.arctan2(d[1], d[0]) - b.heading + np.pi) % (2.0 * np.pi) - np.pi
            limit = TRACK_YAW_RATE * dt
            b.heading = float(b.heading + np.clip(turn, -limit, limit))
        b.speed = planned
        b.position = b.position + planned * dt * np.array([np.cos(b.heading), np.sin(b.heading)])
        b.on_state_update()
        _drop_finished_roads(b)
        state["k"] = k
        state["since"] += 1

    b.act, b.step = act, step


def episode(model, scenario: str, seed: int, arm: dict, trace: list | None = None) -> dict:
    """One episode of ``scenario`` with ``seed``, B driven by ``arm``:
    ``{"kind": "scbg", "quantile": q}``, ``{"kind": "yardstick", "level": "low" | "high"}`` or
    ``{"kind": "default"}``; ``model`` (a :class:`scbg.Model`) is needed for scbg arms only.

    Returns A's mean speed over the 8 s after the takeover, B's collision, and how many of B's
    planned points (as followed, and as generated before lane keeping) and realised positions
    lie on highway-env's road. ``trace``, when given, receives per measured step A's and B's
    position (scbg's frame) and speed. Raises ``ValueError`` for an unknown
    scenario or arm, and ``RuntimeError`` when the seed never brings A and B together."""
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown highway-env scenario {scenario!r}: expected one of {sorted(SCENARIOS)}")
    check_arm(arm)
    if arm["kind"] == "scbg" and model is None:
        raise ValueError("an scbg arm needs a model")
    ep = _Episode(scenario, seed)
    try:
        warm = 0
        while True:
            pair = _pair(ep) if warm >= HISTORY_STEPS - 1 else None
            if pair is not None:
                break
            if warm >= MAX_WARMUP_STEPS:
                raise RuntimeError(f"{scenario} seed {seed}: A and B never met in {MAX_WARMUP_STEPS} steps")
            ep.step()
            warm += 1
        ep.a, ep.b = pair
        if scenario in ("intersection-v0", "roundabout-v0"):
            ep.lead_s = _meeting_lead_s(ep.a, ep.b)  # A's lead at the takeover: B's time less A's
        if ep.a.crashed or ep.b.crashed:
            raise RuntimeError(f"{scenario} seed {seed}: A or B crashed before the takeover")
        stats = {"b_plan_points": 0, "b_plan_points_on_road": 0, "b_raw_plan_points_on_road": 0,
                 "b_held_steps": 0}
        if arm["kind"] == "scbg":
            _follow_plan(ep, model, float(arm["quantile"]), stats)
        elif arm["kind"] == "yardstick":
            _apply_yardstick(ep, arm["level"])
        a_speeds, b_on_road, b_crashed = [], 0, False
        for _ in range(MEASURE_STEPS):
            ep.step()
            a_speeds.append(float(ep.a.speed))
            b_on_road += on_road(ep.road, ep.b.position)
            b_crashed |= bool(ep.b.crashed)
            if trace is not None:
                trace.append({"a_xy_m": _flip(ep.a.position).tolist(), "b_xy_m": _flip(ep.b.position).tolist(),
                              "a_speed_mps": float(ep.a.speed), "b_speed_mps": float(ep.b.speed)})
        result = {
            "a_speed_mps": float(np.mean(a_speeds)),
            "b_collided": b_crashed,
            "b_steps": MEASURE_STEPS,
            "b_steps_on_road": int(b_on_road),
            "a_id": str(ep.cars.index(ep.a) + 1),
            "b_id": str(ep.cars.index(ep.b) + 1),
            "t0_s": round(warm * STEP_SECS, 3),
            **stats,
        }
        if scenario == "merge-v0":
            # The ramp car reached the main road: its lane is a highway lane at the end.
            lane = ep.b.lane_index
            result["b_reached_goal"] = bool(lane[:2] in (("b", "c"), ("c", "d")) and lane[2] in (0, 1)
                                            and ep.road.network.get_lane(lane).on_lane(ep.b.position))
        return result
    finally:
        ep.close()
