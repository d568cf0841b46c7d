"""Effects the simulator adds on request, undeclared to any model.

Each effect changes the ``Scene`` (the per-sample quantities the friction and the logged
columns are computed from) before the friction is computed. Its strength has a physical unit
and a documented default (per joint where it scales with the joint); see docs/simulator.md.

Friction, in the terms of a ``Scene`` (s = sign(v), tau_gear = tau_g - tau_ext, tau_l = |tau_gear|):

    Fc_eff = (fc*dir_c + kc*tau_l) * thermal * coulomb + shift + kq*tau_gear*s + k_abs*tau_l
    Fs_eff = (fs*dir_c + ks*tau_l) * thermal * coulomb + shift + kq*tau_gear*s + k_abs*tau_l
    viscous = fv*dir_v * exp(-alpha_v*(T - t_ref)) * viscous_scale * shape(v)
    tau_f  = LuGre(Fc_eff, Fs_eff) + viscous + extra,   thermal = 1 - alpha_c*(T - t_ref)

Effects that are not friction change what is logged instead: the robot model's gravity torque
(``gravity_logged`` times the true one) or a disturbance torque in tau_m (``tau_m_extra``).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from fricli.core import effectnames as N
from fricli.sim.joints import Joint

RIPPLE_PERIOD = 0.2137     # spatial period of the ripple [rad]
RIPPLE_SECOND = 0.35       # amplitude of the second harmonic, relative to the first
VELOCITY_REF = 0.3         # velocity where the changed viscous curve meets the linear one [rad/s]
HUMIDITY_REF = 45.0        # [%]
HUMIDITY_SWING = 12.0      # [%]
DISTURBANCE_HZ = 2.5       # frequency of the disturbance torque [Hz]
WARM_START = 20.0          # temperature at the start of a log with the temperature effect [degC]
GEAR_TEMPERATURES = (-40.0, 120.0)   # a gear's lubricant works between these [degC]


@dataclasses.dataclass
class Scene:
    """Per-sample quantities (n,) at the internal rate, changed in place by the effects."""

    joint: Joint
    t: np.ndarray
    q: np.ndarray
    v: np.ndarray
    qdd: np.ndarray
    phi: np.ndarray            # gravity phase from the other joints' motion [rad]
    tau_g: np.ndarray          # true gravity torque [Nm]
    tau_ext: np.ndarray        # true external torque [Nm]
    temp: np.ndarray           # [degC]
    loaded: bool               # an external load is present (the sensor column is not all zero)
    kq: float                  # magnitude slope in tau_gear*sign(v) [Nm/Nm]
    shift_pos: float           # Coulomb shift for v > 0 [Nm]
    shift_neg: float           # Coulomb shift for v < 0 [Nm]
    k_abs: float = 0.0         # extra magnitude slope in |tau_gear| [Nm/Nm]
    visc_exponent: float = 1.0
    tau_m_bias: float = 0.0    # constant bias on the measured motor torque [Nm]
    inertia_logged: float | None = None   # inertia the logged tau_dyn uses [kg m^2]
    gravity_logged: float = 1.0           # logged tau_g = gravity_logged * the true tau_g
    columns: dict = dataclasses.field(default_factory=dict)   # name -> (values (n,), unit)

    def __post_init__(self):
        n = len(self.t)
        self.dir_c = np.ones(n)      # multiplies fc, fs (direction asymmetry)
        self.dir_v = np.ones(n)      # multiplies fv (direction asymmetry)
        self.coulomb = np.ones(n)    # multiplies the whole Coulomb/static level
        self.viscous = np.ones(n)    # multiplies the viscous term
        self.extra = np.zeros(n)     # additive torque, part of the friction [Nm]
        self.tau_m_extra = np.zeros(n)   # disturbance torque in tau_m, not friction [Nm]
        if self.inertia_logged is None:
            self.inertia_logged = self.joint.inertia

    @property
    def duration(self) -> float:
        return float(self.t[-1] - self.t[0]) if len(self.t) > 1 else 0.0

    @property
    def sign(self) -> np.ndarray:
        return np.sign(self.v)


class Effect:
    name = ""
    unit = ""              # unit of the strength
    help = ""              # one line: what the strength means

    def default(self, j: Joint) -> float:
        raise NotImplementedError

    def check(self, strength: float) -> None:
        """Raise ValueError for a strength that makes no physical sense."""

    def apply(self, scene: Scene, strength: float, rng: np.random.Generator) -> dict:
        """Change ``scene``; return the effect's parameters for the log's metadata."""
        raise NotImplementedError


RIPPLE_PHASES = {2: (0.7, 2.1), 4: (1.9, 0.4)}  # [rad] of the fundamental and second harmonic


class Position(Effect):
    name, unit = N.POSITION, "Nm"
    help = "position-periodic torque (gear ripple) of this amplitude, with a second harmonic"

    def default(self, j):
        return 1.0 if j.number == 2 else 0.6

    def apply(self, scene, strength, rng):
        ph = RIPPLE_PHASES[scene.joint.number]  # a gear's ripple is tied to its position, not to a run
        w = 2 * np.pi / RIPPLE_PERIOD
        scene.extra += strength * (np.sin(w * scene.q + ph[0]) + RIPPLE_SECOND * np.sin(2 * w * scene.q + ph[1]))
        return {"amplitude": strength, "period": RIPPLE_PERIOD, "second_harmonic": RIPPLE_SECOND,
                "phases": [float(x) for x in ph]}


class Direction(Effect):
    name, unit = N.DIRECTION, "-"
    help = "Coulomb, static and viscous friction scaled by 1+r for v > 0 and 1-r for v < 0"

    def default(self, j):
        return 0.2

    def check(self, strength):
        if not -1 < strength < 1:
            raise ValueError("the direction asymmetry must be between -1 and 1")

    def apply(self, scene, strength, rng):
        factor = 1.0 + strength * scene.sign
        scene.dir_c *= factor
        scene.dir_v *= factor
        j = scene.joint
        return {"r": strength, "fc_pos": j.fc * (1 + strength), "fc_neg": j.fc * (1 - strength),
                "fs_pos": j.fs * (1 + strength), "fs_neg": j.fs * (1 - strength),
                "fv_pos": j.fv * (1 + strength), "fv_neg": j.fv * (1 - strength)}


class Drift(Effect):
    name, unit = N.DRIFT, "-"
    help = "wear: Coulomb/static and viscous levels grow linearly by this fraction over the log"

    def default(self, j):
        return 0.3

    def check(self, strength):
        if strength <= -1:
            raise ValueError("drift must be above -1")

    def apply(self, scene, strength, rng):
        growth = 1.0 + strength * (scene.t - scene.t[0]) / max(scene.duration, 1e-9)
        scene.coulomb *= growth
        scene.viscous *= growth
        return {"growth": strength, "per_second": strength / max(scene.duration, 1e-9)}


class Temperature(Effect):
    name, unit = N.TEMPERATURE, "K"
    help = f"the joint warms from {WARM_START:g} degC by this much over the log (first-order warming)"

    def default(self, j):
        return 25.0

    def check(self, strength):
        end = WARM_START + strength
        if not GEAR_TEMPERATURES[0] <= end <= GEAR_TEMPERATURES[1]:
            raise ValueError(f"the joint would end at {end:g} degC; a gear runs between "
                             f"{GEAR_TEMPERATURES[0]:g} and {GEAR_TEMPERATURES[1]:g} degC (the rise is from "
                             f"{WARM_START:g} degC)")

    def apply(self, scene, strength, rng):
        tau = max(scene.duration, 1e-9) / 2.0
        rise = (1.0 - np.exp(-(scene.t - scene.t[0]) / tau)) / (1.0 - math.exp(-2.0))
        scene.temp = WARM_START + strength * rise
        j = scene.joint
        return {"start": WARM_START, "end": WARM_START + strength, "time_constant": tau,
                "t_ref": j.t_ref, "alpha_c": j.alpha_c, "alpha_v": j.alpha_v}


class Acceleration(Effect):
    name, unit = N.ACCELERATION, "-"
    help = "the logged tau_dyn uses J*(1-f) instead of the true inertia J"

    def default(self, j):
        return 0.5

    def check(self, strength):
        if strength >= 1:
            raise ValueError("inertia must be below 1 (the logged inertia must stay positive)")

    def apply(self, scene, strength, rng):
        j = scene.joint
        scene.inertia_logged = j.inertia * (1.0 - strength)
        return {"inertia_true": j.inertia, "inertia_logged": scene.inertia_logged,
                "missing": j.inertia * strength}


class Offset(Effect):
    name, unit = N.OFFSET, "Nm"
    help = "a constant bias on the measured motor torque tau_m"

    def default(self, j):
        return 1.0 if j.number == 2 else 0.6

    def apply(self, scene, strength, rng):
        scene.tau_m_bias += strength
        return {"offset": strength}


class Level(Effect):
    name, unit = N.LEVEL, "-"
    help = "Coulomb/static and viscous friction scaled as a whole by this factor"

    def default(self, j):
        return 1.25

    def check(self, strength):
        if strength <= 0:
            raise ValueError("level must be positive")

    def apply(self, scene, strength, rng):
        scene.coulomb *= strength
        scene.viscous *= strength
        return {"factor": strength}


class Load(Effect):
    name, unit = N.LOAD, "Nm/Nm"
    help = "Coulomb/static levels gain k*|tau_gear| (the gear's normal force grows with the load)"

    def default(self, j):
        return 0.05 if j.number == 2 else 0.08

    def apply(self, scene, strength, rng):
        scene.k_abs += strength
        return {"kl": strength}


class Quadrant(Effect):
    name, unit = N.QUADRANT, "Nm/Nm"
    help = ("quadrant dependence: Coulomb/static levels gain k*tau_gear*sign(v), more friction when the "
            "joint drives against the gear torque than when it is back-driven")

    def default(self, j):
        return 0.065 if j.number == 2 else 0.1

    def apply(self, scene, strength, rng):
        scene.kq += strength
        return {"kq": strength}


class Gravity(Effect):
    name, unit = N.GRAVITY, "-"
    help = "the logged tau_g (the robot model's gravity) is this fraction too low: (1-f) times the true one"

    def default(self, j):
        return 0.07

    def check(self, strength):
        if not -1 < strength < 1:
            raise ValueError("gravity must be between -1 and 1")

    def apply(self, scene, strength, rng):
        scene.gravity_logged *= 1.0 - strength
        return {"logged_over_true": scene.gravity_logged}


class Disturbance(Effect):
    name, unit = N.DISTURBANCE, "Nm"
    help = (f"a {DISTURBANCE_HZ:g} Hz sinusoidal torque of this amplitude in tau_m (e.g. a pump or fan), "
            "not friction")

    def default(self, j):
        return 1.0 if j.number == 2 else 0.6

    def apply(self, scene, strength, rng):
        ph = rng.uniform(0, 2 * np.pi)
        scene.tau_m_extra += strength * np.sin(2 * np.pi * DISTURBANCE_HZ * (scene.t - scene.t[0]) + ph)
        return {"amplitude": strength, "frequency": DISTURBANCE_HZ, "phase": float(ph)}


class Velocity(Effect):
    name, unit = N.VELOCITY, "-"
    help = f"viscous term ~ |v|^p instead of linear (equal at {VELOCITY_REF:g} rad/s)"

    def default(self, j):
        return 0.5

    def check(self, strength):
        if strength <= 0:
            raise ValueError("velocity exponent must be positive")

    def apply(self, scene, strength, rng):
        scene.visc_exponent = strength
        return {"exponent": strength, "v_ref": VELOCITY_REF}


class Column(Effect):
    name, unit = N.COLUMN, "1/%"
    help = "an extra column 'humidity' [%]; Coulomb/static levels scale by 1 + k*(h - 45 %)"

    def default(self, j):
        return 0.015

    def check(self, strength):
        if abs(strength) * HUMIDITY_SWING >= 1:
            raise ValueError(f"|k| must be below {1 / HUMIDITY_SWING:.3g} 1/% (the humidity swings by "
                             f"{HUMIDITY_SWING:g} %; the Coulomb level must stay positive)")

    def apply(self, scene, strength, rng):
        ph = rng.uniform(0, 2 * np.pi)
        period = 0.8 * max(scene.duration, 1.0)
        h = HUMIDITY_REF + HUMIDITY_SWING * np.sin(2 * np.pi * (scene.t - scene.t[0]) / period + ph)
        scene.columns["humidity"] = (h, "%")
        scene.coulomb *= 1.0 + strength * (h - HUMIDITY_REF)
        return {"column": "humidity", "slope": strength, "reference": HUMIDITY_REF,
                "swing": HUMIDITY_SWING, "period": period, "phase": float(ph)}


class Payload(Effect):
    name, unit = N.PAYLOAD, "Nm"
    help = "an undeclared payload: tau_ext of 0..P Nm varying with the configuration (not in tau_g)"

    def default(self, j):
        return j.load_amplitude

    def apply(self, scene, strength, rng):
        ph = rng.uniform(0, 2 * np.pi)
        scene.tau_ext = scene.tau_ext + strength * (0.5 + 0.5 * np.sin(scene.q + scene.phi + ph))
        scene.loaded = True
        return {"amplitude": strength, "phase": float(ph)}


HYSTERESIS_DEFLECTIONS = (0.002, 0.006, 0.02)   # deflection limits of the Maxwell-slip elements [rad]
HYSTERESIS_SHARES = (0.5, 0.3, 0.2)              # their shares of the total break-away force


class Hysteresis(Effect):
    name, unit = N.HYSTERESIS, "Nm"
    help = ("friction with memory: Maxwell-slip elements (springs that slip at 0.002, 0.006, 0.02 rad) of "
            "this total break-away force")

    def default(self, j):
        return 0.3 * j.fc

    def check(self, strength):
        if strength < 0:
            raise ValueError("the elements' break-away force must be >= 0")

    def apply(self, scene, strength, rng):
        from fricli.models.gms import element_states

        d = np.array(HYSTERESIS_DEFLECTIONS)
        force = strength * np.array(HYSTERESIS_SHARES)
        z, _ = element_states(scene.q, scene.v, d)
        scene.extra += (z / d) @ force
        return {"deflections": list(HYSTERESIS_DEFLECTIONS), "forces": [float(f) for f in force]}


# Registry order is the order effects are applied in (and their random streams).
EFFECTS: dict[str, Effect] = {e.name: e for e in (
    Payload(), Temperature(), Column(), Position(), Direction(), Drift(), Acceleration(), Offset(), Level(),
    Load(), Velocity(), Quadrant(), Gravity(), Disturbance(), Hysteresis())}
# The effects are named as every layer names them (``fricli.core.effectnames``); the simulator's
# earlier names stay accepted.
ALIASES = N.ALIASES
Ripple, Asymmetry, Inertia = Position, Direction, Acceleration   # the classes' earlier names


def canonical(name: str) -> str:
    """An effect's name, an alias (``ALIASES``) replaced by the name it stands for."""
    return N.canonical(name.strip().lower())


def parse(spec: str) -> tuple[str, float | None]:
    """``NAME`` or ``NAME=STRENGTH`` -> (name, strength or None for the default); ``NAME`` may be
    an alias (``ALIASES``)."""
    name, sep, value = spec.partition("=")
    name = canonical(name)
    if name not in EFFECTS:
        raise ValueError(f"unknown effect {name!r} (choose from {', '.join(sorted(EFFECTS))})")
    if not sep:
        return name, None
    try:
        strength = float(value)
    except ValueError:
        raise ValueError(f"effect {name}: strength {value!r} is not a number") from None
    if not math.isfinite(strength):
        raise ValueError(f"effect {name}: strength must be finite")
    try:
        EFFECTS[name].check(strength)
    except ValueError as exc:
        raise ValueError(f"effect {name}: {exc}") from None
    return name, strength


def viscous_shape(v: np.ndarray, exponent: float) -> np.ndarray:
    """v for exponent 1; else sign(v) * v_ref * (|v|/v_ref)^exponent [rad/s]."""
    if exponent == 1.0:
        return v
    return np.sign(v) * VELOCITY_REF * (np.abs(v) / VELOCITY_REF) ** exponent
