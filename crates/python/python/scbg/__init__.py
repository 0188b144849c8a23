"""scbg: socially-controllable behaviour generation (the Rust library, from Python).

Load a trained generator folder, build scenes (from WOMD files, bytes or numpy arrays),
generate B's future at a courtesy quantile toward A, score the courtesy of any future, and
simulate in closed loop step by step — the same library calls as ``scbg serve``.
"""

from ._scbg import Model, Scene, Simulation, read_scenarios, scenarios_from_bytes

__all__ = ["Model", "Scene", "Simulation", "read_scenarios", "scenarios_from_bytes"]
