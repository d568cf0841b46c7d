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


REST_SHARE = 0.02


def in_motion(qd: np.ndarray, share: float = REST_SHARE) -> np.ndarray:
    """Rows moving faster than ``share`` of the top speed, (n,) bool.

    At standstill the friction is statically indeterminate (stiction holds any torque up to the
    breakaway level, set by the motion before), so friction figures are also given over the rows
    in motion.
    """
    speed = np.abs(qd)
    top = float(speed.max()) if speed.size else 0.0
    return speed > share * top if top > 0 else np.zeros(speed.shape, dtype=bool)
