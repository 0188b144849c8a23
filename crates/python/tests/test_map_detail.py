"""Map robustness of the release model: on a straight two-lane road built from arrays, B's
plan at every quantile keeps within 0.5 m of a lane centre line, whatever the lane type and
whether road lines and edges are given, except while it changes lanes."""

import itertools

import numpy as np
import pytest

import scbg

LANE_WIDTH_M = 3.6
TOLERANCE_M = 0.5


def straight_road(lane_type, lines, edges):
    xs = np.arange(-100.0, 400.0, 1.0)
    ys = (0.0, LANE_WIDTH_M)
    kw = {"lanes": [np.stack([xs, np.full_like(xs, y)], 1) for y in ys]}
    if lane_type is not None:
        kw["lane_types"] = [lane_type] * 2
    if lines:
        kw["road_lines"] = [np.stack([xs, np.full_like(xs, LANE_WIDTH_M / 2)], 1)]
    if edges:
        kw["road_edges"] = [
            np.stack([xs, np.full_like(xs, -LANE_WIDTH_M / 2 - 0.5)], 1),
            np.stack([xs[::-1], np.full_like(xs, 1.5 * LANE_WIDTH_M + 0.5)], 1),
        ]
    return kw


def pair_scene(road, b_lane_y):
    """A (id 1) at 20 m/s in the right lane; B (id 2) 30 m ahead at 17 m/s in lane b_lane_y."""
    t = np.arange(11) * 0.1 - 1.0
    rows = []
    for x0, y, v in ((0.0, 0.0, 20.0), (30.0, b_lane_y, 17.0)):
        st = np.zeros((11, 7))
        st[:, 0], st[:, 1], st[:, 3], st[:, 5], st[:, 6] = x0 + v * t, y, v, 4.6, 1.9
        rows.append(st)
    states = np.stack(rows)
    return scbg.Scene.from_arrays("straight-road", np.array([1, 2]), states,
                                  np.ones(states.shape[:2], bool), sdc_id=1,
                                  objects_of_interest=[1, 2], **road)


def off_lane_runs(ys):
    """Runs of plan points farther than the tolerance from both lane centres, and whether the
    plan ends in another lane than it starts in."""
    centres = np.array([0.0, LANE_WIDTH_M])
    dev = np.min(np.abs(ys[:, None] - centres[None, :]), axis=1)
    off = dev > TOLERANCE_M
    runs = np.count_nonzero(np.diff(off.astype(int)) == 1) + int(off[0])
    lane = np.argmin(np.abs(ys[:, None] - centres[None, :]), axis=1)
    return runs, lane[0] != lane[-1], dev.max()


@pytest.mark.parametrize("b_lane_y", [0.0, LANE_WIDTH_M], ids=["B-ahead-of-A", "B-in-the-next-lane"])
def test_release_plans_keep_to_a_lane_on_any_map_detail(release, b_lane_y):
    failures = []
    for lane_type, lines, edges in itertools.product(
        [None, "undefined", "freeway", "surface_street"], [True, False], [True, False]
    ):
        scene = pair_scene(straight_road(lane_type, lines, edges), b_lane_y)
        for q in (0.1, 0.3, 0.5, 0.7, 0.9):
            ys = np.asarray(release.generate(scene, 1, 2, quantile=q)["world_xy_m"])[:, 1]
            runs, changes_lane, worst = off_lane_runs(ys)
            # Off every lane centre only while changing lanes: one run, ending in another lane.
            if runs > (1 if changes_lane else 0):
                failures.append(f"{lane_type} lines={lines} edges={edges} q={q}: "
                                f"{worst:.2f} m off, {runs} runs, lane change {changes_lane}")
    assert not failures, "\n".join(failures)


def test_the_release_model_plans_as_an_ensemble_whose_courtesy_is_its_own(release, release_member):
    """The release model is four generators planning together, and the ψ it reports for its
    future is its own measure of that future, as ``courtesy`` gives it."""
    assert release.members == 4 and release_member.members == 1
    scene = pair_scene(straight_road("freeway", True, True), LANE_WIDTH_M)
    out = release.generate(scene, 1, 2, quantile=0.9)
    again = release.courtesy(scene, 1, 2, out["world_xy_m"])
    assert abs(out["achieved_psi"] - again["psi"]) < 1e-5, (out["achieved_psi"], again)
