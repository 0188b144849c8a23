"""scbg drives one car inside SUMO (https://eclipse.dev/sumo/), among SUMO's own cars.

Two scenarios, each a plain-XML network in ``sumo_nets/`` built by ``netconvert`` at run time:

- ``sumo-onramp``: a one-lane main road with an on-ramp and a 174 m acceleration lane that
  ends (SUMO's LC2013 lane changing). A is a ramp car that must merge; B is the main-road car
  it meets at the merge, i.e. the one arriving at the gore at about A's time, whose gap A
  wants. The main road has one lane, as in the synthetic merges the demo's models learn from,
  so B can make room only by its speed, not by changing lanes.
- ``sumo-4way``: an unsignalised four-way junction of type ``priority``: the west-east road
  has the right of way and the south-north road's cars yield without a stop sign. A drives
  east on the priority road; B drives north across it from the minor road, as the synthetic
  crossings' B crosses A's road.

Per episode a seed draws the departure times and speeds (every arm of one seed starts the
same). SUMO drives everyone until the takeover step t0, the first step at which B's front is
``TAKEOVER_M`` of its scenario before the conflict area (100 m before the gore, 35 m before
the junction: some seconds before the two meet, as at the current step of the synthetic
scenes). Until then all arms are the same simulation; from t0 on, the arm decides B's driver
for 8 s:

- ``{"kind": "scbg", "quantile": q}``: scbg. Every ``replan_every`` steps (default 20, 2 s)
  the network (lane centre lines typed ``LANE_TYPE[scenario]``, road edges, lane lines) and
  every vehicle's last 1.1 s become a scene, ``model.generate(scene, A, B, quantile=q)``
  plans B's next 8 s, and B follows the plan step by step: ``vehicle.moveToXY`` with
  ``keepRoute=1`` puts B at the planned point mapped onto the nearest lane of its own route,
  at the plan's speed, with SUMO's speed checks and lane changing off for B. B is then
  always on a lane, where SUMO's car following, lane changing and right of way see it as it
  is (``keepRoute=2`` would place it exactly, but a point off the lanes takes it off every
  lane, out of the other cars' sight, and may swap its route for the nearest edge's). What B
  keeps of a plan is its progress along the route — when B is where, which is what its
  courtesy toward A is about — and its lane where the route has two (the acceleration lane);
  sideways drift off the lanes is not followed (as scbg's own closed loop keeps plans in
  lane), and B's heading is its lane's, so a plan's wiggle does not feed the next plan.
  ``b_plan_points_on_road`` counts how much of the plans themselves lies on the road.
- ``{"kind": "yardstick", "level": "low" | "high"}``: SUMO's own model at the low or the high
  courtesy setting of ``YARDSTICKS[scenario]``, set on B at t0.
- ``{"kind": "default"}``: SUMO's own model at its defaults.

:func:`episode` returns A's mean speed over the 8 s after t0, whether B collided, and how
much of B's plan and realised path lies on the road. Each call starts and closes its own
libsumo simulation (``--step-length 0.1``, headless).
"""

from __future__ import annotations

import atexit
import math
import os
import shutil
import subprocess
import tempfile
from collections import deque

import numpy as np

from . import (arc_lengths, check_arm, crossing_hold_m, guarded_speed_mps, held_speed_mps, leader_on_path, path_samples,
               point_at, yardstick_value)

SCENARIOS = {
    "sumo-onramp": "SUMO on-ramp: one-lane main road, acceleration lane; A merges from the "
    "ramp, B is the main-road car at A's merge point",
    "sumo-4way": "SUMO unsignalised priority junction: A on the priority road, B crossing "
    "it from the minor road",
}

# The courtesy settings of SUMO's own driver for B, per scenario: "parameter" is set on B at
# t0 to "low" (little courtesy toward A) or "high" (much). On the on-ramp, lcCooperative is
# the LC2013 willingness to cooperate with a car that wants to change into B's lane; its speed
# adjustment (lcCooperativeSpeed, whose default is lcCooperative) is set to the same value.
# At the junction, jmIgnoreFoeProb is the probability that B ignores a priority car
# (jmIgnoreFoeSpeed 50 m/s: any car), i.e. 1 = never yields, 0 = yields as the rules say.
YARDSTICKS = {
    "sumo-onramp": {"parameter": "lcCooperative", "low": 0.0, "high": 1.0},
    "sumo-4way": {"parameter": "jmIgnoreFoeProb", "low": 1.0, "high": 0.0},
}

STEP_S = 0.1
HISTORY_STEPS = 11  # 1.1 s, the current step included
FUTURE_STEPS = 80  # 8 s
# Steps between B's plans (2 s, as scbg.Model.simulation's default). A plan that yields begins
# to slow down only after about a second; re-planned every second, B was re-planned from
# nearly its old speed each time and never yielded: at the junction A's speed then did not
# change with the quantile (q 0.9 - q 0.1: +0.00 m/s over 60 seeds with the demo's model,
# against +0.53 m/s every 2 s and +0.73 m/s every 1.5 s).
REPLAN_EVERY = 20

# Takeover: B's front this far before the conflict area (metres along its route).
TAKEOVER_M = {"sumo-onramp": 100.0, "sumo-4way": 35.0}
# Lane types of the scene's lanes, as the demo's models were trained: freeway merges,
# surface-street crossings.
LANE_TYPE = {"sumo-onramp": "freeway", "sumo-4way": "surface_street"}
_NET_NAME = {"sumo-onramp": "onramp", "sumo-4way": "4way"}
# The edge of B's route that ends at the conflict area: B's distance to the conflict area is
# that edge's length less B's lane position while on it.
_B_APPROACH_EDGE = {"sumo-onramp": "main_in", "sumo-4way": "s_in"}
_MAX_S = 60.0  # an episode's SUMO time never reaches this; a guard against a stuck loop


def nets_folder() -> str:
    """The folder of the plain-XML networks (``*.nod.xml``, ``*.edg.xml``, ``*.rou.xml``)."""
    return os.path.join(os.path.dirname(os.path.abspath(__file__)), "sumo_nets")


def _check_scenario(scenario):
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown SUMO scenario {scenario!r}: expected one of {sorted(SCENARIOS)}")


def netconvert_binary() -> str:
    """netconvert of the eclipse-sumo wheel (``sumo.SUMO_HOME``), else the one on PATH."""
    try:
        import sumo

        path = os.path.join(sumo.SUMO_HOME, "bin", "netconvert")
        if os.path.exists(path):
            return path
    except ImportError:
        pass
    path = shutil.which("netconvert")
    if path is None:
        raise RuntimeError("netconvert not found: pip install eclipse-sumo")
    return path


_BUILT: dict = {}
_TMP: list = []


def build_net(scenario: str, folder: str | None = None) -> str:
    """Builds the scenario's ``.net.xml`` with netconvert into ``folder`` (default: a
    temporary folder, one per process, removed at exit) once per process and returns its
    path."""
    _check_scenario(scenario)
    key = (scenario, folder)
    if key in _BUILT and os.path.exists(_BUILT[key]):
        return _BUILT[key]
    if folder is None:
        if not _TMP:
            _TMP.append(tempfile.mkdtemp(prefix="scbg-sumo-"))
            atexit.register(shutil.rmtree, _TMP[0], True)
        folder = _TMP[0]
    os.makedirs(folder, exist_ok=True)
    name = _NET_NAME[scenario]
    src = nets_folder()
    out = os.path.join(folder, f"{name}.net.xml")
    cmd = [
        netconvert_binary(),
        "--node-files", os.path.join(src, f"{name}.nod.xml"),
        "--edge-files", os.path.join(src, f"{name}.edg.xml"),
        "--output-file", out,
        "--no-turnarounds", "true",
        "--offset.disable-normalization", "true",
        "--no-warnings", "true",
    ]
    con = os.path.join(src, f"{name}.con.xml")
    if os.path.exists(con):
        cmd += ["--connection-files", con]
    res = subprocess.run(cmd, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"netconvert failed for {scenario}:\n{res.stdout}\n{res.stderr}")
    _BUILT[key] = out
    return out


# ------------------------------------------------------------------------------ the road map


def _offset(shape, d):
    """A polyline moved sideways by ``d`` (positive: to the left of its direction)."""
    p = np.asarray(shape, float)
    seg = np.diff(p, axis=0)
    seg /= np.maximum(np.linalg.norm(seg, axis=1, keepdims=True), 1e-9)
    normals = np.stack([-seg[:, 1], seg[:, 0]], axis=1)
    n = np.empty_like(p)
    n[0], n[-1] = normals[0], normals[-1]
    if len(p) > 2:
        mid = normals[:-1] + normals[1:]
        mid /= np.maximum(np.linalg.norm(mid, axis=1, keepdims=True), 1e-9)
        # keep the offset distance at corners
        cos = np.sum(mid * normals[1:], axis=1, keepdims=True)
        n[1:-1] = mid / np.maximum(cos, 0.2)
    return p + d * n


def _densify(shape, step=1.0):
    """Points along a polyline at most ``step`` metres apart (its vertices kept)."""
    p = np.asarray(shape, float)
    out = [p[0]]
    for a, b in zip(p[:-1], p[1:]):
        k = max(1, int(math.ceil(np.linalg.norm(b - a) / step)))
        for i in range(1, k + 1):
            out.append(a + (b - a) * i / k)
    return np.array(out)


class RoadMap:
    """A SUMO network as scbg's map, and SUMO's road surface for on-road checks.

    - ``lanes``: every lane's centre line (internal junction lanes included), in driving
      direction, at most 1 m between points;
    - ``road_edges``: the outer borders of each edge (the right border of its lane 0 and,
      unless the edge has an opposite edge, the left border of its leftmost lane), and each
      junction's outline where it is not an opening to a lane (the kerbs at a junction's
      corners, a gore's tip, the end of an acceleration lane);
    - ``road_lines``: the borders between neighbouring lanes of one edge, and a two-way road's
      middle.
    """

    def __init__(self, net_file: str):
        import sumolib

        net = sumolib.net.readNet(net_file, withInternal=True)
        self.lanes, self.lane_ids, self.road_edges, self.road_lines = [], [], [], []
        self._shapes, self._half_widths = [], []
        ends = []
        for edge in net.getEdges(withInternal=True):
            lanes = sorted(edge.getLanes(), key=lambda ln: ln.getIndex())
            for lane in lanes:
                shape = np.array(lane.getShape(), float)[:, :2]
                self.lanes.append(_densify(shape))
                self.lane_ids.append(lane.getID())
                self._shapes.append(shape)
                self._half_widths.append(lane.getWidth() / 2.0)
                if edge.getFunction() != "internal":
                    ends += [shape[0], shape[-1]]
            if edge.getFunction() == "internal":
                continue
            right = lanes[0]
            left = lanes[-1]
            self.road_edges.append(_densify(_offset(right.getShape(), -right.getWidth() / 2), 2.0))
            left_border = _densify(_offset(left.getShape(), left.getWidth() / 2), 2.0)
            opposite = [e for e in edge.getToNode().getOutgoing() if e.getToNode() == edge.getFromNode()]
            if not opposite:
                self.road_edges.append(left_border)
            elif edge.getID() < opposite[0].getID():
                # A two-way road's middle is a line between its directions, drawn once.
                self.road_lines.append(left_border)
            for lane in lanes[1:]:
                self.road_lines.append(_densify(_offset(lane.getShape(), -lane.getWidth() / 2), 2.0))
        ends = np.array(ends)
        for junction in net.getNodes():
            outline = np.array(junction.getShape(), float)
            if len(outline) < 3:
                continue
            outline = np.vstack([outline[:, :2], outline[:1, :2]])
            for a, b in zip(outline[:-1], outline[1:]):
                # An opening is a side that a lane's end crosses.
                if len(ends) and _point_segment_distance(ends, a, b).min() < 0.5:
                    continue
                if np.linalg.norm(b - a) > 0.05:
                    self.road_edges.append(_densify(np.array([a, b]), 2.0))
        self._a = np.concatenate([s[:-1] for s in self._shapes])
        self._b = np.concatenate([s[1:] for s in self._shapes])
        self._w = np.concatenate([np.full(len(s) - 1, w) for s, w in zip(self._shapes, self._half_widths)])

    def on_road(self, xy) -> np.ndarray:
        """Whether each point ``[n, 2]`` lies on SUMO's road surface: within half its width
        of some lane's centre line (internal junction lanes included)."""
        xy = np.atleast_2d(np.asarray(xy, float))
        ok = np.zeros(len(xy), bool)
        for i, p in enumerate(xy):
            ok[i] = bool(np.any(_point_segment_distance(p[None, :], self._a, self._b) <= self._w))
        return ok


def _point_segment_distance(p, a, b):
    """Distances between points ``p`` and segments ``a → b`` (broadcast)."""
    p, a, b = np.asarray(p, float), np.asarray(a, float), np.asarray(b, float)
    ab = b - a
    denom = np.maximum(np.sum(ab * ab, axis=-1), 1e-12)
    t = np.clip(np.sum((p - a) * ab, axis=-1) / denom, 0.0, 1.0)
    closest = a + t[..., None] * ab
    return np.linalg.norm(p - closest, axis=-1)


_MAPS: dict = {}


def road_map(scenario: str, net_folder: str | None = None) -> RoadMap:
    """The scenario's :class:`RoadMap` (built once per process and folder)."""
    key = (scenario, net_folder)
    if key not in _MAPS:
        _MAPS[key] = RoadMap(build_net(scenario, net_folder))
    return _MAPS[key]


# ----------------------------------------------------------------- SUMO's frame ↔ scbg's frame


def heading_from_sumo_angle(angle_deg: float) -> float:
    """SUMO's angle (degrees clockwise from north) → heading (radians counter-clockwise from
    +x), in (-π, π]."""
    h = math.radians(90.0 - angle_deg)
    return math.atan2(math.sin(h), math.cos(h))


def sumo_angle_from_heading(heading_rad: float) -> float:
    """Heading (radians counter-clockwise from +x) → SUMO's angle (degrees clockwise from
    north), in [0, 360)."""
    return (90.0 - math.degrees(heading_rad)) % 360.0


def centre_from_front(x, y, heading_rad, length):
    """SUMO's position is the front bumper's middle; scbg's is the box's centre."""
    return x - 0.5 * length * math.cos(heading_rad), y - 0.5 * length * math.sin(heading_rad)


def front_from_centre(x, y, heading_rad, length):
    """The inverse of :func:`centre_from_front`."""
    return x + 0.5 * length * math.cos(heading_rad), y + 0.5 * length * math.sin(heading_rad)


def vehicle_state(traci, vid):
    """One vehicle's state row as scbg reads it: centre x, y (m), heading (rad, counter-clockwise
    from +x), vx, vy (m/s), length, width (m)."""
    x, y = traci.vehicle.getPosition(vid)
    h = heading_from_sumo_angle(traci.vehicle.getAngle(vid))
    v = traci.vehicle.getSpeed(vid)
    length = traci.vehicle.getLength(vid)
    width = traci.vehicle.getWidth(vid)
    cx, cy = centre_from_front(x, y, h, length)
    return (cx, cy, h, v * math.cos(h), v * math.sin(h), length, width)


# ------------------------------------------------------------------------- the seed's traffic


def _traffic(scenario, seed):
    """The seed's vehicles: ``[(id, route, depart_s, depart_speed_mps, speed_factor)]``, the
    same for every arm of the seed."""
    rng = np.random.default_rng([int(seed), sorted(SCENARIOS).index(scenario)])
    cars = []
    if scenario == "sumo-onramp":
        main_len, ramp_len, limit = 498.5, 331.9, 27.78  # main_in's and ramp's lane lengths
        v_b = rng.uniform(22.0, 26.5)
        # A's lead at the gore over B, in seconds (positive: A first): A reaches the
        # acceleration lane about level with B, so it merges ahead of B if B lets it.
        lead = rng.uniform(0.0, 2.0)
        v_a = rng.uniform(23.0, 27.0)
        a_depart = main_len / v_b - lead - ramp_len / v_a
        cars.append(("B", "main", 0.0, v_b, v_b / limit))
        cars.append(("A", "onramp", a_depart, v_a, v_a / limit))
        t = 0.0
        for k in range(int(rng.integers(1, 4))):  # main-road cars ahead of B, no slower
            t -= rng.uniform(2.0, 3.5)
            v = rng.uniform(v_b, 27.0)
            cars.append((f"main_ahead.{k}", "main", t, v, v / limit))
        t = 0.0
        for k in range(int(rng.integers(1, 4))):  # and close behind it
            t += rng.uniform(0.8, 1.6)
            v = min(v_b + rng.uniform(-1.0, 1.0), 27.0)
            cars.append((f"main_behind.{k}", "main", t, v, v / limit))
        if rng.random() < 0.5:  # a second ramp car behind A
            v = v_a * rng.uniform(0.95, 1.0)
            cars.append(("ramp_behind", "onramp", a_depart + rng.uniform(2.0, 3.5), v, v / limit))
    else:
        arm_len, limit = 242.5, 13.89  # an approach lane's length
        v_a = rng.uniform(12.0, 13.8)
        v_b = rng.uniform(10.0, 13.0)
        # A's lead at the junction over B, in seconds (positive: A first).
        lead = rng.uniform(-3.0, 2.0)
        a_depart = 0.0
        b_depart = a_depart + arm_len / v_a - arm_len / v_b + lead
        cars.append(("A", "eastbound", a_depart, v_a, v_a / limit))
        cars.append(("B", "northbound", b_depart, v_b, v_b / limit))
        if rng.random() < 0.6:  # a car behind A
            v = rng.uniform(11.5, 13.8)
            cars.append(("east_behind", "eastbound", a_depart + rng.uniform(1.5, 3.5), v, v / limit))
        if rng.random() < 0.5:  # a car behind B
            v = rng.uniform(10.0, 13.0)
            cars.append(("north_behind", "northbound", b_depart + rng.uniform(1.5, 4.0), v, v / limit))
        if rng.random() < 0.5:  # westbound traffic on the priority road
            v = rng.uniform(11.5, 13.8)
            cars.append(("west", "westbound", a_depart + rng.uniform(-2.0, 6.0), v, v / limit))
    t_min = min(c[2] for c in cars)
    return [(i, r, round(d - t_min + 0.2, 1), v, f) for i, r, d, v, f in cars]


def add_traffic(traci, scenario: str, seed: int):
    """Adds the seed's vehicles (A, B and the others) to a started simulation; each departs
    at its drawn time and speed and keeps its drawn desired speed (a speed factor)."""
    for vid, route, depart, speed, factor in _traffic(scenario, seed):
        traci.vehicle.add(vid, route, typeID="car", depart=str(depart), departLane="first",
                          departPos="base", departSpeed=f"{speed:.3f}")
        traci.vehicle.setSpeedFactor(vid, factor)


# ---------------------------------------------------------------------------------- episodes


def _box_corners(s):
    cx, cy, h, _, _, length, width = s
    c, si = math.cos(h), math.sin(h)
    dx = np.array([length / 2, length / 2, -length / 2, -length / 2])
    dy = np.array([width / 2, -width / 2, -width / 2, width / 2])
    return np.stack([cx + dx * c - dy * si, cy + dx * si + dy * c], axis=1)


def boxes_overlap(s1, s2) -> bool:
    """Whether two vehicles' boxes (state rows) overlap (separating axis test)."""
    if math.hypot(s1[0] - s2[0], s1[1] - s2[1]) > 0.5 * (s1[5] + s2[5]) + 0.5 * (s1[6] + s2[6]):
        return False
    p, q = _box_corners(s1), _box_corners(s2)
    for h in (s1[2], s2[2]):
        for axis in (np.array([math.cos(h), math.sin(h)]), np.array([-math.sin(h), math.cos(h)])):
            a, b = p @ axis, q @ axis
            if a.max() < b.min() or b.max() < a.min():
                return False
    return True


def start_sumo(scenario: str, seed: int, net_folder: str | None = None):
    """Starts a headless libsumo simulation of ``scenario``'s network and vehicle types
    (0.1 s steps, collisions only reported, no teleports) and returns the libsumo module;
    close it with ``libsumo.close()``. No vehicles are added."""
    import libsumo

    _check_scenario(scenario)
    net = build_net(scenario, net_folder)
    rou = os.path.join(nets_folder(), f"{_NET_NAME[scenario]}.rou.xml")
    libsumo.start([
        "sumo", "-n", net, "-r", rou,
        "--step-length", str(STEP_S),
        "--seed", str(int(seed) % 2**31),
        "--collision.action", "warn",
        "--collision.check-junctions", "true",
        "--time-to-teleport", "-1",
        "--no-step-log", "true",
        "--no-warnings", "true",
    ])
    return libsumo


def scene_from_history(scenario: str, history, a: str, b: str, rmap: RoadMap):
    """scbg's scene of the last steps ``history`` (oldest first, at most 11; each a dict of
    SUMO id → :func:`vehicle_state` row): every vehicle seen in them, the current step the
    last, the 80 future steps invalid, and the map of ``rmap``. Returns ``(scene, a's track
    id, b's track id)``; track ids number the vehicles from 1 in order of appearance."""
    import scbg

    vids = []
    for frame in history:
        for vid in frame:
            if vid not in vids:
                vids.append(vid)
    steps = HISTORY_STEPS + FUTURE_STEPS
    states = np.zeros((len(vids), steps, 7))
    valid = np.zeros((len(vids), steps), bool)
    offset = HISTORY_STEPS - len(history)
    for k, frame in enumerate(history):
        for i, vid in enumerate(vids):
            if vid in frame:
                states[i, offset + k] = frame[vid]
                valid[i, offset + k] = True
    num = {vid: i + 1 for i, vid in enumerate(vids)}
    ids = np.array([num[v] for v in vids], np.int64)
    scene = scbg.Scene.from_arrays(
        scenario, ids, states, valid, current_step=HISTORY_STEPS - 1, sdc_id=num[a],
        objects_of_interest=[num[a], num[b]], lanes=rmap.lanes, road_edges=rmap.road_edges,
        road_lines=rmap.road_lines, lane_types=[LANE_TYPE[scenario]] * len(rmap.lanes))
    return scene, num[a], num[b]


def _b_distance_to_conflict(traci, scenario):
    """B's front distance (m) to the end of its approach edge, or None once past it."""
    edge = _B_APPROACH_EDGE[scenario]
    if traci.vehicle.getRoadID("B") != edge:
        return None
    return traci.lane.getLength(traci.vehicle.getLaneID("B")) - traci.vehicle.getLanePosition("B")


def _set_yardstick(traci, scenario, level):
    """Sets ``YARDSTICKS[scenario]``'s ``level`` on SUMO's B."""
    value = yardstick_value(YARDSTICKS[scenario], level)
    if scenario == "sumo-onramp":
        for key in ("lcCooperative", "lcCooperativeSpeed"):
            traci.vehicle.setParameter("B", f"laneChangeModel.{key}", str(value))
    else:
        # SUMO takes junction-model parameters from the vehicle's type only: 4way.rou.xml's
        # yardstick types differ from "car" in jmIgnoreFoeProb (and jmIgnoreFoeSpeed) alone.
        traci.vehicle.setType("B", f"car_ignores_foes_{value:.2f}")


def _put(traci, xy, speed_mps, b_state):
    """Puts B's centre at ``xy`` for the next step, at ``speed_mps``. ``moveToXY`` with
    ``keepRoute=1`` maps the front bumper (half B's length ahead along its heading, SUMO's lane
    angle) onto the nearest lane of B's route: SUMO's cars then see B on that lane where it is,
    and the junction knows which way it goes. A point SUMO cannot map (over 100 m from B's
    route) leaves B to move on along its lane at that speed."""
    fx, fy = front_from_centre(xy[0], xy[1], b_state[2], b_state[5])
    try:
        traci.vehicle.moveToXY("B", "", -1, fx, fy, traci.constants.INVALID_DOUBLE_VALUE, 1)
    except traci.TraCIException:
        pass
    traci.vehicle.setSpeed("B", float(speed_mps))


B_ACC_MPS2 = 2.6  # catching up with a plan after a hold: SUMO's car type's accel


class _PlanFollower:
    """B along its current plan: at the plan's point of each step, but never faster than the
    follow-distance guard (:func:`guarded_speed_mps`) allows behind a car in its way, and as long
    as the crossing rule (:func:`crossing_hold_m`) lets it; held, it brakes to stop before the
    crossing, and after a hold it catches up with the plan's timing at :data:`B_ACC_MPS2` until
    the next plan."""

    def __init__(self, plan, start_xy):
        self.path = np.vstack([start_xy, plan])
        self.arc = arc_lengths(self.path)
        self.samples = path_samples(self.path, self.arc)
        self.s_m = 0.0

    def step(self, traci, j, b_state, others) -> bool:
        """Puts B at its place on the plan's step ``j``; whether the crossing rule held it."""
        held = False
        due = self.arc[j + 1]
        v_b = math.hypot(b_state[3], b_state[4])
        speed = max(due - self.s_m, 0.0) / STEP_S
        if self.s_m < self.arc[j] - 1e-6:  # behind the plan's timing after a hold
            speed = min(speed, v_b + B_ACC_MPS2 * STEP_S)
        rows = np.asarray(others, float).reshape(-1, 7)
        gap, v_lead = leader_on_path(self.samples, self.s_m, rows[:, :2], rows[:, 3:5],
                                     0.5 * (rows[:, 5] + b_state[5]))
        speed = guarded_speed_mps(speed, v_b, gap, v_lead, STEP_S)
        hold = crossing_hold_m(self.path, self.arc, self.s_m, b_state, others)
        if math.isfinite(hold):
            limit = held_speed_mps(hold, self.s_m, STEP_S)
            if speed > limit:
                speed, held = limit, True
        self.s_m += speed * STEP_S
        xy = self.path[j + 1] if abs(self.s_m - due) < 1e-9 else point_at(self.path, self.arc, self.s_m)[0]
        _put(traci, xy, speed, b_state)
        return held


def episode(model, scenario: str, seed: int, arm: dict, net_folder: str | None = None,
            trace: list | None = None, replan_every: int = REPLAN_EVERY) -> dict:
    """One episode of ``scenario`` from ``seed`` with B driven as ``arm`` says (see the
    module's docstring); ``model`` (an ``scbg.Model``) is needed by scbg arms only.

    Returns ``a_speed_mps`` (A's mean speed over the 8 s after t0), ``b_collided`` (B in
    SUMO's collision list, or its box overlapping another's), ``b_plan_points`` and
    ``b_plan_points_on_road`` (B's planned points within the 8 s, scbg arms only),
    ``b_steps`` and ``b_steps_on_road`` (B's realised positions), ``a_id``, ``b_id``,
    ``t0_s``. ``net_folder``: where the network is built (default: a temporary folder);
    ``replan_every``: steps between B's plans (1 to 80) in scbg arms.
    ``trace``: a list that gets, per step after t0, ``{"t_s", "states": {id: state row},
    "collisions": [(id, id)], "plan": B's current plan or None}``."""
    _check_scenario(scenario)
    check_arm(arm)
    if arm["kind"] == "scbg" and model is None:
        raise ValueError("an scbg arm needs a model")
    if not isinstance(replan_every, int) or not 1 <= replan_every <= FUTURE_STEPS:
        raise ValueError(f"replan_every must be an integer in [1, {FUTURE_STEPS}], got {replan_every!r}")

    rmap = road_map(scenario, net_folder)
    traci = start_sumo(scenario, seed, net_folder)
    try:
        add_traffic(traci, scenario, seed)
        history = deque(maxlen=HISTORY_STEPS)
        t0 = None
        while t0 is None:
            traci.simulationStep()
            now = traci.simulation.getTime()
            if now > _MAX_S:
                raise RuntimeError(f"{scenario} seed {seed}: B never reached the takeover point")
            history.append({v: vehicle_state(traci, v) for v in traci.vehicle.getIDList()})
            if "A" in history[-1] and "B" in history[-1] and len(history) == HISTORY_STEPS:
                d = _b_distance_to_conflict(traci, scenario)
                if d is not None and d <= TAKEOVER_M[scenario]:
                    t0 = now
        if arm["kind"] == "yardstick":
            _set_yardstick(traci, scenario, arm["level"])
        scbg_arm = arm["kind"] == "scbg"
        if scbg_arm:
            traci.vehicle.setSpeedMode("B", 0)
            traci.vehicle.setLaneChangeMode("B", 0)
        a_speeds, b_xy, plan_points, plan_on_road = [], [], 0, 0
        collided = False
        plan, plan_k, follower, held_steps = None, 0, None, 0
        for k in range(FUTURE_STEPS):
            if scbg_arm:
                if k % replan_every == 0:
                    scene, a_num, b_num = scene_from_history(scenario, history, "A", "B", rmap)
                    plan = np.asarray(model.generate(scene, a_num, b_num,
                                                     quantile=float(arm["quantile"]))["world_xy_m"])
                    plan_k = k
                    follower = _PlanFollower(plan, np.array(history[-1]["B"][:2]))
                    within = plan[: FUTURE_STEPS - k]
                    plan_points += len(within)
                    plan_on_road += int(rmap.on_road(within).sum())
                now = history[-1]
                held_steps += follower.step(traci, k - plan_k, now["B"],
                                            [st for v, st in now.items() if v != "B"])
            traci.simulationStep()
            frame = {v: vehicle_state(traci, v) for v in traci.vehicle.getIDList()}
            history.append(frame)
            if "A" in frame:
                a_speeds.append(math.hypot(frame["A"][3], frame["A"][4]))
            pairs = [(c.collider, c.victim) for c in traci.simulation.getCollisions()]
            pairs += [("B", v) for v, s in frame.items()
                      if v != "B" and "B" in frame and boxes_overlap(frame["B"], s)]
            if "B" in frame:
                b_xy.append(frame["B"][:2])
                collided = collided or any("B" in p for p in pairs)
            if trace is not None:
                trace.append({"t_s": traci.simulation.getTime(), "states": frame,
                              "collisions": pairs, "plan": plan})
        b_on = int(rmap.on_road(np.array(b_xy)).sum()) if b_xy else 0
        return {
            "a_speed_mps": float(np.mean(a_speeds)) if a_speeds else float("nan"),
            "b_collided": bool(collided),
            "b_plan_points": int(plan_points),
            "b_plan_points_on_road": int(plan_on_road),
            "b_steps": len(b_xy),
            "b_steps_on_road": b_on,
            "a_id": "A",
            "b_id": "B",
            "t0_s": float(t0),
            "b_held_steps": held_steps,
        }
    finally:
        traci.close()
