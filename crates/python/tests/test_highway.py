"""The real-simulator example: an scbg-driven merging car inside highway-env (from PyPI)."""

import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "examples"))

SEEDS = 6


def test_a_courteous_b_lets_highway_env_a_drive_faster(trained):
    try:
        import highway_env  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("highway-env is not installed (pip install highway-env)")
    import highway_merge

    model, _ = trained
    # B, driven by scbg ahead of highway-env's A, at a high courtesy quantile toward A against
    # a low one, in the same episodes (only the quantile changes): A's mean speed is higher,
    # on the paired mean over the seeds.
    effects = []
    for seed in range(SEEDS):
        low = highway_merge.episode(model, 0.1, seed)
        high = highway_merge.episode(model, 0.9, seed)
        assert all(v > 0 for v in low + high)
        effects.append(high[1] - low[1])
    assert sum(effects) / len(effects) > 0, effects
