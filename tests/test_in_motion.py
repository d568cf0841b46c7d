"""One rule decides which rows are in motion: ``fricli.core.metrics.in_motion`` (docs/log-format.md,
"In motion"). These tests grep the package for other in-motion thresholds."""

import pathlib
import re

import numpy as np

from fricli.core import metrics

PACKAGE = pathlib.Path(__file__).resolve().parent.parent / "fricli"

#: ways code decides "in motion" on its own
PATTERNS = {
    "its own rest share": re.compile(r"\bREST_SHARE\s*="),
    "its own in-motion function": re.compile(r"\bdef\s+(in_motion|_moving|_?at_rest|_?is_moving)\s*\("),
    "a share of the top speed": re.compile(r"[<>]=?[^<>\n]*\*\s*(float\()?[\w.]*\b(top|vmax|max\(\))"),
    "exact zero velocity": re.compile(r"\bqd[\"']?\]?\s*(!=|==)\s*0(\.0*)?\b(?!\.\d)|\bspeed\s*>\s*0(\.0*)?\b(?!\.\d)"),
    "a speed threshold": re.compile(r"\b(speed|np\.abs\(\s*\w*qd\w*\s*\))\s*>=?\s*(?!0\b)[\w(]"),
}
#: lines that state a threshold the user gave (adapt --min-speed), not a rule of their own
USER_GIVEN = re.compile(r"\bmin_speed\b")
#: (file, pattern name): why it is not an in-motion rule over a log
ALLOWED = {
    ("models/terms.py", "exact zero velocity"):
        "a model's held state at run time (the held direction and torque at the last sample with qd != 0): "
        "a controller knows no top speed of a log",
    ("models/residual.py", "exact zero velocity"):
        "the smallest speed the training rows reach sets the pre-sliding scale v_ps (a scale, not a choice "
        "of rows)",
    ("models/dissipative.py", "exact zero velocity"):
        "the training rows' speeds set the velocity scale v0 (a scale, not a choice of rows; the rows are "
        "chosen by train-base)",
    ("fitting/training_data.py", "a speed threshold"):
        "the lowest bin of the velocity histogram that finds a sweep's levels (LOW, below the in-motion share: "
        "a sweep's slowest levels), not a choice of rows in motion",
    ("fitting/steady.py", "a speed threshold"):
        "the velocity noise floor of steady-state and settled detection (NOISE_FLOOR, or four times the "
        "sample-to-sample velocity noise): rows whose velocity is known well enough to lie on the static "
        "curve (steady or settled), a question other than which rows move",
    ("applying/observer.py", "a speed threshold"):
        "the controller's rest speed (moving_speed, from the thresholds file, `fricli thresholds "
        "--moving-speed`): the observer runs causally, row by row, and knows no top speed of a log",
    ("fitting/steady.py", "a share of the top speed"):
        "the same velocity noise floor of steady-state detection",
}


def hits() -> list[str]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE).as_posix()
        if rel == "core/metrics.py":
            continue
        for number, line in enumerate(path.read_text().splitlines(), 1):
            code = line.split("#", 1)[0]
            if not code.strip() or code.lstrip().startswith(('"""', "'''")) or USER_GIVEN.search(code):
                continue
            for name, pattern in PATTERNS.items():
                if pattern.search(code) and (rel, name) not in ALLOWED:
                    out.append(f"fricli/{rel}:{number}: {name}: {line.strip()}")
    return out


def test_patterns_catch_the_ways_in_motion_was_decided():
    caught = ["REST_SHARE = 0.02", "def _moving(qd):", "return mask & (speed > max(abs_tol, 1e-3 * top))",
              "moving = np.abs(v) > 1e-3 * top", "moving = speed > training_data.LOW * float(speed.max())",
              "moving = qd != 0", "m = self.signals[\"qd\"] != 0", "rest = qd == 0.0", "moving = speed[speed > 0]",
              "moving = speed > abs_tol",
              "moving = speed >= lo", "mask = np.abs(qd) > tol"]
    for line in caught:
        assert any(p.search(line) for p in PATTERNS.values()), line
    fine = ["moving = metrics.in_motion(qd)", "if abs(v) > RATIO_BOUND:", "top = float(speed.max())",
            "pos = (qd > 0).astype(float)", "if ctx.v_scale() <= 0:", "x = 0.5 * vmax", "qd = 0.5"]
    for line in fine:
        assert not any(p.search(line) for p in PATTERNS.values()), line


def test_no_other_in_motion_threshold_in_the_package():
    found = hits()
    assert not found, "in-motion thresholds other than fricli.core.metrics.in_motion:\n" + "\n".join(found)


def test_in_motion_is_a_share_of_the_top_speed():
    qd = np.array([0.0, -0.01, 0.021, -1.0, 0.5, 0.02])
    assert metrics.in_motion(qd).tolist() == [False, False, True, True, True, False]
    assert metrics.in_motion(1000 * qd).tolist() == metrics.in_motion(qd).tolist()    # no unit in the rule
    assert not metrics.in_motion(np.zeros(5)).any() and metrics.in_motion(np.zeros(0)).shape == (0,)


def test_a_hold_is_a_stretch_at_rest_longer_than_a_pass_through_a_reversal():
    """A sine motion of 2.5 min period passes each reversal within HOLD_S below the in-motion
    speed: no hold; a stop of 2 s in it is one, and only its rows are."""
    t = np.arange(0.0, 300.0, 0.01)
    qd = np.cos(2 * np.pi * t / 150.0)
    assert not metrics.at_hold(t, qd).any()
    stop = (t > 40.0) & (t < 42.0)
    held = metrics.at_hold(t, np.where(stop, 0.0, qd))
    assert held[stop].all() and not held[~stop].any()
    assert not metrics.at_hold(t, np.zeros_like(t), longer=400.0).any()
