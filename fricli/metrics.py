"""Error figures."""

from __future__ import annotations

import numpy as np


def errors(y: np.ndarray, y_pred: np.ndarray) -> dict[str, float]:
    """MAE, RMSE and max absolute error of y_pred against y, shapes (n,)."""
    e = np.asarray(y_pred, dtype=np.float64) - np.asarray(y, dtype=np.float64)
    if e.size == 0:
        return {"mae": float("nan"), "rmse": float("nan"), "max": float("nan"), "n": 0}
    return {"mae": float(np.mean(np.abs(e))), "rmse": float(np.sqrt(np.mean(e * e))),
            "max": float(np.max(np.abs(e))), "n": int(e.size)}


def relative_error(y: np.ndarray, y_pred: np.ndarray) -> float:
    """100 * ||y - y_pred|| / ||y|| [%]."""
    return float(100.0 * np.linalg.norm(y - y_pred) / np.linalg.norm(y))
