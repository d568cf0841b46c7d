"""The simulator: a harmonic-drive joint following a scenario's motion, logged as a fricli log.

Joint dynamics (log contract: friction tau_f positive along the motion):

    tau_m = J*qdd + c + tau_g + tau_f - tau_ext + noise

with c the coupling torque from the other joints' motion (known to the robot model). The
friction is integrated at an internal rate of at least 1 kHz (an integer multiple of the
output rate) with the exact bristle update of ``fricli.numerics.physics`` and logged at the output
rate. Every random draw comes from ``numpy.random.default_rng([seed, stream])`` with one stream
per purpose (motion, configuration, noise, each effect), so adding an effect or a load leaves
the motion and the noise of the same seed unchanged.
"""

from __future__ import annotations

import json
import math

import numpy as np
from fricli.core import lazy, logs
from fricli.numerics import physics
from fricli.core.logs import table_from_arrays
from fricli.sim import effects as fx
from fricli.sim import joints, trajectories

pa = lazy.module("pyarrow")

SCENARIOS = ("base", "extended", "adapt", "daily")
LOADS = ("none", "sym", "asym")
INTERNAL_RATE_MIN = 1000.0     # [Hz]
COUPLING = 0.25                # coupling inertia to the other joints, relative to J
METADATA_KEY = b"fricli.sim"
_STREAM_PLAN, _STREAM_CONFIG, _STREAM_NOISE, _STREAM_EFFECT0 = 0, 1, 2, 10

UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm",
         "tau_dyn": "Nm", "tau_ext": "Nm", "temp": "degC", "tau_f_true": "Nm"}


def default_state(scenario: str) -> str:
    """Friction state of a scenario: ``base`` (warm) for base and daily, ``shifted`` for extended and adapt."""
    return "base" if scenario in ("base", "daily") else "shifted"


def true_params(joint: int | joints.Joint, scenario: str = "base", friction_state: str | None = None) -> dict[str, float]:
    """The true friction parameters of a scenario (names as in the LuGre model kind).

    fc, fs, vs, delta, fv, kc, ks, sigma0, sigma1 (extended LuGre, load tau_l = |tau_g - tau_ext|),
    the temperature law t_ref, alpha_c, alpha_v, and the state: temperature, kq, fc_shift_pos,
    fc_shift_neg (zero in the base state, where the friction is exactly an extended LuGre model).
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r} (choose from {', '.join(SCENARIOS)})")
    j = joint if isinstance(joint, joints.Joint) else joints.joint(joint)
    out = j.lugre()
    out.update(t_ref=j.t_ref, alpha_c=j.alpha_c, alpha_v=j.alpha_v)
    out.update(joints.state_params(j, friction_state or default_state(scenario)))
    return out


def _rng(seed: int, stream: int) -> np.random.Generator:
    return np.random.default_rng([int(seed), stream])


def _rates(rate: float) -> tuple[float, int]:
    """(internal rate [Hz], decimation factor)."""
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError("the output rate must be a positive number of Hz")
    k = max(1, math.ceil(INTERNAL_RATE_MIN / rate - 1e-9))
    return rate * k, k


def _plan(scenario, j, rng, duration, thin=False):
    if scenario == "base":
        return trajectories.base_plan(j, rng, thin=thin)
    if scenario == "adapt":
        return trajectories.adapt_plan(j, rng)
    if scenario == "daily":
        return trajectories.daily_plan(j, rng)
    return trajectories.extended_plan(j, rng, trajectories.EXTENDED_DURATION if duration is None else duration)


def _load_profile(load: str, amplitude: float, q, phi, rng) -> np.ndarray:
    """True external torque of the scenario's payload [Nm] (zero-mean ``sym``, one-sided ``asym``)."""
    phase = rng.uniform(0, 2 * np.pi)    # drawn always, so the stream does not depend on the load
    if load == "none":
        return np.zeros_like(q)
    wave = np.sin(q + phi + phase)
    return amplitude * wave if load == "sym" else amplitude * (0.5 + 0.5 * wave)


def friction(scene: fx.Scene, dt: np.ndarray) -> np.ndarray:
    """True friction tau_f (n,) [Nm] of a scene (see ``fricli.sim.effects`` for the equations)."""
    j = scene.joint
    v = scene.v
    s = scene.sign
    tau_gear = scene.tau_g - scene.tau_ext
    tau_l = np.abs(tau_gear)
    dT = scene.temp - j.t_ref
    level = (1.0 - j.alpha_c * dT) * scene.coulomb
    shift = np.where(s > 0, scene.shift_pos, np.where(s < 0, scene.shift_neg, 0.0))
    shift = shift + scene.kq * tau_gear * s + scene.k_abs * tau_l
    fc = (j.fc * scene.dir_c + j.kc * tau_l) * level + shift
    fs = (j.fs * scene.dir_c + j.ks * tau_l) * level + shift
    floor = 0.02 * j.fc              # keeps the Stribeck curve positive under extreme effects
    g = np.maximum(physics.stribeck(v, fc, fs, j.vs, j.delta), floor)
    tau, _ = physics.lugre_friction(v, g, 0.0, j.sigma0, j.sigma1, dt, z0=0.0)
    fv = j.fv * scene.dir_v * np.exp(-j.alpha_v * dT) * scene.viscous
    return tau + fv * fx.viscous_shape(v, scene.visc_exponent) + scene.extra


def resolve_effects(specs) -> list[tuple[str, float | None]]:
    """Effects as (name, strength or None) from ``NAME[=STRENGTH]`` strings or pairs; no repeats."""
    out: dict[str, float | None] = {}
    for spec in specs:
        name, strength = fx.parse(spec) if isinstance(spec, str) else (fx.canonical(spec[0]), spec[1])
        if name not in fx.EFFECTS:
            raise ValueError(f"unknown effect {name!r} (choose from {', '.join(sorted(fx.EFFECTS))})")
        if name in out:
            raise ValueError(f"effect {name} is given twice")
        if strength is not None:
            fx.EFFECTS[name].check(float(strength))
        out[name] = strength
    return list(out.items())


def simulate(scenario: str = "base", joint: int | joints.Joint = 2, *, load: str = "none", effects=(), seed: int = 0,
             rate: float = 100.0, duration: float | None = None, friction_state: str | None = None,
             thin: bool = False, contacts=()) -> pa.Table:
    """A simulated log as a pyarrow table (columns and units of the log contract).

    scenario: base | extended | adapt | daily; joint: 2 | 4 or a ``joints.Joint``; load: none | sym | asym (external payload
    measured by the sensor, not in tau_g); effects: ``NAME[=STRENGTH]`` strings (see
    ``fricli.sim.effects.EFFECTS``); rate: output rate [Hz]; duration [s]: extended only;
    friction_state: base | shifted (default: base for the base scenario, else shifted); thin:
    base only, each slow level one short stretch at a random position (see
    ``trajectories.base_plan``); contacts: (start [s], torque [Nm], duration [s]) of external torques
    of constant size added to tau_ext (the joint keeps its path: the motor torque takes the push;
    the log's reference tau_ext holds them). The same arguments give the same table.
    """
    if scenario not in SCENARIOS:
        raise ValueError(f"unknown scenario {scenario!r} (choose from {', '.join(SCENARIOS)})")
    if load not in LOADS:
        raise ValueError(f"unknown load {load!r} (choose from {', '.join(LOADS)})")
    if duration is not None and scenario != "extended":
        raise ValueError("a duration can only be given for the extended scenario")
    if thin and scenario != "base":
        raise ValueError("thin applies to the base scenario only")
    j = joint if isinstance(joint, joints.Joint) else joints.joint(joint)
    state = friction_state or default_state(scenario)
    state_p = joints.state_params(j, state)
    chosen = resolve_effects(effects)
    fs_int, k = _rates(float(rate))

    plan = _plan(scenario, j, _rng(seed, _STREAM_PLAN), duration, thin)
    n_out = int(math.floor(plan.t * rate + 1e-9)) + 1
    t = np.arange((n_out - 1) * k + 1) / fs_int
    q, qd, qdd = trajectories.evaluate(plan, t)
    rng_conf = _rng(seed, _STREAM_CONFIG)
    conf = trajectories.configuration(scenario, rng_conf)
    phi, phidd = conf.phi(t)
    tau_g = j.gravity_amplitude * np.sin(q + phi)
    tau_ext = _load_profile(load, j.load_amplitude, q, phi, rng_conf)
    pushes = contact_torque(t, contacts)
    tau_ext = tau_ext + pushes

    scene = fx.Scene(joint=j, t=t, q=q, v=qd, qdd=qdd, phi=phi, tau_g=tau_g, tau_ext=tau_ext,
                     temp=np.full_like(t, state_p["temperature"]), loaded=load != "none",
                     kq=state_p["kq"], shift_pos=state_p["fc_shift_pos"], shift_neg=state_p["fc_shift_neg"])
    applied = []
    for index, (name, effect) in enumerate(fx.EFFECTS.items()):
        strength = dict(chosen).get(name, "absent")
        if strength == "absent":
            continue
        strength = effect.default(j) if strength is None else float(strength)
        params = effect.apply(scene, strength, _rng(seed, _STREAM_EFFECT0 + index))
        applied.append({"name": name, "strength": strength, "unit": effect.unit, "params": params})

    tau_f = friction(scene, physics.intervals(t))
    coupling = COUPLING * j.inertia * phidd
    tau_dyn_true = j.inertia * qdd + coupling
    tau_dyn_logged = scene.inertia_logged * qdd + coupling

    out = slice(None, None, k)
    rng_noise = _rng(seed, _STREAM_NOISE)
    noise_m = rng_noise.normal(0.0, j.noise_sd, n_out)
    noise_ext = rng_noise.normal(0.0, j.ext_noise_sd, n_out)
    tau_m = (tau_dyn_true + scene.tau_g + tau_f - scene.tau_ext + scene.tau_m_extra)[out]
    tau_m = tau_m + noise_m + scene.tau_m_bias
    sensor = scene.tau_ext[out] + noise_ext if scene.loaded else pushes[out]

    columns = {
        "t": t[out], "joint": np.full(n_out, j.number, dtype=np.int64),
        "q": q[out], "qd": qd[out], "qdd": qdd[out],
        "tau_m": tau_m, "tau_g": scene.gravity_logged * scene.tau_g[out], "tau_dyn": tau_dyn_logged[out],
        "tau_ext": sensor,
        "temp": scene.temp[out], "tau_f_true": tau_f[out],
    }
    units = dict(UNITS)
    for name, (values, unit) in scene.columns.items():
        columns[name] = values[out]
        units[name] = unit
    table = table_from_arrays(columns, units)
    parameters = true_params(j, scenario, state)
    for name in ("inertia", "gravity_amplitude", "load_amplitude", "noise_sd", "ext_noise_sd"):
        parameters[name] = getattr(j, name)
    meta = {
        "scenario": scenario, "joint": j.number, "seed": int(seed), "load": load,
        "friction_state": state, "rate_hz": float(rate), "internal_rate_hz": fs_int,
        "duration_s": float(t[-1]), "rows": n_out, "parameters": parameters,
        "units": {name: joints.PARAM_UNITS[name] for name in parameters},
        "effects": applied, "configuration": conf.as_dict(),
    }
    if thin:
        meta["thin"] = True
    if contacts:
        meta["contacts"] = [{"start_s": float(a), "torque_nm": float(b), "duration_s": float(c)} for a, b, c in contacts]
    return table.replace_schema_metadata({METADATA_KEY: json.dumps(meta, sort_keys=True)})


def contact_torque(t: np.ndarray, contacts) -> np.ndarray:
    """The external torque [Nm] of ``contacts`` (start [s], torque [Nm], duration [s]) at times ``t``."""
    out = np.zeros_like(t)
    for start, torque, length in contacts:
        if not (math.isfinite(start) and math.isfinite(torque) and length > 0):
            raise ValueError(f"a contact needs a finite start and torque and a duration above 0, got "
                             f"{start:g}, {torque:g}, {length:g}")
        if not t[0] <= start <= t[-1]:
            raise ValueError(f"a contact at {start:g} s starts outside the simulated {t[0]:g} to {t[-1]:g} s")
        out[(t >= start) & (t < start + length)] += torque
    return out


def write(table: pa.Table, path: str) -> None:
    """Write a simulated log atomically (``-`` for stdout); see ``fricli.core.logs.write_table``."""
    logs.write_table(table, path)


def metadata(table: pa.Table) -> dict | None:
    """The ``fricli.sim`` metadata of a simulated log (None for other logs)."""
    raw = (table.schema.metadata or {}).get(METADATA_KEY)
    return json.loads(raw) if raw else None
