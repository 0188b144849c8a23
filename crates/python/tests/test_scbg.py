"""The scbg Python module against a tiny model trained by the scbg binary."""

import json
import os
import subprocess
import tarfile

import numpy as np
import pytest

import scbg


def _pair(scene):
    return scene.sdc_id, [i for i in scene.objects_of_interest if i != scene.sdc_id][0]


def test_generate_and_courtesy(trained):
    model, file = trained
    assert model.variant == "full"
    assert model.audience == "pair"
    scene = scbg.read_scenarios(file)[0]
    a, b = _pair(scene)
    low = model.generate(scene, a, b, quantile=0.1)
    high = model.generate(scene, a, b, quantile=0.9)
    for out, q in ((low, 0.1), (high, 0.9)):
        assert out["world_xy_m"].shape == (80, 2) and np.isfinite(out["world_xy_m"]).all()
        assert abs(out["quantile"] - q) < 1e-6
        # A range the range predictor did not collapse.
        assert out["psi_low"] < out["psi_high"], out
        # The courtesy of a generated future is what generate's J_φ measured.
        c = model.courtesy(scene, a, b, out["world_xy_m"])
        assert abs(c["psi"] - out["achieved_psi"]) < 1e-3
    # The two ends of the knob move B.
    assert np.abs(low["world_xy_m"] - high["world_xy_m"]).max() > 0.1
    # An explicit ψ at the 0.9 quantile's value gives the same future.
    again = model.generate(scene, a, b, psi=high["psi"])
    np.testing.assert_allclose(again["world_xy_m"], high["world_xy_m"])


def test_the_ranked_policy_picks_labelled_samples(trained_dirs):
    gen, file = trained_dirs
    model = scbg.Model(gen, policy="ranked")
    assert model.policy == "ranked"
    scene = scbg.read_scenarios(file)[0]
    a, b = _pair(scene)
    # The tiny model's labels keep 26 futures of B (2 sampled, 24 of the baseline) and any
    # lane moves of them: quantile 0 takes the lowest-ψ one, quantile 1 the highest.
    low = model.generate(scene, a, b, quantile=0.0)
    high = model.generate(scene, a, b, quantile=1.0)
    # The pick at quantile 1 has the higher label; each future comes kept in lane, and J_φ of
    # it, measured again from its world-frame points, is the ψ reported as achieved.
    assert low["psi"] < high["psi"]
    measured = [model.courtesy(scene, a, b, out["world_xy_m"])["psi"] for out in (low, high)]
    for out, m in zip((low, high), measured):
        assert abs(m - out["achieved_psi"]) < 1e-3
    with pytest.raises(ValueError, match="unknown policy"):
        scbg.Model(gen, policy="oracle")


def test_scenes_from_bytes_and_arrays(trained):
    model, file = trained
    with open(file, "rb") as f:
        scenes = scbg.scenarios_from_bytes(f.read())
    assert len(scenes) == 12
    scene = scenes[0]
    states, valid = scene.states()
    assert states.shape == (len(scene.ids), 91, 7) and valid.shape == states.shape[:2]
    lane = np.stack([np.linspace(-50, 400, 200), np.zeros(200)], axis=1)
    rebuilt = scbg.Scene.from_arrays(
        "from-arrays", scene.ids, states, valid, sdc_id=scene.sdc_id,
        objects_of_interest=scene.objects_of_interest, lanes=[lane], road_edges=[lane + [0, 5]])
    assert rebuilt.num_steps == 91 and rebuilt.current_step == 10
    back, back_valid = rebuilt.states()
    np.testing.assert_allclose(back[valid], states[valid], rtol=1e-6, atol=1e-6)
    a, b = _pair(rebuilt)
    out = model.generate(rebuilt, a, b, quantile=0.5)
    assert out["world_xy_m"].shape == (80, 2)


def test_simulation_reset_and_step(trained):
    model, file = trained
    scene = scbg.read_scenarios(file)[0]
    a, b = _pair(scene)
    states, valid = scene.states()
    ia = list(scene.ids).index(a)
    sim = model.simulation(scene, {b: 0.9}, ego=a)  # the ego is driven from here
    ids, st, ok = sim.reset()
    assert sim.step_index == 10 and st.shape == (len(ids), 5) and ok.all()
    for t in range(11, 16):
        ego = states[ia, t, :5]
        ids, st, ok = sim.step(ego)
        np.testing.assert_allclose(st[list(ids).index(a), :2], ego[:2])
    assert sim.step_index == 15
    ib = list(ids).index(b)
    assert np.hypot(*(st[ib, :2] - states[ib, 10, :2])) > 0.1, "B did not move"
    reactive = model.simulation(scene, {b: 0.5}, ego=a, ego_mode="reactive", others="reactive")
    while not reactive.finished:
        reactive.step()
    assert reactive.scene().num_steps == 91
    # reset() starts over.
    reactive.reset()
    assert reactive.step_index == 10 and not reactive.finished


def test_bad_inputs_raise_value_errors(trained):
    model, file = trained
    scene = scbg.read_scenarios(file)[0]
    a, b = _pair(scene)
    with pytest.raises(ValueError, match="quantile 1.5"):
        model.generate(scene, a, b, quantile=1.5)
    with pytest.raises(ValueError, match="987654"):
        model.generate(scene, a, 987654, quantile=0.5)
    with pytest.raises(ValueError, match="not both"):
        model.generate(scene, a, b, quantile=0.5, psi=0.1)
    with pytest.raises(ValueError, match="80"):
        model.courtesy(scene, a, b, np.zeros((3, 2)))
    with pytest.raises(ValueError, match="shape"):
        scbg.Scene.from_arrays("x", np.array([1]), np.zeros((1, 91, 3)), np.ones((1, 91), bool))
    with pytest.raises(ValueError, match="ego_mode"):
        model.simulation(scene, {b: 0.5}, ego_mode="flying")
    with pytest.raises(ValueError, match="no agent with id 4242"):
        model.simulation(scene, {4242: 0.5})
    sim = model.simulation(scene, {b: 0.5}, ego=a)
    with pytest.raises(ValueError, match="ego"):
        sim.step()
    with pytest.raises(ValueError):
        scbg.read_scenarios("/nonexistent.tfrecord")


def _varint(n):
    out = bytearray()
    while True:
        byte, n = n & 0x7F, n >> 7
        out.append(byte | (0x80 if n else 0))
        if not n:
            return bytes(out)


def _field(number, payload):
    """A length-delimited protobuf field."""
    return _varint(number << 3 | 2) + _varint(len(payload)) + payload


def _submission_with_empty_joint_scenes(scenario_id, joint_scenes):
    """A SimAgentsChallengeSubmission encoded here, not by scbg: one scenario whose joint
    scenes hold no trajectory, submission_type SIM_AGENTS_SUBMISSION."""
    rollouts = _field(1, scenario_id.encode()) + b"".join(_field(2, b"") for _ in range(joint_scenes))
    return _field(1, rollouts) + bytes([0x10, 0x01])


def test_score_wosac_scores_a_submission_as_the_closed_loop_did(trained_dirs, tmp_path):
    gen, file = trained_dirs
    scene = scbg.read_scenarios(file)[0]
    a, b = _pair(scene)
    settings = tmp_path / "wosac.toml"
    settings.write_text('[closed_loop]\nformat = "wosac"\nname = "mine"\n')
    out = tmp_path / "sim"
    subprocess.run([os.environ.get("SCBG_BIN", "scbg"), "sim", "--model", gen, "--scenario", file,
                    "--scenario-id", scene.scenario_id, "--a", str(a), "--b", str(b),
                    "--config", str(settings), "--out", str(out)], check=True, capture_output=True)
    with open(out / "sim.json") as f:
        closed_loop = json.load(f)["wosac"]
    shard = out / "mine.binproto-00000-of-00001"

    score = scbg.score_wosac([file], [shard])
    assert score["challenge"] == "2025" and score["shards"] == 1
    assert [s["scenario_id"] for s in score["per_scenario"]] == [scene.scenario_id]
    scored = score["per_scenario"][0]
    for key, value in closed_loop.items():
        assert scored[key] == value, key
    assert score["aggregate"]["metametric"] == closed_loop["metametric"]
    assert score["not_submitted"] == len(scbg.read_scenarios(file)) - 1
    assert score["skipped_items"] == []

    # A .tar.gz of the shard gives the same numbers; a foreign encoder's submission with 2 joint
    # scenes and a shard that is not protobuf are left out with their reasons.
    archive = tmp_path / "submission.tar.gz"
    with tarfile.open(archive, "w:gz") as tar:
        tar.add(shard, arcname=shard.name)
    short = tmp_path / "short.binproto-00000-of-00001"
    short.write_bytes(_submission_with_empty_joint_scenes(scene.scenario_id, 2))
    garbage = tmp_path / "garbage.binproto-00000-of-00001"
    garbage.write_bytes(b"\x0a\x05\x01")
    packed = scbg.score_wosac([file], [archive])
    assert packed["per_scenario"][0]["metametric"] == scored["metametric"]
    bad = scbg.score_wosac([file], [short, garbage])
    assert bad["per_scenario"] == [] and bad["aggregate"] is None
    assert bad["skipped"] == {"not 32 joint scenes": 1,
                              "not a SimAgentsChallengeSubmission protobuf": 1}
    details = " ".join(k["detail"] for k in bad["skipped_items"])
    assert "2 joint scenes" in details and "garbage.binproto" in details
    with pytest.raises(ValueError, match="nothing-"):
        scbg.score_wosac([file], [str(tmp_path / "nothing-*.binproto")])
