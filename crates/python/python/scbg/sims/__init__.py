"""Foreign simulators driven by scbg: harnesses that put one scbg-driven car among a simulator's own."""

import math

import numpy as np


def check_arm(arm):
    """Raises ``ValueError`` unless ``arm`` is one of the arms every harness's ``episode`` takes:
    ``{"kind": "scbg", "quantile": q}`` with q in [0, 1], ``{"kind": "yardstick", "level":
    "low" | "high" | f}`` (f in [0, 1]: that fraction of the way from the low to the high
    setting) or ``{"kind": "default"}``."""
    kind = arm.get("kind") if isinstance(arm, dict) else None
    if kind == "scbg":
        q = arm.get("quantile")
        if not isinstance(q, (int, float)) or math.isnan(float(q)) or not 0.0 <= float(q) <= 1.0:
            raise ValueError(f"scbg arm: quantile must be a number in [0, 1], got {q!r}")
    elif kind == "yardstick":
        level = arm.get("level")
        if level not in ("low", "high") and not (
                isinstance(level, (int, float)) and not isinstance(level, bool) and 0.0 <= float(level) <= 1.0):
            raise ValueError(f"yardstick arm: level must be 'low', 'high' or a number in [0, 1], got {level!r}")
    elif kind != "default":
        raise ValueError(f"arm must be a dict with kind 'scbg', 'yardstick' or 'default', got {arm!r}")


def yardstick_value(yardstick, level):
    """The setting of ``yardstick`` (an entry of a harness's ``YARDSTICKS``) at ``level``:
    ``"low"``, ``"high"``, or a fraction of the way from the low to the high setting. A right of
    way (``yields``: never / always) is graded by ``lead_s``: between its ends B yields when A's
    lead at the conflict exceeds the returned ``lead_s × (0.5 − level)`` seconds."""
    if level in ("low", "high"):
        return yardstick[level]
    low, high = yardstick["low"], yardstick["high"]
    if isinstance(low, (int, float)):
        return low + float(level) * (high - low)
    if "lead_s" in yardstick:
        return yardstick["lead_s"] * (0.5 - float(level))
    raise ValueError(f"yardstick {yardstick['parameter']!r} has two settings only: 'low' and 'high'")


def graded(yardstick):
    """Whether ``yardstick`` has settings between its ends (numbers, or a graded right of way)."""
    return isinstance(yardstick["low"], (int, float)) or "lead_s" in yardstick


def arc_lengths(points):
    """Cumulative arc length (m) at each point of a polyline ``[n, 2]``, from 0."""
    return np.concatenate([[0.0], np.cumsum(np.hypot(*np.diff(points, axis=0).T))])


def point_at(points, arc, s):
    """The point at arc length ``s`` of a polyline (``arc`` from :func:`arc_lengths`), and the
    unit direction there (None on a segment of zero length)."""
    i = int(np.clip(np.searchsorted(arc, s, side="right") - 1, 0, len(points) - 2))
    seg = points[i + 1] - points[i]
    length = float(np.hypot(*seg))
    t = 0.0 if length < 1e-9 else float(np.clip((s - arc[i]) / length, 0.0, 1.0))
    return points[i] + t * seg, (seg / length if length > 1e-9 else None)


# B's gap acceptance where its path crosses another road (both harnesses), the rule the
# highway-env harness applies to B's lane changes: B drives into a crossing car's way only if
# that car can stop short of B braking at most CROSS_BRAKE_MPS2 after CROSS_REACTION_S, or has
# passed; else B stops before the crossing and waits. A plan that forces its way in still makes
# A brake hard; one that would leave A no room to stop is held. A crossing car's way is the path
# its simulator says it will drive where the harness can read one (highway-env's routes), else
# the straight line along its heading.
CROSS_BRAKE_MPS2 = 7.0
CROSS_REACTION_S = 0.5
CROSS_MARGIN_M = 0.5
CROSS_LOOKAHEAD_M = 40.0  # along B's plan
CROSS_REACH_M = 80.0  # along the crossing car's way
CROSS_MIN_SIN = 0.5  # paths meeting at 30° or more cross; shallower ones are lanes merging
B_MAX_BRAKE_MPS2 = 8.0  # B holds only where it can stop before the crossing
B_BRAKE_MPS2 = 4.0  # and brakes for it no harder than this while it has room


def _along_way(pts, way):
    """For each point ``[n, 2]``: its distance to the polyline ``way`` ``[m, 2]`` (the first
    segment extended backwards, so points behind the way's start count), the arc length of its
    nearest point from the way's start (negative behind it), and the way's unit direction there."""
    a = way[:-1]
    d = np.diff(way, axis=0)
    length = np.maximum(np.hypot(*d.T), 1e-9)
    rel = pts[:, None, :] - a[None, :, :]
    t = np.einsum("nmk,mk->nm", rel, d) / (length * length)
    low = np.zeros_like(length)
    low[0] = -np.inf
    t = np.clip(t, low, 1.0)
    gap = rel - t[:, :, None] * d[None, :, :]
    dist = np.hypot(gap[..., 0], gap[..., 1])
    j = dist.argmin(axis=1)
    rows = np.arange(len(pts))
    start = np.concatenate([[0.0], np.cumsum(length)])[:-1]
    along = start[j] + t[rows, j] * length[j]
    return dist[rows, j], along, d[j] / length[j, None]


def crossing_hold_m(path, arc, s_m, b_state, others, ways=None):
    """How far along B's path (arc length, from the path's start) B's centre may go: the first
    place where its box would enter the way of a crossing car that can neither stop short nor
    has passed, less :data:`CROSS_MARGIN_M`; ``inf`` where no such car is or B is too late to
    stop for it. :func:`crossing_rule` also says what B does when too late."""
    return crossing_rule(path, arc, s_m, b_state, others, ways)[0]


def crossing_rule(path, arc, s_m, b_state, others, ways=None):
    """B's gap acceptance where its path crosses another car's way: ``(hold_m, committed)``.
    ``hold_m``: how far along B's path (arc length, from the path's start) B's centre may go —
    the first place where its box would enter the way of a crossing car that can neither stop
    short nor has passed, less :data:`CROSS_MARGIN_M` — or ``inf`` where no such car is or B can
    no longer stop before it. ``committed``: such a car is there and B can no longer stop
    before it; where the simulator's cars do not yield by a right of way, B then goes on at its
    speed rather than slow down in that car's way.

    ``path``/``arc``: B's plan and its arc lengths; ``s_m``: B's progress along it; ``b_state``
    and ``others``: B's and the other cars' state rows ``[x, y, heading, vx, vy, length, width]``
    now, in the path's frame; ``ways``, optionally: per other car, the path ``[m, 2]`` its centre
    will drive from where it is, or None (the default: the straight line along its heading)."""
    length_b, width_b = b_state[5], b_state[6]
    v_b = math.hypot(b_state[3], b_state[4])
    ahead = np.arange(s_m, min(s_m + CROSS_LOOKAHEAD_M, arc[-1]) + 1e-9, 0.5)
    if len(ahead) < 2:
        return math.inf, False
    pts = np.column_stack([np.interp(ahead, arc, path[:, 0]), np.interp(ahead, arc, path[:, 1])])
    steps = np.diff(pts, axis=0)
    steps = np.vstack([steps, steps[-1:]])
    dirs = steps / np.maximum(np.hypot(*steps.T), 1e-9)[:, None]
    hold = math.inf
    for k, (cx, cy, h, vx, vy, length_v, width_v) in enumerate(others):
        way = None if ways is None else ways[k]
        if way is None or len(way) < 2:
            way = np.array([[cx, cy], [cx + CROSS_REACH_M * math.cos(h), cy + CROSS_REACH_M * math.sin(h)]])
        lateral, along, u = _along_way(pts, np.asarray(way, float))
        crossing = np.abs(dirs[:, 0] * u[:, 1] - dirs[:, 1] * u[:, 0]) > CROSS_MIN_SIN
        inside = crossing & (lateral < 0.5 * (width_v + length_b) + CROSS_MARGIN_M) & (along < CROSS_REACH_M)
        if not inside.any():
            continue
        i = int(inside.argmax())
        clear_m = 0.5 * (length_v + width_b) + CROSS_MARGIN_M  # its centre to B's side, clear
        front_gap_m = along[i] - clear_m
        if along[i] < -clear_m:
            continue  # it has passed
        speed = math.hypot(vx, vy)
        stop_m = speed * CROSS_REACTION_S + speed * speed / (2.0 * CROSS_BRAKE_MPS2)
        if front_gap_m >= 0.0 and front_gap_m >= stop_m:
            continue  # it can stop short of B
        hold = min(hold, ahead[i] - CROSS_MARGIN_M)
    if hold - s_m < v_b * v_b / (2.0 * B_MAX_BRAKE_MPS2):
        return math.inf, math.isfinite(hold)  # too late to stop: B is committed
    return hold, False


def held_speed_mps(hold_m, s_m, step_s):
    """The fastest B may drive over the next step and still stop before ``hold_m`` braking at
    most :data:`B_BRAKE_MPS2`, from progress ``s_m`` (both along its path)."""
    room = max(hold_m - s_m, 0.0)
    return min(math.sqrt(2.0 * B_BRAKE_MPS2 * room), room / step_s)


# B's follow-distance guard, both harnesses: B never drives along its plan faster than the ACC
# model allows behind the nearest car in its way (IDM blended with the constant-acceleration
# heuristic, Kesting, Treiber & Helbing 2010, leader at constant speed), as scbg's own closed
# loop follows a plan that runs into another agent at a safe distance instead. Plain IDM brakes
# at tens of m/s² for a faster car that cuts in close ahead, and B got rear-ended doing so.
GUARD_ACC_MPS2 = 6.0  # highway-env's ACC_MAX
GUARD_BRAKE_MPS2 = 5.0  # comfortable braking
GUARD_GAP_M = 2.0  # jam distance
GUARD_HEADWAY_S = 1.0
GUARD_CORRIDOR_M = 2.2  # a car whose centre is this close to B's path ahead is in its way
GUARD_LOOKAHEAD_M = 60.0
GUARD_COOLNESS = 0.99  # the ACC model's weight of the heuristic
GUARD_MAX_BRAKE_MPS2 = 9.0  # B's hardest braking


def path_samples(path, arc):
    """A polyline's points every metre of arc length (for :func:`leader_on_path`)."""
    every_m = np.arange(0.0, arc[-1] + 1e-9, 1.0)
    return np.column_stack([np.interp(every_m, arc, path[:, 0]), np.interp(every_m, arc, path[:, 1])])


def leader_on_path(samples, s_m, xy, velocities, half_lengths_m):
    """Bumper-to-bumper gap (m) and speed along B's path of the nearest car in B's way from arc
    length ``s_m``, or (inf, 0): of the cars at ``xy`` ``[k, 2]`` (velocities ``[k, 2]``), the
    first whose centre comes within :data:`GUARD_CORRIDOR_M` of the path in
    :data:`GUARD_LOOKAHEAD_M`, its gap taken where the path passes nearest it and its speed as
    the part of its velocity along the path there (none for a car coming towards B).
    ``samples``: the path every metre (:func:`path_samples`); ``half_lengths_m``: per car, its
    half length plus B's."""
    i0 = int(np.floor(s_m))
    pts = samples[i0:i0 + int(GUARD_LOOKAHEAD_M) + 1]
    xy = np.asarray(xy, float).reshape(-1, 2)
    if len(pts) == 0 or len(xy) == 0:
        return math.inf, 0.0
    dist = np.hypot(*(xy[:, None, :] - pts[None, :, :]).transpose(2, 0, 1))
    near = dist < GUARD_CORRIDOR_M
    hit = near.any(axis=1)
    if not hit.any():
        return math.inf, 0.0
    first = np.where(hit, near.argmax(axis=1), np.iinfo(np.int64).max)
    j = int(first.argmin())
    at = int(dist[j].argmin())  # where the path passes nearest the leader
    step = pts[min(at + 1, len(pts) - 1)] - pts[max(at - 1, 0)]
    along = step / max(float(np.hypot(*step)), 1e-9)
    speed = max(float(np.asarray(velocities[j], float) @ along), 0.0)
    return float(i0 + at - s_m - half_lengths_m[j]), speed


def guarded_speed_mps(planned_mps, v_mps, gap_m, v_lead_mps, step_s):
    """``planned_mps``, or less where the ACC model behind a leader ``gap_m`` ahead at
    ``v_lead_mps`` allows less over the next step from B's speed ``v_mps``."""
    if not math.isfinite(gap_m):
        return planned_mps
    gap_m = max(gap_m, 0.1)
    dv = v_mps - v_lead_mps
    want = GUARD_GAP_M + max(0.0, v_mps * GUARD_HEADWAY_S + v_mps * dv / (
        2.0 * math.sqrt(GUARD_ACC_MPS2 * GUARD_BRAKE_MPS2)))
    idm = GUARD_ACC_MPS2 * (1.0 - (want / gap_m) ** 2)
    # The heuristic: a leader no slower than B needs no braking; else brake to match its speed.
    cah = 0.0 if v_lead_mps > 0.0 and dv <= 0.0 else -max(dv, 0.0) ** 2 / (2.0 * gap_m)
    if idm >= cah:
        acc = idm
    else:
        acc = (1.0 - GUARD_COOLNESS) * idm + GUARD_COOLNESS * (
            cah + GUARD_BRAKE_MPS2 * math.tanh((idm - cah) / GUARD_BRAKE_MPS2))
    acc = max(acc, -GUARD_MAX_BRAKE_MPS2)
    return min(planned_mps, max(v_mps + acc * step_s, 0.0))
