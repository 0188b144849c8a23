"""The real-simulator example: an scbg-driven merging car inside highway-env (from PyPI)."""

import os
import sys

import pytest

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "examples"))


def test_the_quantile_changes_how_highway_env_cars_fare(trained):
    try:
        import highway_env  # noqa: F401
    except ImportError:
        if os.environ.get("CI"):
            raise
        pytest.skip("highway-env is not installed (pip install highway-env)")
    import highway_merge

    model, _ = trained
    effects = []
    for seed in range(3):
        low = highway_merge.episode(model, 0.1, seed)
        high = highway_merge.episode(model, 0.9, seed)
        assert all(v > 0 for v in low + high)
        effects.append(high[0] - low[0])
    # The merging car's courtesy quantile changes the simulator's own cars' mean speed.
    assert any(abs(e) > 1e-3 for e in effects), effects
