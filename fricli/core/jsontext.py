"""JSON as fricli writes it: NaN and infinities as null, keys sorted, indented, one final newline."""

from __future__ import annotations

import json
import math


def json_safe(obj):
    """``obj`` with NaN and infinite floats as None (JSON null): e.g. the MAE over no rows."""
    if isinstance(obj, float) and not math.isfinite(obj):
        return None
    if isinstance(obj, dict):
        return {k: json_safe(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [json_safe(v) for v in obj]
    return obj


def is_finite_number(value) -> bool:
    """Whether a value read from JSON is a finite number (not a bool)."""
    return isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)


def is_count(value, least: int = 0) -> bool:
    """Whether a value read from JSON is an integer (not a bool) of at least ``least``."""
    return isinstance(value, int) and not isinstance(value, bool) and value >= least


def dumps(obj) -> str:
    """The JSON text of ``obj`` (``json_safe``), indented by 2, keys sorted, ending in a newline."""
    return json.dumps(json_safe(obj), indent=2, sort_keys=True, allow_nan=False) + "\n"
