"""Foreign simulators driven by scbg: harnesses that put one scbg-driven car among a simulator's own."""

import math


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
    ``"low"``, ``"high"``, or a fraction of the way from the low to the high setting, which
    only a yardstick whose settings are numbers has."""
    if level in ("low", "high"):
        return yardstick[level]
    low, high = yardstick["low"], yardstick["high"]
    if not isinstance(low, (int, float)):
        raise ValueError(f"yardstick {yardstick['parameter']!r} has two settings only: 'low' and 'high'")
    return low + float(level) * (high - low)
