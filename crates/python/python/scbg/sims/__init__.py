"""Foreign simulators driven by scbg: harnesses that put one scbg-driven car among a simulator's own."""

import math


def check_arm(arm):
    """Raises ``ValueError`` unless ``arm`` is one of the arms every harness's ``episode`` takes:
    ``{"kind": "scbg", "quantile": q}`` with q in [0, 1], ``{"kind": "yardstick", "level":
    "low" | "high"}`` or ``{"kind": "default"}``."""
    kind = arm.get("kind") if isinstance(arm, dict) else None
    if kind == "scbg":
        q = arm.get("quantile")
        if not isinstance(q, (int, float)) or math.isnan(float(q)) or not 0.0 <= float(q) <= 1.0:
            raise ValueError(f"scbg arm: quantile must be a number in [0, 1], got {q!r}")
    elif kind == "yardstick":
        if arm.get("level") not in ("low", "high"):
            raise ValueError(f"yardstick arm: level must be 'low' or 'high', got {arm.get('level')!r}")
    elif kind != "default":
        raise ValueError(f"arm must be a dict with kind 'scbg', 'yardstick' or 'default', got {arm!r}")
