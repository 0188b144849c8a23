"""scbg: socially-controllable behaviour generation (the Rust library, from Python).

Load a trained generator folder, build scenes (from WOMD files, bytes or numpy arrays),
generate B's future at a courtesy quantile toward A, score the courtesy of any future, and
simulate in closed loop step by step — the same library calls as ``scbg serve``; and score
anyone's WOSAC submission as ``scbg eval wosac`` does.
"""

from ._scbg import Model, Scene, Simulation, read_scenarios, scenarios_from_bytes
from ._scbg import score_wosac

__all__ = ["Model", "Scene", "Simulation", "read_scenarios", "scenarios_from_bytes"]
__all__ += ["score_wosac"]
