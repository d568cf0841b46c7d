"""diagnose's load, payload and direction effects on a joint whose friction turns over a
pre-sliding travel after each reversal: the terms turn with the rest of the Coulomb friction, not
at the sample where qd changes sign."""

from __future__ import annotations

import numpy as np
import pytest

from fricli.core import logs
from fricli.fitting.diagnosis import diagnose
from fricli.fitting.diagnosis import effects as E
from fricli.fitting.diagnosis.torque_effects import load_travel
from fricli.models.lugre import LuGreModel

TRAVEL = 5e-4      # rad: the joint's pre-sliding travel
KC = 0.1           # Nm/Nm


def _base() -> LuGreModel:
    return LuGreModel(fc=6.0, fs=8.0, vs=0.03, delta=2.0, fv=9.0, kc=0.0, ks=0.0, sigma0=6.0 / TRAVEL, sigma1=0.0)


def _elastoplastic(q: np.ndarray, d: float) -> np.ndarray:
    """An element that follows q and slips at +-d, over d (n,): written out, not the term's code."""
    out, z = np.empty(q.size), 0.0
    for k in range(1, q.size):
        z = min(max(z + q[k] - q[k - 1], -d), d)
        out[k] = z / d
    return out


NOISE = 0.15       # Nm, the standard deviation of tau_m's noise


def _motion() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, q, qd) (n,): 30 s at 500 Hz of slow harmonic motion (reversals at a few tenths of
    rad/s^2) with four rests."""
    t = np.arange(0.0, 30.0, 0.002)
    qd = 0.35 * np.sin(2 * np.pi * 0.11 * t + 0.3) + 0.25 * np.sin(2 * np.pi * 0.27 * t + 1.0)
    for centre in (3.0, 10.0, 17.0, 24.0):
        qd *= 1 - np.exp(-(((t - centre) / 0.35) ** 8))
    return t, np.cumsum(qd) * 0.002, qd


def _log(seed: int, q_noise: float = 0.0):
    """30 s at 500 Hz of slow harmonic motion (reversals at a few tenths of rad/s^2) with four
    rests, under a varying gravity load; the friction of ``_base`` plus KC |tau_g| turning over
    TRAVEL."""
    rng = np.random.default_rng(seed)
    t, q, qd = _motion()
    tau_g = 40.0 * np.cos(q) + 15.0 * np.cos(q + 0.8 * np.sin(2 * np.pi * 0.03 * t))
    sig = {"t": t, "q": q, "qd": qd, "qdd": np.gradient(qd, t), "tau_g": tau_g}
    friction = _base().predict(sig)[0] + KC * np.abs(tau_g) * _elastoplastic(q, TRAVEL)
    cols = dict(sig, q=q + q_noise * rng.standard_normal(t.size), tau_m=tau_g + friction + NOISE * rng.standard_normal(t.size))
    units = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm"}
    return logs.from_table(logs.table_from_arrays(cols, units), name="load", zero=("tau_dyn",))


def test_a_load_that_turns_over_the_pre_sliding_travel_is_fitted_down_to_the_noise():
    """With the sign of motion, the load term is wrong for the many samples a slow reversal takes
    to cover the travel: kc came out 7 % low, the held-out MAE 4.6 times the noise's, and against
    its rival `level` it lost: `level` was named."""
    d = diagnose(_base(), _log(1))
    assert d.added[0] == "load", [(e.name, round(e.gain, 3)) for e in d.effects]
    assert d.effects[0].params["kc"]["value"] == pytest.approx(KC, rel=0.02)
    assert d.mae_after < 1.05 * NOISE * np.sqrt(2.0 / np.pi)     # what is left is the noise


def test_the_load_term_turns_with_the_sign_where_the_position_noise_at_rest_would_flip_it():
    base = _base()
    ctx = E.Context(_log(1).signals, np.zeros(1), presliding=E.presliding_travel(base, _log(1).signals))
    assert ctx.presliding == pytest.approx(TRAVEL) and load_travel(ctx) == pytest.approx(TRAVEL)
    rest = _log(1, q_noise=TRAVEL)
    qd = rest.signals["qd"].copy()
    qd[:500] = 0.0                      # a second at rest, where the noise of q moves the element
    sig = dict(rest.signals, qd=qd)
    assert load_travel(E.Context(sig, np.zeros(1), presliding=TRAVEL)) == 0.0


def _payload_log(seed: int):
    """The same motion under gravity tau_g and a payload the robot model lacks (its torque measured
    by a tau_ext sensor): the base model's friction (kc = ks = KC) at the load the gear holds,
    |tau_g + payload|, turning over TRAVEL as the bristles do."""
    rng = np.random.default_rng(seed)
    t, q, qd = _motion()
    tau_g = 40.0 * np.cos(q) + 15.0 * np.cos(q + 0.8 * np.sin(2 * np.pi * 0.03 * t))
    payload = 25.0 * np.cos(q + 0.4)
    sig = {"t": t, "q": q, "qd": qd, "qdd": np.gradient(qd, t), "tau_g": tau_g}
    friction = _loaded_base().predict(dict(sig, tau_g=tau_g + payload))[0]
    cols = dict(sig, tau_m=tau_g + payload + friction + NOISE * rng.standard_normal(t.size), tau_ext=-payload)
    units = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "tau_ext": "Nm"}
    return logs.from_table(logs.table_from_arrays(cols, units), name="payload", zero=("tau_dyn",))


def _loaded_base() -> LuGreModel:
    return LuGreModel(fc=6.0, fs=8.0, vs=0.03, delta=2.0, fv=9.0, kc=KC, ks=KC, sigma0=6.0 / TRAVEL, sigma1=0.0)


def test_a_payload_the_robot_model_lacks_turns_over_the_pre_sliding_travel_too():
    """With the sign of motion the payload term jumped at each slow reversal: `load` and `drift` were
    named instead (kc 0.079) and 0.30 Nm of MAE was left; turning over the travel it is named."""
    d = diagnose(_loaded_base(), _payload_log(1))
    assert d.added[0] == "payload", [(e.name, round(e.gain, 3)) for e in d.effects]
    assert d.effects[0].params["kc"]["value"] == pytest.approx(KC, rel=0.03)
    assert "load" not in d.added and "drift" not in d.added


R = 0.2            # the direction asymmetry: levels x (1 + R) moving forward, x (1 - R) backward


def _direction_log(seed: int):
    """The same motion; LuGre friction whose Stribeck curve and viscous slope are (1 + R sign(qd))
    times the base model's: the bristles turn over to the new direction's level over TRAVEL."""
    from fricli.numerics import physics

    rng = np.random.default_rng(seed)
    t, q, qd = _motion()
    tau_g = 40.0 * np.cos(q)
    k = 1 + R * np.sign(qd)
    g = (6.0 + 2.0 * physics.stribeck_shape(qd, 0.03, 2.0)) * k
    friction, _ = physics.lugre_friction(qd, g, 9.0 * k, 6.0 / TRAVEL, 0.0, physics.intervals(t))
    cols = {"t": t, "q": q, "qd": qd, "qdd": np.gradient(qd, t), "tau_g": tau_g,
            "tau_m": tau_g + friction + NOISE * rng.standard_normal(t.size)}
    units = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm"}
    return logs.from_table(logs.table_from_arrays(cols, units), name="direction", zero=("tau_dyn",))


def test_a_direction_asymmetry_turns_over_the_pre_sliding_travel_too():
    """The positive direction's level switched off at the sample where qd changed sign: 0.22 Nm of
    MAE was left (the noise's: 0.12), and two of the levels came out 3.5 and 6 % off; turning over the travel the
    four levels come within 2 % and the noise is what is left."""
    d = diagnose(_base(), _direction_log(1))
    assert d.added == ["direction"], [(e.name, round(e.gain, 3)) for e in d.effects]
    levels = d.effects[0].params
    for name, true in (("Fc+", 6.0 * (1 + R)), ("Fc-", 6.0 * (1 - R)), ("Fv+", 9.0 * (1 + R)), ("Fv-", 9.0 * (1 - R))):
        assert levels[name]["value"] == pytest.approx(true, rel=0.02), (name, levels[name]["value"])
    assert d.mae_after < 1.1 * NOISE * np.sqrt(2.0 / np.pi)
