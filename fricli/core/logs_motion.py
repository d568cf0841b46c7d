"""A log's motion columns filtered and differentiated: the zero-phase low-pass, qd and qdd derived
where missing, and rate columns and time steps that cannot be measurements."""

from __future__ import annotations

import math

import numpy as np

from fricli.core.errors import DataError

HALF_TURN = math.pi   # rad: no joint moves half a turn between two samples; a step beyond it is a wrap at a turn

PLAUSIBLE_STEP = (1e-5, 0.1)    # s: a controller's sample period lies between these (100 kHz, 10 Hz)


def implausible_step(step: float | None) -> bool:
    """Whether a median time step [s] lies outside ``PLAUSIBLE_STEP`` (by more than 1 ppm: recorded
    timestamps carry rounding): a time column in the wrong unit."""
    return step is not None and not PLAUSIBLE_STEP[0] * (1 - 1e-6) <= step <= PLAUSIBLE_STEP[1] * (1 + 1e-6)


def wraps(q: np.ndarray) -> bool:
    """Whether rotary positions q (n,) [rad] step by more than half a turn between two samples
    anywhere: recorded within one turn (a continuous joint, or a driver that wraps), not a motion."""
    return len(q) > 1 and bool(np.abs(np.diff(q)).max() > HALF_TURN)


def lowpass_applies(t: np.ndarray, cutoff_hz: float) -> bool:
    """Whether ``lowpass`` filters at all: 16 samples or more and a cut-off below the Nyquist
    frequency (by more than 1 ppm: a recorded sample rate carries rounding in its timestamps)."""
    return len(t) >= 16 and cutoff_hz < 0.5 / float(np.median(np.diff(t))) * (1 - 1e-6)


def lowpass(x: np.ndarray, t: np.ndarray, cutoff_hz: float, order: int = 4) -> np.ndarray:
    """Zero-phase Butterworth low-pass of ``x`` sampled at times ``t`` (median rate). DataError
    when the cut-off is so far below the sample rate that the filter is singular."""
    if not lowpass_applies(t, cutoff_hz):
        return x.copy()
    fs = 1.0 / float(np.median(np.diff(t)))
    from scipy import signal  # imported here: it costs about a second at start-up

    sos = signal.butter(order, cutoff_hz, fs=fs, output="sos")
    # padded by the ends' odd reflection over three periods of the cut-off (scipy's default pads a
    # few samples, so a low cut-off left a transient in the first and last tenth of a second)
    try:
        return signal.sosfiltfilt(sos, x, padlen=min(len(x) - 1, max(3 * (2 * len(sos) + 1), int(3 * fs / cutoff_hz))))
    except np.linalg.LinAlgError:
        raise DataError(f"a low-pass cut-off of {cutoff_hz:g} Hz is too far below the sample rate ({fs:g} Hz) "
                        "to filter at") from None


def check_lowpass_period(t: np.ndarray, cutoff_hz: float) -> None:
    """DataError when a period of ``cutoff_hz`` is longer than the log of times ``t``: a zero-phase
    filter of it outputs little but its padding (``--lowpass`` of an output)."""
    duration = float(t[-1] - t[0]) if len(t) else 0.0
    if lowpass_applies(t, cutoff_hz) and cutoff_hz * duration < 1:
        raise DataError(f"--lowpass {cutoff_hz:g} Hz is a period longer than the log ({duration:g} s): "
                        f"give at least {1 / duration:.3g} Hz")


def _contradicts(x: np.ndarray, rate: np.ndarray, t: np.ndarray) -> bool:
    """Whether a rate column constant over the rows (``rate``) contradicts the signal ``x`` it is
    the derivative of: x departs from x[0] + rate (t - t[0]) by more than a tenth of its range (a
    constant-velocity sweep, or a constant-acceleration ramp, agrees with it)."""
    if len(x) < 3 or np.ptp(rate) != 0 or not np.ptp(x) > 0:
        return False
    return bool(np.max(np.abs(x - x[0] - rate[0] * (t - t[0]))) > 0.1 * np.ptp(x))


def not_measured(sig: dict[str, np.ndarray], qdd: bool = True, kept: bool = False) -> list[tuple[str, str]]:
    """Motion columns that cannot be measurements, as (column, note): an acceleration ``qdd``
    constant over a log whose velocity varies otherwise (a column of zeros a recorder filled in),
    a velocity ``qd`` constant while the position moves otherwise. Such a column is unknown, not a
    value: the caller drops it and it is derived like a missing one (``qdd`` as ``derive_motion``'s);
    ``kept``: the caller writes it as recorded (an import without the robot terms), and the note says so."""
    out, t = [], sig["t"]
    left = "not a measurement; the log keeps it as recorded and every command reads it as missing (derived where needed)"
    if "q" in sig and "qd" in sig and _contradicts(sig["q"], sig["qd"], t):
        out.append(("qd", f"the velocity column qd is constant ({sig['qd'][0]:g}) while the position moves "
                          "otherwise: " + (left if kept else "not a measurement, derived from q instead")))
    if "qdd" in sig and "qd" in sig and not out and _contradicts(sig["qd"], sig["qdd"], t):
        out.append(("qdd", f"the acceleration column qdd is constant ({sig['qdd'][0]:g}) while the velocity "
                           "varies otherwise: " + (left if kept else "not a measurement, "
                                                   + ("derived from the velocity instead" if qdd else "left out (not read)"))))
    elif "qdd" in sig and out and np.ptp(sig["qdd"]) == 0:
        out.append(("qdd", "the acceleration column qdd is constant too: " + (left if kept else "derived with the velocity")))
    return out


def dead_torque(sig: dict[str, np.ndarray], unit: str = "Nm") -> str | None:
    """A note when the motor torque is one value on every row while the joint moves both ways:
    friction changes sign with the motion, so no measured torque stays put (a recorder writes
    zeros, or its last value, for a channel it did not record); else None."""
    tau, qd = sig.get("tau_m"), sig.get("qd")
    if tau is None or qd is None or len(tau) < 3 or np.ptp(tau) != 0 or not (qd.max() > 0 > qd.min()):
        return None
    return (f"'tau_m' is {tau[0]:g} {unit} on every one of the {len(tau)} rows while the joint moves both ways: not a "
            "measurement (a channel the recorder did not record?); the friction target and the external torque "
            "built from it are meaningless")


def rate_mismatch(sig: dict[str, np.ndarray], check: str = "check each column's field metadata 'unit'") -> str | None:
    """A note when a measured ``qd`` is not the rate of change of ``q`` over ``t`` but a multiple
    of it (units of t, q and qd that disagree: t in ms read as s, degrees read as radians); else
    None. The increments of q over 200 windows of the first 100,000 rows are compared with the
    integral of qd over them (a least-squares factor), where the two agree in shape (correlation
    above 0.95). ``check``: where the note sends the user."""
    q, qd, t = sig.get("q"), sig.get("qd"), sig["t"]
    if q is None or qd is None or len(t) < 10:
        return None
    q, qd, t = q[:100_000], qd[:100_000], t[:100_000]
    w = max(1, len(t) // 200)
    moved = np.concatenate([[0.0], np.cumsum(0.5 * (qd[1:] + qd[:-1]) * np.diff(t))])
    a, b = moved[w:] - moved[:-w], q[w:] - q[:-w]
    ab, aa, bb = float(np.dot(a, b)), float(np.dot(a, a)), float(np.dot(b, b))
    if not (aa > 0 and bb > 0 and np.isfinite(ab * aa * bb)) or ab / np.sqrt(aa * bb) < 0.95:
        return None
    factor = ab / bb
    if 0.2 < factor < 5:
        return None
    return (f"qd is {factor:.3g} times the rate of change of q over t: their units disagree (1e+03: t in ms read "
            f"as s; 57.3 or 0.0175: degrees read as radians); {check}")


def derives_qdd(has_qd: bool, has_qdd: bool, qdd: bool = True) -> bool:
    """Whether ``derive_motion`` derives qdd: where the log lacks it and the reader reads it
    (``qdd``), or where qd is derived too (from it, by differences: no further filter)."""
    return not has_qdd and (qdd or not has_qd)


def derive_motion(sig: dict[str, np.ndarray], cutoff_hz: float, qdd: bool = True, rotary: bool = False) -> dict:
    """Fill in missing qd and qdd in place: zero-phase low-pass, then central differences.
    ``qdd`` False: a missing qdd stays missing where qd is measured (a reader that reads no
    acceleration spares the zero-phase filter of qd, which needs the whole log). ``rotary``: a
    position that wraps at a turn (``wraps``) is differentiated unwrapped (``"unwrapped": True``)."""
    derived = []
    t = sig["t"]
    acceleration = derives_qdd("qd" in sig, "qdd" in sig, qdd)
    if len(t) < 3 and ("qd" not in sig or acceleration):
        raise DataError("too few samples to derive velocity and acceleration")
    unwrapped = False
    if "qd" not in sig:
        unwrapped = rotary and wraps(sig["q"])
        sig["qd"] = np.gradient(lowpass(np.unwrap(sig["q"]) if unwrapped else sig["q"], t, cutoff_hz), t)
        derived.append("qd")
        if acceleration:
            sig["qdd"] = np.gradient(sig["qd"], t)
            derived.append("qdd")
    elif acceleration:
        sig["qdd"] = np.gradient(lowpass(sig["qd"], t, cutoff_hz), t)
        derived.append("qdd")
    return ({"columns": derived, "cutoff_hz": cutoff_hz, **({"unwrapped": True} if unwrapped else {})}
            if derived else {})
