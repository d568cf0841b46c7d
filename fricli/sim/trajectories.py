"""Motion profiles of the simulated scenarios, built from smooth pieces.

A ``Plan`` is a list of pieces, each a raised-cosine velocity ramp from v0 to v1 over T seconds
(v0 == v1: constant velocity, v0 == v1 == 0: rest). Within a piece, with u = tau/T,

    qd  = v0 + (v1 - v0) * (1 - cos(pi u)) / 2
    q   = q0 + v0 tau + (v1 - v0) / 2 * (tau - T/pi sin(pi u))
    qdd = (v1 - v0) * pi / (2T) * sin(pi u)

so position, velocity and acceleration are exact and continuous (acceleration is zero at both
ends of each ramp). Peak acceleration of a ramp is pi |v1 - v0| / (2T).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from fricli.core.errors import DataError
from fricli.sim.joints import Joint

A_MAX = 2.0          # peak acceleration of velocity ramps [rad/s^2]
T_RAMP_MIN = 0.15    # shortest ramp [s]
V_MAX = 0.7          # highest velocity of the scenarios [rad/s]

BASE_LEVELS = (0.005, 0.01, 0.02, 0.03, 0.05, 0.07, 0.1, 0.15, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7)
BASE_STRETCH_S = 12.0     # longest constant-velocity stretch per direction and level [s]
BASE_SPLIT_BELOW = 0.1    # levels below this are split over several positions [rad/s]
BASE_SLOW_PARTS = 6       # ... this many, spread over the position range
ADAPT_VELOCITY = 0.2      # the one velocity of the adapt movement [rad/s]
DAILY_LEVELS = (0.01, 0.025, 0.05, 0.1, 0.2, 0.4, 0.7)   # velocity levels of the daily check [rad/s]
DAILY_STRETCH_S = 2.5     # constant-velocity stretch per direction and level of the daily check [s]
EXTENDED_DURATION = 120.0


@dataclasses.dataclass
class Plan:
    """Pieces as arrays: start time t0 [s], duration T [s], v0, v1 [rad/s], start position q0 [rad]."""

    t0: list = dataclasses.field(default_factory=list)
    T: list = dataclasses.field(default_factory=list)
    v0: list = dataclasses.field(default_factory=list)
    v1: list = dataclasses.field(default_factory=list)
    q0: list = dataclasses.field(default_factory=list)
    t: float = 0.0        # end of the plan so far
    q: float = 0.0        # position at the end
    v: float = 0.0        # velocity at the end

    def _piece(self, T: float, v1: float) -> None:
        if T <= 0:
            return
        self.t0.append(self.t)
        self.T.append(T)
        self.v0.append(self.v)
        self.v1.append(v1)
        self.q0.append(self.q)
        self.q += (self.v + v1) / 2.0 * T
        self.t += T
        self.v = v1

    # ------------------------------------------------------------- primitives

    def ramp(self, v1: float, a_max: float = A_MAX) -> None:
        """Smooth velocity change to v1."""
        self._piece(ramp_time(self.v, v1, a_max), v1)

    def hold(self, T: float) -> None:
        """Constant velocity (or rest) for T seconds."""
        self._piece(T, self.v)

    def hold_distance(self, d: float) -> None:
        """Constant velocity until the position has changed by d (same sign as the velocity)."""
        if self.v == 0:
            raise ValueError("hold_distance at rest")
        self.hold(max(d / self.v, 0.0))

    def stretch(self, v: float, q_end: float, a_max: float = A_MAX) -> None:
        """From rest: accelerate to v, hold, and come to rest exactly at q_end."""
        ramps = ramp_distance(0.0, v, a_max) * 2.0
        d = q_end - self.q
        if d * v <= 0 or abs(d) < ramps:
            self.move_to(q_end, abs(v), a_max)
            return
        self.ramp(v, a_max)
        self.hold_distance(d - math.copysign(ramps, d))
        self.ramp(0.0, a_max)

    def move_to(self, q_end: float, v_max: float, a_max: float = A_MAX) -> None:
        """Rest-to-rest move to q_end at up to v_max (a shorter move never reaches v_max)."""
        d = q_end - self.q
        if d == 0:
            return
        v = min(v_max, math.sqrt(4.0 * a_max * abs(d) / math.pi))
        # a ramp 0 -> v at peak acceleration a_max covers pi v^2 / (4 a_max)
        while ramp_distance(0.0, v, a_max) * 2.0 > abs(d):
            v *= 0.98
        self.stretch(math.copysign(v, d), q_end, a_max)
        self.q = q_end   # absorb rounding

    def out_and_back(self, start: float, v: float, d: float, approach: float, rest: float) -> None:
        """Move to ``start`` at up to ``approach``, then a stretch of ``d`` at ``v`` and back at -v,
        with a rest of ``rest`` seconds before, between and after."""
        self.move_to(start, approach)
        self.hold(rest)
        self.stretch(v, start + d)
        self.hold(rest)
        self.stretch(-v, start)
        self.hold(rest)

    def arrays(self) -> dict[str, np.ndarray]:
        return {k: np.asarray(getattr(self, k), dtype=np.float64) for k in ("t0", "T", "v0", "v1", "q0")}


def ramp_time(v0: float, v1: float, a_max: float = A_MAX) -> float:
    dv = abs(v1 - v0)
    if dv == 0:
        return 0.0
    return max(T_RAMP_MIN, math.pi * dv / (2.0 * a_max))


def ramp_distance(v0: float, v1: float, a_max: float = A_MAX) -> float:
    return abs(v0 + v1) / 2.0 * ramp_time(v0, v1, a_max)


def evaluate(plan: Plan, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """q [rad], qd [rad/s], qdd [rad/s^2] of the plan at times t (n,); at rest after its end."""
    p = plan.arrays()
    idx = np.clip(np.searchsorted(p["t0"], t, side="right") - 1, 0, len(p["t0"]) - 1)
    T, v0, v1, q0 = p["T"][idx], p["v0"][idx], p["v1"][idx], p["q0"][idx]
    tau = np.minimum(t - p["t0"][idx], T)
    phase = np.pi * tau / T
    dv = v1 - v0
    qd = v0 + dv * (1.0 - np.cos(phase)) / 2.0
    q = q0 + v0 * tau + dv / 2.0 * (tau - T / np.pi * np.sin(phase))
    qdd = dv * np.pi / (2.0 * T) * np.sin(phase)
    return q, qd, qdd


# ----------------------------------------------------------------- scenarios


def base_plan(j: Joint, rng: np.random.Generator, thin: bool = False) -> Plan:
    """Constant-velocity sweeps: every level of BASE_LEVELS once in each direction.

    Fast levels sweep the whole position range; slow ones a stretch of BASE_STRETCH_S seconds,
    split for levels below BASE_SPLIT_BELOW into BASE_SLOW_PARTS pieces stratified over the
    range (placed by ``rng`` within their strata), so slow data meets the whole span of gravity
    loads, as sweeps over the whole range would.

    ``thin``: every level below BASE_SPLIT_BELOW is one unsplit stretch at a random position
    instead, so each slow level meets one narrow band of gravity loads (slow sweeps kept short
    because they are expensive).
    """
    lo, hi = j.q_min, j.q_max
    full = hi - lo
    plan = Plan(q=lo)
    plan.hold(1.0)
    placed = []   # (start position, velocity, stretch length [rad])
    for v in BASE_LEVELS:
        d = v * BASE_STRETCH_S + 2 * ramp_distance(0.0, v)
        if d >= full:
            continue
        if thin and v < BASE_SPLIT_BELOW:
            placed.append((lo + 0.02 + float(rng.uniform()) * (full - 0.04 - d), v, d))
            continue
        parts = BASE_SLOW_PARTS if v < BASE_SPLIT_BELOW else 1
        # stratified over the range, so every slow level meets the whole span of gravity loads
        slots = (np.arange(parts) + rng.uniform(0.15, 0.85, parts)) / parts
        placed += [(lo + 0.02 + slot * (full - 0.04 - d / parts), v, d / parts) for slot in slots]
    placed.sort()
    for start, v, d in placed:
        plan.out_and_back(start, v, d, approach=0.3, rest=0.5)
    plan.move_to(lo, 0.5)
    plan.hold(0.5)
    for v in BASE_LEVELS:
        if v * BASE_STRETCH_S + 2 * ramp_distance(0.0, v) < full:
            continue
        plan.stretch(v, hi)
        plan.hold(0.5)
        plan.stretch(-v, lo)
        plan.hold(0.5)
    plan.hold(0.5)
    return plan


def daily_plan(j: Joint, rng: np.random.Generator) -> Plan:
    """A short daily check (about a minute): every level of DAILY_LEVELS out and back for up to
    DAILY_STRETCH_S seconds, each from a start position drawn over the range by ``rng``."""
    lo, hi = j.q_min, j.q_max
    plan = Plan(q=lo)
    plan.hold(0.5)
    for v in DAILY_LEVELS:
        d = min(v * DAILY_STRETCH_S + 2 * ramp_distance(0.0, v), hi - lo - 0.04)
        start = lo + 0.02 + float(rng.uniform(0.0, 1.0)) * (hi - lo - 0.04 - d)
        plan.out_and_back(start, v, d, approach=0.5, rest=0.3)
    plan.hold(0.5)
    return plan


def adapt_plan(j: Joint, rng: np.random.Generator) -> Plan:
    """One point-to-point movement over the whole range at ADAPT_VELOCITY, out and back."""
    plan = Plan(q=j.q_min)
    plan.hold(1.0)
    plan.stretch(ADAPT_VELOCITY, j.q_max)
    plan.hold(0.5)
    plan.stretch(-ADAPT_VELOCITY, j.q_min)
    plan.hold(1.0)
    return plan


def extended_plan(j: Joint, rng: np.random.Generator, duration: float = EXTENDED_DURATION) -> Plan:
    """Varying velocity levels (0.05..0.7 rad/s, log-uniform) held 1-4 s, with reversals
    (direct or through a short rest) and accelerations, about ``duration`` seconds long."""
    if not duration >= 10.0:
        raise DataError(f"the extended scenario needs a duration of at least 10 s (got {duration:g})")
    lo, hi = j.q_min + 0.05, j.q_max - 0.05
    plan = Plan(q=float(rng.uniform(-0.5, 0.5)))
    plan.hold(0.5)
    direction = 1.0 if rng.uniform() < 0.5 else -1.0
    while plan.t < duration - 4.0:
        speed = float(np.exp(rng.uniform(np.log(0.05), np.log(V_MAX))))
        hold = float(rng.uniform(1.0, 4.0))
        if rng.uniform() < 0.45:
            direction = -direction
        through_rest = bool(rng.uniform() < 0.4)
        dwell = float(rng.uniform(0.1, 0.6))
        choice = None
        for d in (direction, -direction):
            v = d * speed
            rest = plan.v != 0 and through_rest
            if plan.v == 0 or rest:
                q_start = plan.q + np.sign(plan.v) * ramp_distance(plan.v, 0.0)
                q_start += d * ramp_distance(0.0, v)
            else:
                q_start = plan.q + (plan.v + v) / 2.0 * ramp_time(plan.v, v)
            # room left at constant velocity, keeping enough to stop (or reverse) smoothly
            room = (hi - q_start if d > 0 else q_start - lo) - 1.5 * ramp_distance(v, 0.0) - 0.02
            if room > 0.3 * speed:
                choice = (v, rest, room)
                break
        if choice is None:           # no room either way at this speed: stop first
            plan.ramp(0.0)
            plan.hold(dwell)
            continue
        v, rest, room = choice
        direction = float(np.sign(v))
        if rest:
            plan.ramp(0.0)
            plan.hold(dwell)
        plan.ramp(v)
        plan.hold(max(0.3, min(hold, room / speed, duration - 2.0 - plan.t)))
    plan.ramp(0.0)
    plan.hold(max(0.5, duration - plan.t))
    return plan


# ---------------------------------------------------------- other joints' motion


@dataclasses.dataclass(frozen=True)
class Configuration:
    """Offset phi(t) [rad] of the gravity phase, tau_g = A sin(q + phi(t)), from the other
    joints' motion: a sum of slow sines (none for single-joint scenarios)."""

    amplitudes: tuple = ()
    periods: tuple = ()
    phases: tuple = ()
    offset: float = 0.0

    def phi(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """phi(t) [rad] and its second derivative [rad/s^2], each (n,)."""
        phi = np.full_like(t, self.offset)
        phidd = np.zeros_like(t)
        for a, p, ph in zip(self.amplitudes, self.periods, self.phases):
            w = 2.0 * np.pi / p
            s = a * np.sin(w * t + ph)
            phi += s
            phidd -= w * w * s
        return phi, phidd

    def as_dict(self) -> dict:
        return dataclasses.asdict(self)


def configuration(scenario: str, rng: np.random.Generator) -> Configuration:
    if scenario != "extended":
        return Configuration()
    return Configuration(amplitudes=(0.7, 0.4), periods=(41.0, 17.3),
                         phases=tuple(float(x) for x in rng.uniform(0, 2 * np.pi, 2)))
