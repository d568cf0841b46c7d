"""What a controller runs every sample: the generalized-momentum observer of the external torque,
the online adaptation of each joint's friction level and contact detection, row by row.

The observer (De Luca et al.): with p = M(q) qd the generalized momentum and the robot equation in
fricli's sign convention (docs/log-format.md: ``tau_ext = tau_g + tau_dyn + tau_f - tau_m``),

    dp/dt = tau_m - tau_f + tau_ext - g(q) + C(q, qd)^T qd

so the residual r = K (p(t) - p(0) - integral(tau_m - tau_f_pred + C^T qd - g + r) dt) obeys
dr/dt = K (tau_ext + tau_f - tau_f_pred - r): a first-order low-pass, of time constant 1/K, of the
external torque plus the friction model's error. No acceleration is needed. Discretised by the
backward Euler rule over each sample's own interval dt_k = t_k - t_(k-1), it is

    y_k = (y_(k-1) - K (p_k - p_(k-1)) + K dt_k (tau_m,k - w_k)) / (1 + K dt_k)      "measured friction"
    f_k = (f_(k-1) + K dt_k f0_k) / (1 + K dt_k)                                    "model friction"
    r_k = a f_k + b - y_k

with w = g - C^T qd, f0 the friction model's output and (a, b) the friction level (1, 0 unless
adapted): r_k is the observer's residual exactly (both filters are linear, so the low-pass of
``a f0 + b - (friction + external torque)`` is the difference of the low-passes), stable for any
K dt, and the rows need not be evenly spaced. ``tau_ext_pred`` is r, ``tau_f_pred`` a f0 + b.

Where the controller's robot model is the log's own columns (a log without a URDF), the per-joint
form takes p = 0 and w = tau_g + tau_dyn: the same filter of tau_g + tau_dyn + tau_f_pred - tau_m,
which needs the acceleration in tau_dyn.

Adaptation: per joint, the scale a of the model's friction (and, with ``offset``, an offset b),
tracked by recursive least squares with exponential forgetting on (f_k, 1) -> y_k (f_k -> y_k
without the offset): the a-priori error is -r_k itself. The scale alone is the default: an offset
also absorbs whatever torque error depends on the position (a gravity error, a gear ripple), which
it then tracks with the memory's lag. The
forgetting factor of a sample is exp(-dt_k / T) (T: the memory's time constant). The offset is
normalised by the joint's friction scale S (the RMS of the model's friction in motion on the
calibration logs, ``Thresholds``). An update is made only while the joint moves
(|qd| > ``moving_speed``: at rest friction is statically indeterminate) and no contact is suspected
(|r| at most ``freeze`` times the joint's threshold, and no contact flagged on this row or in the
``holdoff`` seconds before it: a push whose residual dips below the release for a moment is not
learned then); a and b are clipped to
their bounds after every update and the covariance's trace is capped at its initial value
(no wind-up while a direction is not excited). The friction of row k uses the level of rows < k.

Contact: a joint is flagged once r has stayed beyond its threshold, with one sign, for
``persistence`` samples in a row (a single wrong sample of tau_m or qd is not a contact), and
released when |r| falls below ``release`` times the threshold (hysteresis). In motion the threshold
is base + share x |a f_k + b|: a change of the friction level leaves an error proportional to the
friction itself (``level_share`` calibrates the share); at rest it is base. At rest (|qd| at most ``moving_speed``) the friction is statically
indeterminate: a held joint keeps whatever friction torque it came to rest with, anywhere within
its static band [-F_s, F_s], which no model of the state predicts, and an external torque within
that band does not reach the motor. With thresholds, the estimate at rest is therefore the part of
the measured torque outside the band: tau_ext_pred = clip(y, b - a F_s, b + a F_s) - y
(``static_friction``: F_s per joint, the largest friction the model gives just above
``moving_speed`` on the calibration logs; a and b the adapted scale and offset, 1 and 0 without
adaptation: the band is friction, at the level the joint's friction has); in motion it is r.
"""

from __future__ import annotations

import dataclasses
import json
import math

import numpy as np

from fricli.core import metrics
from fricli.core.errors import DataError, LogError
from fricli.core.jsontext import is_count

DEFAULT_GAIN = 50.0            # K [1/s]: the observer's bandwidth (time constant 20 ms)
FAST_GAIN = 100.0              # K [1/s] of thresholds calibrated on logs sampled at FAST_STEP or faster
FAST_STEP = 0.5 / FAST_GAIN    # s: the sample interval up to which K dt stays at most 0.5 at FAST_GAIN
DEFAULT_QUANTILE = 0.999       # of |r| over the calibration logs' rows
DEFAULT_MARGIN = 1.5           # threshold = margin x that quantile
DEFAULT_RELEASE = 0.5          # a flag is released below this share of the threshold
DEFAULT_MOVING_SPEED = 0.02    # |qd| above which a joint moves [rad/s or m/s]
DEFAULT_PERSISTENCE = 3        # samples beyond the threshold, of one sign, before a flag
MAX_PERSISTENCE = 1_000_000    # at most (an int of the exported C code; 1,000 s at 1 kHz)
FORMS = ("per-joint", "urdf")  # the observer forms thresholds are calibrated on
FORGET_MIN = 1e-12             # least forgetting factor: a gap of over 27.6 T forgets as much (the
                               # covariance cap binds; exp underflows to 0 past 745 T)
THRESHOLDS_FORMAT = "fricli.thresholds"
THRESHOLDS_VERSION = 1


@dataclasses.dataclass(frozen=True)
class Adaptation:
    """The online adaptation's settings (module docstring)."""

    time_constant: float = 30.0          # T [s]: forgetting exp(-dt/T)
    scale_bounds: tuple = (0.5, 2.0)     # a
    offset: bool = False                 # adapt the offset b too (else the scale a alone)
    offset_bound: float = 0.5            # |b| <= offset_bound x S
    freeze: float = 0.5                  # no update while |r| > freeze x threshold
    holdoff: float = 1.0                 # [s] nor within this time after a contact flag
    initial_covariance: float = 1.0      # P(0) = this x identity (a and b / S)


@dataclasses.dataclass
class Thresholds:
    """Per-joint contact thresholds [Nm] and friction scales S [Nm], how they were calibrated."""

    joints: list                          # joint names, in the order of the arrays
    threshold: np.ndarray                 # (J,) of |tau_ext_pred|
    static_friction: np.ndarray           # (J,) F_s: the band of friction at rest
    friction_scale: np.ndarray            # (J,)
    share: np.ndarray | None = None       # (J,) in motion the threshold grows by share x |filtered tau_f_pred|
    persistence: int = 1                  # samples beyond the threshold, of one sign, before a flag
    gain: float = DEFAULT_GAIN
    quantile: float = DEFAULT_QUANTILE
    margin: float = DEFAULT_MARGIN
    release: float = DEFAULT_RELEASE
    moving_speed: float = DEFAULT_MOVING_SPEED
    form: str = "per-joint"               # "per-joint" or "urdf": the observer form calibrated on
    logs: list = dataclasses.field(default_factory=list)

    def as_json(self) -> dict:
        return {"format": THRESHOLDS_FORMAT, "version": THRESHOLDS_VERSION, "gain": self.gain,
                "quantile": self.quantile, "margin": self.margin, "release": self.release, "moving_speed": self.moving_speed,
                "form": self.form, "logs": self.logs, "persistence": int(self.persistence),
                "joints": {str(j): {"threshold": float(self.threshold[i]),
                                    "share": float(self.shares[i]),
                                    "static_friction": float(self.static_friction[i]),
                                    "friction_scale": float(self.friction_scale[i])}
                           for i, j in enumerate(self.joints)}}

    @classmethod
    def from_json(cls, data: dict, name: str) -> "Thresholds":
        try:
            if data.get("format") != THRESHOLDS_FORMAT:
                raise KeyError("format")
            if data.get("version", 1) != THRESHOLDS_VERSION:
                raise LogError(f"{name}: a thresholds file of version {data.get('version')!r}; this fricli reads "
                               f"version {THRESHOLDS_VERSION} (calibrate again with fricli thresholds)")
            if not isinstance(data["joints"], dict) or not data["joints"]:
                raise TypeError("joints")
            joints = list(data["joints"])
            thr = np.array([float(data["joints"][j]["threshold"]) for j in joints])
            rest = np.array([float(data["joints"][j]["static_friction"]) for j in joints])
            scale = np.array([float(data["joints"][j]["friction_scale"]) for j in joints])
            share = np.array([float(data["joints"][j].get("share", 0.0)) for j in joints])
            persistence = data.get("persistence", 1)
            if not is_count(persistence, 1) or persistence > MAX_PERSISTENCE:
                raise ValueError("persistence")
            if data["form"] not in FORMS:
                raise ValueError("form")
            out = cls(joints, thr, rest, scale, share=share, persistence=persistence,
                      gain=float(data["gain"]), quantile=float(data["quantile"]),
                      margin=float(data["margin"]), release=float(data["release"]),
                      moving_speed=float(data["moving_speed"]), form=str(data["form"]),
                      logs=list(data.get("logs", [])))
        except (KeyError, TypeError, ValueError, AttributeError):
            raise LogError(f"{name}: not a thresholds file of fricli thresholds") from None
        if not (all(np.all(np.isfinite(x)) and np.all(x > 0) for x in (thr, rest, scale))
                and np.all(np.isfinite(share)) and np.all(share >= 0)
                and 0 < out.release < 1 and out.gain > 0 and out.moving_speed >= 0):
            raise LogError(f"{name}: thresholds and friction scales must be positive numbers, shares at least 0, "
                           "release in (0, 1)")
        return out

    @classmethod
    def read(cls, path: str) -> "Thresholds":
        try:
            with open(path, encoding="utf-8") as fh:
                data = json.load(fh)
        except FileNotFoundError:
            raise LogError(f"{path}: no such file") from None
        except (OSError, UnicodeDecodeError, ValueError) as exc:
            raise LogError(f"{path}: cannot read a thresholds file ({str(exc).splitlines()[0]})") from None
        if not isinstance(data, dict):
            raise LogError(f"{path}: not a thresholds file of fricli thresholds")
        return cls.from_json(data, path)

    def for_joints(self, joints: list, name: str) -> "Thresholds":
        """The thresholds of ``joints`` (names as text), in that order."""
        names = [str(j) for j in self.joints]
        missing = [str(j) for j in joints if str(j) not in names]
        if missing:
            raise LogError(f"{name}: no threshold for joint {missing[0]} (it has joints {', '.join(names)})")
        idx = [names.index(str(j)) for j in joints]
        return dataclasses.replace(self, joints=list(joints), threshold=self.threshold[idx], share=self.shares[idx],
                                   static_friction=self.static_friction[idx], friction_scale=self.friction_scale[idx])

    @property
    def shares(self) -> np.ndarray:
        """(J,) the share of |tau_f_pred| added to the threshold in motion (0 where not calibrated)."""
        return np.zeros(len(self.threshold)) if self.share is None else np.asarray(self.share, dtype=float)


class Observer:
    """The state of one arm's observer, adaptation and detection over J joints (module docstring).
    ``step`` takes one sample; the arrays are (J,). The joints do not interact: each is stepped in
    plain floats (at a handful of joints numpy's cost per call would outweigh the arithmetic)."""

    def __init__(self, joints: int, gain: float = DEFAULT_GAIN, thresholds: Thresholds | None = None,
                 adaptation: Adaptation | None = None):
        if adaptation is not None and thresholds is None:
            raise DataError("adaptation needs the contact thresholds (and friction scales) of fricli thresholds: "
                            "it must not learn a push as friction")
        self.n, self.gain, self.thresholds, self.adaptation = joints, float(gain), thresholds, adaptation
        self.started = False
        self.t = 0.0
        self.t_adapt = None
        self._suspected = [-math.inf] * joints     # time of the last row flagged
        self._p = [0.0] * joints
        self._y = [0.0] * joints
        self._f = [0.0] * joints
        self._a = [1.0] * joints
        self._b = [0.0] * joints            # the offset divided by S
        p0 = float(adaptation.initial_covariance) if adaptation is not None else 1.0
        self._P = [[p0, 0.0, p0] for _ in range(joints)]   # P11, P12, P22 per joint
        self.p_max = (2.0 if adaptation is not None and adaptation.offset else 1.0) * p0
        self._contact = [False] * joints
        self._run = [0] * joints            # samples in a row beyond the threshold, with the sign of _side
        self._side = [0] * joints
        self._limit = [math.inf] * joints   # the threshold of the last sample
        if thresholds is not None:
            threshold, band = thresholds.threshold, thresholds.static_friction
            share, self.persistence = thresholds.shares, int(thresholds.persistence)
            scale, self.release, self.moving_speed = (thresholds.friction_scale, float(thresholds.release),
                                                      float(thresholds.moving_speed))
        else:
            threshold, band = np.full(joints, np.inf), None
            share, self.persistence = np.zeros(joints), 1
            scale, self.release, self.moving_speed = np.ones(joints), DEFAULT_RELEASE, DEFAULT_MOVING_SPEED
        self._threshold = [float(x) for x in threshold]
        self._share = [float(x) for x in share]
        self._band = None if band is None else [float(x) for x in band]
        self._scale = [float(x) for x in scale]
        if adaptation is not None:
            self.lo, self.hi = float(adaptation.scale_bounds[0]), float(adaptation.scale_bounds[1])
            self.b_bound = float(adaptation.offset_bound)

    def step(self, t: float, f0: np.ndarray, tau_m: np.ndarray, p: np.ndarray, w: np.ndarray,
             qd: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """One sample: (tau_f_pred, tau_ext_pred, contact) for time ``t`` [s], the friction model's
        output ``f0``, motor torque, momentum p (0 in the per-joint form), w = g - C^T qd (tau_g +
        tau_dyn in the per-joint form) and velocity."""
        f0, tau_m, p, w, qd = f0.tolist(), tau_m.tolist(), p.tolist(), w.tolist(), qd.tolist()
        k = self.gain
        first = not self.started
        if first:
            self.started = True
        else:
            dt = t - self.t
            if not dt > 0.0:
                raise DataError(f"'t' is not increasing (t = {t:g} s)")
            kd = k * dt
        self.t = t
        ad = self.adaptation
        if ad is not None:
            lam = None
            if self.t_adapt is not None:        # the first sample: no interval to forget over yet
                lam = max(math.exp(-(t - self.t_adapt) / ad.time_constant), FORGET_MIN)
            self.t_adapt = t
        tau_f, res = [0.0] * self.n, [0.0] * self.n
        for j in range(self.n):
            offset = self._b[j] * self._scale[j]
            tau_f[j] = self._a[j] * f0[j] + offset
            if first:
                self._f[j] = f0[j]
                self._y[j] = tau_f[j]        # r = 0: the observer starts at rest with the arm (p(0))
            else:
                self._y[j] = (self._y[j] - k * (p[j] - self._p[j]) + kd * (tau_m[j] - w[j])) / (1.0 + kd)
                self._f[j] = (self._f[j] + kd * f0[j]) / (1.0 + kd)
            self._p[j] = p[j]
            level = self._a[j] * self._f[j] + offset
            r = level - self._y[j]
            moves = abs(qd[j]) > self.moving_speed
            threshold = self._threshold[j]
            if moves:
                threshold += self._share[j] * abs(level)
            elif self._band is not None:     # the static band at the adapted level: a [-F_s, F_s] + offset
                band, y = self._a[j] * self._band[j], self._y[j]
                r = min(max(y, offset - band), offset + band) - y
            mag = abs(r)
            side = 1 if r > threshold else (-1 if r < -threshold else 0)
            self._run[j] = 0 if side == 0 else (self._run[j] + 1 if side == self._side[j] else 1)
            self._side[j] = side
            self._limit[j] = threshold
            self._contact[j] = mag >= self.release * threshold if self._contact[j] else self._run[j] >= self.persistence
            res[j] = r
            if ad is not None and lam is not None:
                self._adapt(j, t, lam, r, mag, moves, threshold)
        return np.array(tau_f), np.array(res), np.array(self._contact)

    def _adapt(self, j: int, t: float, lam: float, r: float, mag: float, moves: bool, threshold: float) -> None:
        """One recursive least-squares step of joint ``j``'s scale (and offset), forgetting ``lam``."""
        ad = self.adaptation
        if self._contact[j]:
            self._suspected[j] = t
        if not (moves and mag <= ad.freeze * threshold and t - self._suspected[j] >= ad.holdoff):
            return
        scale = self._scale[j]
        x1 = self._f[j] / scale                        # regressor (f / S, x2), target y / S
        x2 = 1.0 if ad.offset else 0.0                 # without the offset: scalar least squares on a
        e = -r / scale                                 # a-priori error y/S - (a f/S + b)
        P11, P12, P22 = self._P[j]
        g1 = P11 * x1 + P12 * x2
        g2 = P12 * x1 + P22 * x2
        den = lam + x1 * g1 + x2 * g2
        k1, k2 = g1 / den, g2 / den
        self._a[j] = min(max(self._a[j] + k1 * e, self.lo), self.hi)
        self._b[j] = min(max(self._b[j] + k2 * e, -self.b_bound), self.b_bound)
        n11 = (P11 - k1 * g1) / lam
        n12 = (P12 - k1 * g2) / lam
        n22 = (P22 - k2 * g2) / lam if ad.offset else P22
        tr = n11 + n22 * x2
        cap = self.p_max / tr if tr > self.p_max else 1.0
        self._P[j] = [n11 * cap, n12 * cap, n22 * cap]

    @property
    def threshold(self) -> np.ndarray:
        """The threshold each joint's last sample was compared with [Nm] (inf before the first)."""
        return np.array(self._limit)

    @property
    def a(self) -> np.ndarray:
        """The adapted scale a per joint."""
        return np.array(self._a)

    @property
    def offset(self) -> np.ndarray:
        """The adapted offset b [Nm] per joint."""
        return np.array([b * s for b, s in zip(self._b, self._scale)])


@dataclasses.dataclass
class Replayed:
    """Per row and joint (n, J): tau_f_pred, tau_ext_pred, contact, the adapted scale and offset, the
    threshold the row was compared with."""

    tau_f: np.ndarray
    tau_ext: np.ndarray
    contact: np.ndarray
    scale: np.ndarray
    offset: np.ndarray
    threshold: np.ndarray


def replay(t: np.ndarray, f0: np.ndarray, tau_m: np.ndarray, p: np.ndarray, w: np.ndarray, qd: np.ndarray,
           gain: float = DEFAULT_GAIN, thresholds: Thresholds | None = None,
           adaptation: Adaptation | None = None) -> Replayed:
    """``Observer.step`` over every row, in order: t (n,), the others (n, J)."""
    n, joints = f0.shape
    obs = Observer(joints, gain, thresholds, adaptation)
    out = Replayed(np.empty((n, joints)), np.empty((n, joints)), np.zeros((n, joints), dtype=bool),
                   np.empty((n, joints)), np.empty((n, joints)), np.empty((n, joints)))
    for i in range(n):
        out.scale[i], out.offset[i] = obs.a, obs.offset   # the level row i's friction uses
        out.tau_f[i], out.tau_ext[i], out.contact[i] = obs.step(float(t[i]), f0[i], tau_m[i], p[i], w[i], qd[i])
        out.threshold[i] = obs.threshold
    return out


def default_gain(step: float) -> float:
    """The observer gain [1/s] ``fricli thresholds`` calibrates with on logs sampled every ``step``
    seconds: FAST_GAIN (a 10 ms time constant: a contact of twice the threshold flagged within 20
    ms) where K dt stays at most 0.5 at it, else DEFAULT_GAIN. The backward-Euler residual takes
    K dt / (1 + K dt) of each new sample: with K dt at most 0.5, one wrong sample of the measured
    torque or velocity moves it by at most a third of its error."""
    return FAST_GAIN if step <= FAST_STEP * (1 + 1e-9) else DEFAULT_GAIN


def static_band(friction: list[np.ndarray], speeds: list[np.ndarray], moving_speed: float,
                joints: list) -> np.ndarray:
    """F_s per joint: the largest |friction| (n, J) the model gives on the rows where the joint moves
    just above ``moving_speed`` (up to 5 times it): the friction a joint breaks away from rest with."""
    f = np.abs(np.concatenate(friction))
    v = np.abs(np.concatenate(speeds))
    out = np.zeros(f.shape[1])
    for j in range(f.shape[1]):
        slow = (v[:, j] > moving_speed) & (v[:, j] <= 5 * moving_speed)
        if not slow.any():
            raise DataError(f"joint {joints[j]}: the calibration logs have no rows moving between {moving_speed:g} "
                            f"and {5 * moving_speed:g} (the static friction band is calibrated there)")
        out[j] = float(np.max(f[slow, j]))
    return out


def calibrate(residuals: list[np.ndarray], friction: list[np.ndarray], speeds: list[np.ndarray], joints: list,
              gain: float, form: str, band: np.ndarray, quantile: float = DEFAULT_QUANTILE,
              margin: float = DEFAULT_MARGIN, release: float = DEFAULT_RELEASE,
              moving_speed: float = DEFAULT_MOVING_SPEED, logs: list | None = None) -> Thresholds:
    """Thresholds from the residuals (n, J) of the static observer with the static band ``band``
    (``static_band``) on collision-free logs: per joint ``margin`` x the ``quantile`` of
    |tau_ext_pred| over every row; the friction scale S: the RMS of the model's friction (n, J) over
    the rows where |qd| (``speeds``) is above ``moving_speed``."""
    check_settings(quantile, margin, release, moving_speed)
    r = np.abs(np.concatenate(residuals))
    f = np.concatenate(friction)
    mv = np.abs(np.concatenate(speeds)) > moving_speed
    thr, scale = np.zeros(r.shape[1]), np.zeros(r.shape[1])
    for j in range(r.shape[1]):
        thr[j] = margin * np.quantile(r[:, j], quantile)
        scale[j] = math.sqrt(float(np.mean(np.square(f[mv[:, j], j])))) if mv[:, j].any() else 0.0
        if not (thr[j] > 0 and scale[j] > 0):
            raise DataError(f"joint {joints[j]}: the calibration logs give no residual or no friction in motion to "
                            "calibrate on")
    return Thresholds(list(joints), thr, np.asarray(band, dtype=float), scale, gain=gain, quantile=quantile,
                      margin=margin, release=release, moving_speed=moving_speed, form=form, logs=logs or [])


def level_share(scales: list[np.ndarray], speeds: list[np.ndarray], thresholds: Thresholds) -> Thresholds:
    """``thresholds`` with each joint's share: ``margin`` x the ``quantile`` of |a - 1| over the rows
    in motion, a (n, J) the friction scale the online adaptation (``Adaptation()``) found on the
    collision-free calibration logs (``scales``, their |qd| ``speeds``). The friction level drifts
    within a run (temperature, lubricant) by about that much; on another day by more; either way
    the model's error from a level change is proportional to the friction itself."""
    a = np.concatenate(scales)
    mv = np.abs(np.concatenate(speeds)) > thresholds.moving_speed
    share = np.array([thresholds.margin * float(np.quantile(np.abs(a[mv[:, j], j] - 1.0), thresholds.quantile))
                      if mv[:, j].any() else 0.0 for j in range(a.shape[1])])
    return dataclasses.replace(thresholds, share=share)


def check_settings(quantile: float, margin: float, release: float, moving_speed: float) -> None:
    if not (0 < quantile <= 1) or not margin > 0 or not (0 < release < 1) or not moving_speed > 0:
        raise DataError("quantile in (0, 1], margin above 0, release in (0, 1) and a moving speed above 0 are needed")


@dataclasses.dataclass
class Event:
    """One contact: the joint, the times it was flagged and released [s], the peak residual [Nm]
    (signed) and its time."""

    joint: object
    start: float
    end: float | None
    peak: float
    peak_time: float


def events(t: np.ndarray, contact: np.ndarray, tau_ext: np.ndarray, joints: list) -> list[Event]:
    """The contacts of a replay: one per run of flagged rows of a joint, in time order."""
    out = []
    for j, name in enumerate(joints):
        for s, e in metrics.true_runs(contact[:, j] != 0):
            seg = tau_ext[s:e, j]
            i = int(np.argmax(np.abs(seg)))
            out.append(Event(name, float(t[s]), float(t[e]) if e < len(t) else None, float(seg[i]),
                             float(t[s + i])))
    return sorted(out, key=lambda ev: (ev.start, str(ev.joint)))
