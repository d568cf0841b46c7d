"""Error figures."""

from __future__ import annotations

import numpy as np

from fricli.core.errors import DataError


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


#: a row is in motion when |qd| exceeds this share of the log's top speed (docs/log-format.md, "In motion")
REST_SHARE = 0.02
#: a joint whose position spans less than this over a whole log [rad or m] is held still (its
#: in-motion rows are velocity noise): a log of one joint at a time holds the others so
HELD_SPAN = 0.01


#: a stretch of rows not in motion lasting longer than this [s] is a hold, not a pass through a
#: reversal: a joint in sine motion of period P spends 0.64 % of P below REST_SHARE of its top
#: speed at each reversal, under 1 s for any period up to 2.5 min
HOLD_S = 1.0

#: a load slope needs |tau_g| to vary by at least this share of the friction level (docs/lugre.md)
LOAD_SHARE = 0.05


def load_range(tau_g: np.ndarray, friction: np.ndarray) -> tuple[float, float]:
    """The 5th-to-95th percentile range of |tau_g| (n,) and the median |friction| (n,) [Nm]."""
    lo, hi = np.percentile(np.abs(tau_g), [5, 95])
    return float(hi - lo), float(np.median(np.abs(friction)))


def load_can_show(tau_g: np.ndarray, friction: np.ndarray) -> bool:
    """Whether the gravity torque varies enough over these rows for a load slope of the friction
    to show: its range (``load_range``) at least LOAD_SHARE of the friction level. Below that,
    even a slope of 1 (friction growing as fast as the load on the gear, more than any gear shows)
    moves the friction by less than LOAD_SHARE of its level: no slope can be told from noise, and
    one fitted there would extrapolate to every larger load the joint meets (a payload on a wrist
    that carried almost none)."""
    spread, level = load_range(tau_g, friction)
    return spread >= LOAD_SHARE * level and spread > 0


def held_still(q: np.ndarray) -> np.ndarray:
    """Columns of ``q`` (n, joints) [rad or m] whose span is under HELD_SPAN, (joints,) bool."""
    return np.ptp(q, axis=0) < HELD_SPAN if len(q) else np.ones(q.shape[1], dtype=bool)


def in_motion(qd: np.ndarray, share: float = REST_SHARE) -> np.ndarray:
    """Rows moving faster than ``share`` of the top speed max|qd|, (n,) bool; none when the
    joint never moves. The one rule for "in motion" in fricli.

    At standstill the friction is statically indeterminate (stiction holds any torque up to the
    breakaway level, set by the motion before), so friction figures are also given over the rows
    in motion, and fits of a friction curve over velocity use only those rows. Relative to the
    top speed, the rule does not depend on the unit of qd, and the velocity noise at rest (a
    small share of any real motion) falls below it.
    """
    speed = np.abs(qd)
    top = float(speed.max()) if speed.size else 0.0
    return speed > share * top if top > 0 else np.zeros(speed.shape, dtype=bool)


def slow_motion(qd: np.ndarray) -> np.ndarray:
    """Rows that move but not ``in_motion``: 0 < |qd| at or below its share, (n,) bool. A joint
    passes there through each reversal (where a pre-sliding state shows); standstill, qd = 0,
    holds what the controller set."""
    return (np.asarray(qd) != 0) & ~in_motion(qd)


def at_hold(t: np.ndarray, qd: np.ndarray, longer: float = HOLD_S) -> np.ndarray:
    """Rows of the stretches not ``in_motion`` that last longer than ``longer`` [s] (time of a
    stretch's last row minus its first), (n,) bool: the joint held still, where the torque is what
    the controller left, not a law of friction. The slow rows of a pass through a reversal, where
    a pre-sliding state shows, are not among them."""
    t = np.asarray(t, dtype=np.float64)
    out = np.zeros(len(t), dtype=bool)
    for a, b in true_runs(~in_motion(qd)):
        if t[b - 1] - t[a] > longer:
            out[a:b] = True
    return out


def true_runs(mask: np.ndarray) -> list[tuple[int, int]]:
    """(start, stop) of every maximal run of True in ``mask`` (n,) bool, rows start:stop."""
    edges = np.flatnonzero(np.diff(np.concatenate([[0], np.asarray(mask, dtype=np.int8), [0]])))
    return [(int(a), int(b)) for a, b in zip(edges[::2], edges[1::2])]


def moving_both_ways(qd: np.ndarray, what: str) -> np.ndarray:
    """The rows in motion (``in_motion``), (n,) bool; DataError naming ``what`` (e.g. "the linear
    model") when none of them moves in one of the two directions."""
    moving = in_motion(qd)
    for name, side in (("positive", qd > 0), ("negative", qd < 0)):
        if not (moving & side).any():
            raise DataError(f"no rows in motion with {name} velocity: {what} needs motion in both directions")
    return moving
