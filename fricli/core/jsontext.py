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


def dumps(obj) -> str:
    """The JSON text of ``obj`` (``json_safe``), indented by 2, keys sorted, ending in a newline."""
    return json.dumps(json_safe(obj), indent=2, sort_keys=True, allow_nan=False) + "\n"
