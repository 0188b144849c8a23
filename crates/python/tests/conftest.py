"""A tiny model trained by the scbg binary, shared by the test files."""

import os
import subprocess

import pytest

import scbg


def _scbg(*args):
    subprocess.run([os.environ.get("SCBG_BIN", "scbg"), *args], check=True, capture_output=True)


@pytest.fixture(scope="session")
def trained_dirs(tmp_path_factory):
    """The tiny generator's folder and the scenario file it was trained on."""
    d = tmp_path_factory.mktemp("scbg")
    data, cache, model, gen = (str(d / n) for n in ("data", "cache", "model", "gen"))
    _scbg("synth", "--scenarios", "12", "--seed", "4", "--out", data, "--scenarios-per-file", "12")
    _scbg("data", "prepare", "--input", data, "--out", cache)
    _scbg("train", "predictor", "--config", os.environ["SCBG_TINY_CONFIG"], "--data", cache,
          "--out", model)
    settings = d / "tiny.toml"
    settings.write_text("[labels]\nsamples = 2\n[generator]\nepochs = 1\nbatch_size = 8\n"
                        "range_steps = 100\n")
    _scbg("train", "generator", "--predictor", model, "--data", cache, "--out", gen,
          "--config", str(settings))
    return gen, os.path.join(data, "synth-00000.tfrecord")


@pytest.fixture(scope="session")
def trained(trained_dirs):
    gen, file = trained_dirs
    return scbg.Model(gen), file


RELEASE_MODEL = os.path.join(os.path.dirname(__file__), "..", "..", "..", "models", "courtesy")


@pytest.fixture(scope="session")
def release():
    """The release model of the repository (models/courtesy): four trained generators planning as one."""
    return scbg.Model(RELEASE_MODEL)


@pytest.fixture(scope="session")
def release_member():
    """One member of the release model alone (its data seed 0), for situations that one model's
    plans make."""
    return scbg.Model(os.path.join(RELEASE_MODEL, "seed0", "generator"))
