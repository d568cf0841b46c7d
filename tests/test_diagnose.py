"""fricli diagnose: terms, held-out scoring, the effect library, the augmented model, the CLI,
and the acceptance on simulated logs with an undeclared effect."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pytest
from click.testing import CliRunner

from fricli import models
from fricli.core import logs, metrics
from fricli.cli import cli
from fricli.fitting.diagnosis import diagnose
from fricli.fitting.diagnosis import effects as E
from fricli.fitting.diagnosis import driver, selection, structure
from fricli.cli.diagnose import table
from fricli.models import terms as T
from fricli.fitting.diagnosis.fix import augment
from fricli.core.errors import ModelFileError
from fricli.models.augmented import AugmentedModel
from fricli.models.base import FrictionModel

# --------------------------------------------------------------------------- helpers


class CoulombViscous(FrictionModel):
    """A stateless test model: tau_f = fc*sign(qd) + fv*qd."""

    kind = "test-coulomb-viscous"

    def __init__(self, fc=5.0, fv=10.0):
        self.fc, self.fv = fc, fv

    def predict(self, signals, state=None):
        v = signals["qd"]
        return self.fc * np.sign(v) + self.fv * v, None

    def required_inputs(self):
        return {"qd"}


def synthetic(rng, n=6000, friction=None, noise=0.2, **extra):
    """A log with piecewise-constant velocity levels (rests included) over t [s] at 100 Hz;
    ``friction(sig)`` gives the true friction (default: the test model's)."""
    t = np.arange(n) / 100.0
    levels = rng.choice([-1.0, 1.0], n // 200 + 1) * rng.uniform(0.02, 0.7, n // 200 + 1)
    levels[::7] = 0.0
    v = np.convolve(np.repeat(levels, 200)[:n], np.ones(15) / 15, mode="same")
    q = np.cumsum(v) / 100.0
    qdd = np.gradient(v, t)
    tau_g = 20.0 * np.sin(q + 0.2 * np.sin(0.1 * t))
    sig = {"t": t, "q": q, "qd": v, "qdd": qdd, "tau_g": tau_g, **extra}
    f = (friction or (lambda s: CoulombViscous().predict(s)[0]))(sig)
    cols = dict(sig, tau_m=tau_g + f + noise * rng.standard_normal(n))
    units = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "temp": "degC"}
    return logs.from_table(logs.table_from_arrays(cols, units), name="synthetic", zero=("tau_dyn",))   # no inertia in tau_m


# --------------------------------------------------------------------------- terms


def test_held_sign_holds_the_last_direction_through_rest():
    qd = np.array([0.0, 0.0, 0.5, 0.0, 0.0, -0.2, 0.0, 0.3])
    assert T.held_sign(qd).tolist() == [0, 0, 1, 1, 1, -1, -1, 1]
    assert T.held_sign(qd, -1.0)[:2].tolist() == [-1, -1]


@pytest.mark.parametrize("rests", [0, 1, 40])
def test_columns_hold_what_the_functions_hold_and_combine_as_the_matrix(rests):
    rng = np.random.default_rng(rests)
    n = 200
    qd = rng.normal(size=n)
    qd[rng.choice(n, rests, replace=False)] = 0.0
    if rests:
        qd[:3] = 0.0                        # and before the first motion
    sig = {"t": np.arange(float(n)), "qd": qd, "tau_g": rng.normal(size=n), "tau_m": rng.normal(size=n),
           "tau_dyn": rng.normal(size=n)}
    p = rng.normal(size=n)
    cols = T.Columns(sig, p, (-1.0, 2.5))
    np.testing.assert_array_equal(cols.direction, T.held_sign(qd, -1.0))
    np.testing.assert_array_equal(cols.held_gravity, T.held(sig["tau_g"], qd, 2.5))
    terms = [T.term("a", T.HELDGRAVITY), T.term("b", T.OVERLOAD, T.SIGN), T.term("c", T.P, T.POS)]
    coef = np.array([0.3, -1.2, 0.7])
    np.testing.assert_allclose(T.Columns(sig, p).combination(terms, coef), T.matrix(terms, sig, p) @ coef,
                               rtol=1e-14, atol=1e-14)


def test_term_values_and_inputs():
    sig = {"t": np.arange(4.0), "qd": np.array([1.0, 0.0, -2.0, 0.0]), "temp": np.array([20.0, 21, 22, 23]),
           "tau_g": np.array([3.0, -1, 2, 0]), "tau_m": np.array([7.0, 3, -4, -5]), "tau_dyn": np.array([0.0, 0, 1, 0]),
           "tau_ext": np.array([1.0, 0, 0, 0])}
    p = np.array([5.0, 4, -6, -5])
    cols = T.Columns(sig, p)
    assert cols.value(T.term("x", T.P, T.POS)).tolist() == [5, 4, 0, 0]
    assert cols.value(T.term("x", T.sig_("qd"), T.dev("temp", 21.0))).tolist() == [-1, 0, -2, 0]
    # the load the gear holds, tau_l = tau_m - tau_dyn - p = [2, -1, 1, 0]; tau_ext is not read
    assert cols.value(T.term("x", T.OVERLOAD, T.SIGN)).tolist() == [-1, -0.0, 1, 0]
    assert cols.value(T.term("x", T.abs_("tau_g"), T.SIGN)).tolist() == [3, 1, -2, 0]
    assert cols.value(T.term("x", T.HELDGRAVITY)).tolist() == [3, 3, 2, 2]      # held through rests
    assert T.inputs([T.term("x", T.P, T.dev("temp", 0)), T.term("y", T.OVERLOAD)]) == {"temp", "tau_m", "tau_dyn",
                                                                                      "tau_g"}
    with pytest.raises(ModelFileError, match="reads the reference column tau_ext.*diagnose"):
        T.check({"name": "tau_l held", "factors": [{"f": "heldgear"}]})
    with pytest.raises(ModelFileError, match="reference column 'tau_f_true'"):
        T.check({"name": "x", "factors": [{"f": "signal", "name": "tau_f_true"}]})
    with pytest.raises(ValueError):
        T.check({"name": "bad", "factors": [{"f": "nonsense"}]})
    with pytest.raises(ValueError):
        T.check({"name": "bad", "factors": [{"f": "dev", "name": "temp"}]})


# --------------------------------------------------------------------------- selection


def test_blocks_cover_every_row_once_and_nest_in_folds():
    bounds, fold = selection.block_bounds(1003, 10)
    assert bounds[0] == 0 and bounds[-1] == 1003 and np.all(np.diff(bounds) > 0)
    assert len(fold) == len(bounds) - 1 and np.all(np.diff(fold) >= 0)
    edges = selection.fold_bounds(1003, 10)
    for f in range(10):
        mine = np.flatnonzero(fold == f)
        assert bounds[mine[0]] == edges[f] and bounds[mine[-1] + 1] == edges[f + 1]


def test_heldout_sse_matches_a_direct_blocked_cross_validation(rng):
    n = 2000
    X = np.column_stack([rng.standard_normal(n), np.linspace(-1, 1, n)])
    r = X @ [0.5, 2.0] + 0.3 * rng.standard_normal(n)
    d = selection.Design(r, 5)
    d.add("a", X[:, 0])
    d.sse(["a"])                       # the Gram matrices grow with the columns added after this
    d.add("b", X[:, 1])
    got = d.sse(["a", "b"])
    edges = selection.fold_bounds(n, 5)
    pred = np.empty(n)
    for a, b in zip(edges[:-1], edges[1:]):
        train = np.r_[0:a, b:n]
        beta, *_ = np.linalg.lstsq(X[train], r[train], rcond=None)
        pred[a:b] = X[a:b] @ beta
    err = (r - pred) / d.rscale
    direct = np.array([np.sum(err[a:b] ** 2) for a, b in zip(d.bounds[:-1], d.bounds[1:])])
    np.testing.assert_allclose(got, direct, rtol=1e-8, atol=1e-10)
    np.testing.assert_allclose(d.heldout_prediction(["a", "b"]), pred, rtol=1e-8, atol=1e-10)


def test_compare_flags_a_real_gain_and_not_noise(rng):
    old = 1.0 + 0.1 * rng.random(100)
    assert selection.compare(0.5 * old, old, 0.01).significant
    noise = old * (1 + 0.01 * rng.standard_normal(100))
    c = selection.compare(noise, old, 0.01)
    assert abs(c.gain) < 0.01 and not c.clear(0.1)


# --------------------------------------------------------------------------- effects


def test_equivalent_levels_of_a_coulomb_viscous_curve():
    qd = np.r_[np.linspace(-0.7, -0.01, 50), 0.0, np.linspace(0.01, 0.7, 50)]
    y = np.where(qd > 0, 6 + 11 * qd, np.where(qd < 0, -4 + 9 * qd, 0))
    lv = E.equivalent_levels(y, qd)
    assert lv["Fc+"] == pytest.approx(6) and lv["Fv+"] == pytest.approx(11)
    assert lv["Fc-"] == pytest.approx(4) and lv["Fv-"] == pytest.approx(9)


def test_position_frequency_is_found_over_unevenly_spaced_q(rng):
    log = synthetic(rng)
    sig = log.signals
    period = 0.0731
    r = 0.8 * np.sin(2 * np.pi * sig["q"] / period + 1.0) + 0.2 * rng.standard_normal(len(log))
    w = E.Position().frequencies(E.Context(sig, np.zeros(len(log))), r)[0]
    assert 2 * np.pi / w == pytest.approx(period, rel=0.01)


def test_a_ripple_whose_phase_turns_with_the_direction_is_added_as_position(rng):
    """Harmonic-drive friction ripple: a torque periodic in q whose friction part changes sign with
    the motion. Its two directions' phases differ by 90 degrees: the mean over both directions of a
    fit without the direction terms leaves most of it."""
    period = 0.0517

    def friction(s):
        wq = 2 * np.pi * s["q"] / period
        return CoulombViscous().predict(s)[0] + 0.4 * np.sin(wq + 0.3) + 0.4 * T.held_sign(s["qd"]) * np.cos(wq + 0.3)

    d = diagnose(CoulombViscous(), synthetic(rng, friction=friction, noise=0.1))
    assert d.added == ["position"]
    params = {k: v["value"] for k, v in d.effects[0].params.items()}
    assert params["period1"] == pytest.approx(period, rel=1e-3)
    assert params["amplitude1"] == pytest.approx(0.4, rel=0.05)
    assert params["friction1"] == pytest.approx(0.4, rel=0.05)
    assert d.mae_after < 0.5 * d.mae_before


SYNTHETIC_EFFECTS = {
    "offset": lambda s, f: f + 1.5,
    "level": lambda s, f: 1.3 * f,
    "direction": lambda s, f: np.where(s["qd"] > 0, 1.3, 0.8) * f,
    "acceleration": lambda s, f: f + 2.0 * s["qdd"],
    "load": lambda s, f: f + 0.08 * np.abs(s["tau_g"]) * T.held_sign(s["qd"]),
}


@pytest.mark.parametrize("name", sorted(SYNTHETIC_EFFECTS))
def test_synthetic_effect_is_added_first_with_its_parameters(rng, name):
    change = SYNTHETIC_EFFECTS[name]
    log = synthetic(rng, friction=lambda s: change(s, CoulombViscous().predict(s)[0]))
    d = diagnose(CoulombViscous(), log)
    assert d.added[0] == name
    assert d.effects[0].name == name and d.effects[0].significant
    assert d.mae_after < 0.5 * d.mae_before
    params = {k: v["value"] for k, v in d.effects[0].params.items()}
    expected = {"offset": {"offset": 1.5}, "level": {"scale": 1.3}, "acceleration": {"inertia": 2.0},
                "direction": {"Fc+": 6.5, "Fc-": 4.0, "Fv+": 13.0, "Fv-": 8.0}, "load": {"kc": 0.08}}[name]
    for key, value in expected.items():
        assert params[key] == pytest.approx(value, rel=0.05), key


def test_level_plus_offset_is_not_reported_as_direction(rng):
    log = synthetic(rng, friction=lambda s: 1.3 * CoulombViscous().predict(s)[0] + 1.0)
    d = diagnose(CoulombViscous(), log)
    assert set(d.added) == {"level", "offset"}


def test_clean_log_adds_nothing_and_json_schema(rng):
    d = diagnose(CoulombViscous(), synthetic(rng))
    assert d.added == []
    assert d.mae_after == d.mae_before
    out = d.to_json()
    assert set(out) == {"mae_before", "mae_after", "cut", "intervals", "effects", "added", "model_errors",
                        "suspected", "declined", "skipped", "notes", "unexplained_share", "unexplained"}
    for e in out["effects"]:
        assert set(e) == {"name", "significant", "gain", "params", "part", "implausible"}
        assert e["part"] in ("friction", "model")
        for par in e["params"].values():
            assert set(par) == {"value", "unit"}
    lo, hi = out["intervals"]["mae_before"]
    assert lo < out["mae_before"] < hi
    assert set(out["unexplained"]) == {"share", "main", "time", "velocity", "position"}
    assert 0 <= out["unexplained_share"] < 0.1
    json.dumps(out, allow_nan=False)


def test_column_effect_needs_the_column_and_is_found(rng):
    n = 6000
    h = 50 + 15 * np.sin(np.arange(n) / n * 2 * np.pi * 1.3)
    log = synthetic(rng, n=n, friction=lambda s: CoulombViscous().predict(s)[0] + 0.08 * (s["humidity"] - 50)
                    * T.held_sign(s["qd"]), humidity=h)
    d = diagnose(CoulombViscous(), log)
    assert d.added[0] == "column:humidity"
    assert d.effects[0].params["dFc/dhumidity"]["value"] == pytest.approx(0.08, rel=0.1)
    assert "temperature" in d.skipped


def test_too_short_log_is_refused(rng):
    from fricli.core.errors import DataError

    with pytest.raises(DataError, match="too few rows"):
        diagnose(CoulombViscous(), synthetic(rng, n=100))


# --------------------------------------------------------------------------- the augmented model


def _lugre():
    from fricli.models.lugre import LuGreModel

    return LuGreModel(fc=5.0, fs=6.5, vs=0.05, delta=1.2, fv=10.0, kc=0.02, ks=0.03, sigma0=2e4, sigma1=5.0)


def test_augmented_model_round_trip_and_batches(tmp_path, rng):
    log = synthetic(rng)
    terms = [T.term("p*pos", T.P, T.POS), T.term("tau_g held", T.HELDGRAVITY)]
    errors = [T.term("1", T.ONE), T.term("qdd", T.sig_("qdd"))]
    aug = AugmentedModel(_lugre(), terms, [0.2, 0.05], error_terms=errors, error_coef=[0.3, 1.5],
                         effects=["offset", "direction", "acceleration", "quadrant"], errors=["offset", "acceleration"])
    path = tmp_path / "aug.npz"
    models.save_for_log(str(path), aug, log, rows_used=len(log))
    back, meta = models.load(str(path))
    assert meta["kind"] == "augmented" and meta["model"]["children"]["base"]["kind"] == "lugre"
    assert back.required_inputs() == {"t", "qd", "qdd", "tau_g"}
    whole = back.predict(log.signals)[0]
    np.testing.assert_array_equal(whole, aug.predict(log.signals)[0])
    assert back.errors == ["offset", "acceleration"] and [t["name"] for t in back.error_terms] == ["1", "qdd"]
    np.testing.assert_allclose(whole - back.friction_only().predict(log.signals)[0], 0.3 + 1.5 * log.signals["qdd"])
    # cut into batches at awkward places (inside rests too): the state carries across
    parts, state = [], None
    for a, b in [(0, 137), (137, 1400), (1400, 1401), (1401, 6000)]:
        sig = {k: v[a:b] for k, v in log.signals.items()}
        out, state = back.predict(sig, state)
        parts.append(out)
    np.testing.assert_allclose(np.concatenate(parts), whole, rtol=1e-12, atol=1e-9)


def test_augmented_model_refuses_bad_parts():
    with pytest.raises(ValueError):
        AugmentedModel(_lugre(), [T.term("1", T.ONE)], [1.0, 2.0])
    with pytest.raises(ValueError):
        AugmentedModel(_lugre(), [T.term("1", T.ONE)], [np.nan])


def test_lugre_base_carries_direction_as_its_own_parameters(rng):
    true = _lugre().replace(fc=6.0, fs=7.8, fv=12.0, fc_neg=4.0, fs_neg=5.2, fv_neg=8.0)
    log = synthetic(rng, n=8000, friction=lambda s: true.predict(s)[0])
    base = _lugre()
    d = diagnose(base, log)
    assert d.added[0] == "direction"
    fixed = augment(base, d, log)
    assert "direction" in fixed.carried
    got = fixed.base
    for name, value in (("fc", 6.0), ("fv", 12.0), ("fc_neg", 4.0), ("fv_neg", 8.0)):
        assert getattr(got, name) == pytest.approx(value, rel=0.05), name
    assert diagnose(fixed, log).added == []


# --------------------------------------------------------------------------- simulated acceptance

SIM_EFFECTS = {  # simulator effect -> the name diagnose must give it
    "position": "position", "temperature": "temperature", "drift": "drift", "direction": "direction",
    "inertia": "acceleration", "load": "load", "velocity": "velocity", "level": "level", "offset": "offset",
    "column": "column:humidity", "hysteresis": "hysteresis",
}


def _sim(seed, *effects, duration=60.0):
    from fricli import sim

    table = sim.simulate("extended", joint=2, seed=seed, effects=effects, duration=duration, friction_state="base")
    return table, logs.from_table(table, name=f"extended seed {seed}")


@pytest.fixture(scope="module")
def lugre_base():
    """The LuGre model identified on a clean base log (seed 1)."""
    from fricli import sim
    from fricli.fitting.identify import identify

    return identify(logs.from_table(sim.simulate("base", joint=2, seed=1), name="base seed 1")).model_


def _mae(model, log):
    return metrics.errors(logs.friction_target(log.signals), model.predict(log.signals)[0])["mae"]


def _ripple_phase_is_per_log(t2, t3) -> bool:
    from fricli import sim

    def phases(table):
        return [e["params"]["phases"] for e in sim.metadata(table)["effects"] if e["name"] == "position"]

    return phases(t2) != phases(t3)


@pytest.mark.parametrize("effect", sorted(SIM_EFFECTS))
def test_simulated_effect_is_ranked_first_and_fixed(lugre_base, effect):
    t2, log2 = _sim(2, effect)
    t3, log3 = _sim(3, effect)
    d = diagnose(lugre_base, log2)
    assert d.effects[0].name == SIM_EFFECTS[effect]
    assert d.added[0] == SIM_EFFECTS[effect]
    fixed = augment(lugre_base, d, log2)
    assert diagnose(fixed, log2).added == []
    if effect == "position" and _ripple_phase_is_per_log(t2, t3):
        pytest.skip("the simulator draws the ripple's phase per seed, so no model can predict the ripple "
                    "of another log (a gear's ripple is fixed to its position)")
    before, after = _mae(lugre_base, log3), _mae(fixed, log3)
    assert after <= 0.7 * before, f"MAE {before:.3f} -> {after:.3f}"


def test_a_drift_holds_its_level_beyond_the_diagnosed_span(lugre_base):
    """Fitted on 60 s, a straight trend run on for an hour would reverse the friction; beyond
    the log's time span the fixed model keeps the level the log ended with."""
    _, log = _sim(2, "drift")
    d = diagnose(lugre_base, log)
    fixed = augment(lugre_base, d, log)
    assert d.added[0] == "drift"
    t = log.signals["t"]
    hour, two_hours = ({**log.signals, "t": t + shift} for shift in (3600.0, 7200.0))
    np.testing.assert_allclose(fixed.predict(hour)[0], fixed.predict(two_hours)[0], rtol=1e-6, atol=1e-6)
    assert _mae(fixed, log) < 0.7 * _mae(lugre_base, log)


def test_simulated_clean_log_adds_nothing(lugre_base):
    _, log = _sim(2)
    d = diagnose(lugre_base, log)
    assert d.added == []
    assert d.unexplained.share < 0.1


HARD_CASES = {  # simulator effects -> the effects diagnose must add, in any order
    # a gravity torque logged too low: the gear also carries more load than tau_g says, and the
    # friction grows with it (the joint's load slope): payload, turning over the pre-sliding travel
    ("gravity",): {"gravity", "payload"},
    ("quadrant",): {"quadrant"},
    ("temperature", "position"): {"temperature", "position"},
}


@pytest.mark.parametrize("effects", sorted(HARD_CASES))
def test_harder_cases_are_named_and_fixed(lugre_base, effects):
    _, log2 = _sim(2, *effects)
    _, log3 = _sim(3, *effects)
    d = diagnose(lugre_base, log2)
    want = HARD_CASES[effects]
    assert set(d.added) == want
    assert {e.name for e in d.effects[:len(want)]} == want
    lo, hi = d.intervals["cut"]
    assert 0.4 < lo <= d.cut <= hi
    fixed = augment(lugre_base, d, log2)
    before, after = _mae(lugre_base, log3), _mae(fixed, log3)
    assert after <= 0.6 * before, f"MAE {before:.3f} -> {after:.3f}"


def test_gravity_error_is_a_model_error_kept_apart_from_friction(lugre_base):
    from fricli import sim

    t2, log2 = _sim(2, "gravity")
    low = next(e for e in sim.metadata(t2)["effects"] if e["name"] == "gravity")["strength"]
    d = diagnose(lugre_base, log2)
    gravity = d.effects[0]
    assert gravity.part == "model" and d.errors == ["gravity"]
    assert gravity.params["error"]["value"] == pytest.approx(-100 * low, abs=0.5)
    fixed = augment(lugre_base, d, log2)
    assert fixed.errors == ["gravity"] and [t["name"] for t in fixed.error_terms] == ["tau_g"]
    # the friction of the load the logged tau_g lacks is friction (payload), not a model error; its
    # slope is the joint's own load slope (simulated joint 2: kc 0.04, ks 0.05)
    payload = next(e for e in d.effects if e.name == "payload")
    assert d.added == ["gravity", "payload"] and 0.04 <= payload.params["kc"]["value"] <= 0.05
    assert [t["name"] for t in fixed.terms] == ["(|tau_l|-|tau_g|)*slip"]
    friction, error, _ = fixed.predict_parts(log2.signals)
    np.testing.assert_array_equal(friction, fixed.friction_only().predict(log2.signals)[0])
    np.testing.assert_allclose(error, (1 / (1 - low) - 1) * log2.signals["tau_g"], rtol=0.02)
    text = fixed.describe()
    assert "robot-model errors (not friction): gravity" in text
    assert text.index("robot-model errors") > text.index("augmented model")


@pytest.mark.parametrize("effect", ["gravity", "quadrant"])
def test_gravity_and_quadrant_under_a_payload(lugre_base, effect):
    from fricli import sim

    table = sim.simulate("extended", joint=2, seed=2, load="sym", effects=(effect,), duration=60.0,
                         friction_state="base")
    d = diagnose(lugre_base, logs.from_table(table, name="payload"))
    # the payload also loads the gear, which the base model's load term does not see; the sensor's
    # tau_ext is a reference, not an input, so what tells the twins apart is the rests alone
    assert d.added[0] == effect and ("gravity" in d.added) != ("quadrant" in d.added)
    assert all("does not tell them apart" in note and "tau_ext" not in note for note in d.notes)


def test_a_payload_the_model_does_not_see_in_its_load_term_is_found(lugre_base):
    from fricli import sim

    table = sim.simulate("extended", joint=2, seed=2, load="asym", duration=60.0, friction_state="base")
    d = diagnose(lugre_base, logs.from_table(table, name="payload"))
    assert d.added == ["payload"]
    assert d.effects[0].params["kc"]["value"] == pytest.approx(sim.true_params(2)["kc"], rel=0.1)
    assert d.unexplained.share < 0.1


def test_disturbance_is_unexplained_structure_not_an_effect(lugre_base):
    _, log2 = _sim(2, "disturbance")
    _, log3 = _sim(3, "disturbance")
    d = diagnose(lugre_base, log2)
    assert d.added == []
    assert d.unexplained.share > 0.3 and d.unexplained.main == "time"
    assert 2.0 <= d.unexplained.time.where["frequency_hz"] <= 3.0
    fixed = augment(lugre_base, d, log2)
    assert _mae(fixed, log3) <= _mae(lugre_base, log3)


def test_simulated_inertia_is_reported_in_kg_m2(lugre_base):
    from fricli import sim

    t2, log2 = _sim(2, "inertia")
    missing = next(e for e in sim.metadata(t2)["effects"] if e["name"] == "acceleration")["params"]["missing"]
    d = diagnose(lugre_base, log2)
    par = d.effects[0].params["inertia"]
    assert par["unit"] == "kg m^2" and par["value"] == pytest.approx(missing, rel=0.05)


# --------------------------------------------------------------------------- CLI


@pytest.fixture(scope="module")
def files(tmp_path_factory, lugre_base):
    folder = tmp_path_factory.mktemp("diag")
    base = folder / "lugre.npz"
    t1, log1 = _sim(1)
    models.save_for_log(str(base), lugre_base, log1, rows_used=len(log1))
    out = {"dir": folder, "model": str(base)}
    for name, effs in (("asym", ("direction",)), ("clean", ())):
        table, _ = _sim(2, *effs)
        path = folder / f"{name}.parquet"
        logs.write_table(table, str(path))
        out[name] = str(path)
    return out


def test_cli_json_and_fix_round_trip(files):
    runner = CliRunner()
    fixed = str(files["dir"] / "fixed.npz")
    res = runner.invoke(cli, ["diagnose", files["model"], files["asym"], "--json", "--fix", "-o", fixed])
    assert res.exit_code == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["added"][0] == "direction" and out["effects"][0]["name"] == "direction"
    assert out["mae_after"] < 0.3 * out["mae_before"]
    assert f"wrote {fixed}" in res.stderr
    res = runner.invoke(cli, ["diagnose", fixed, files["asym"], "--json"])
    assert res.exit_code == 0 and json.loads(res.stdout)["added"] == []
    # the fixed model works with the other commands
    res = runner.invoke(cli, ["inspect", fixed])
    meta = json.loads(res.stdout)
    assert meta["kind"] == "augmented" and meta["model"]["params"]["effects"][0] == "direction"
    pred = str(files["dir"] / "pred.parquet")
    res = runner.invoke(cli, ["predict", fixed, files["asym"], "-o", pred, "--json"])
    assert res.exit_code == 0, res.stderr
    assert json.loads(res.stdout)["friction"]["mae"] < 0.3
    res = runner.invoke(cli, ["estimate-ext", fixed, files["asym"], "-o", pred])
    assert res.exit_code == 0, res.stderr
    res = runner.invoke(cli, ["evaluate", "--model", f"fixed={fixed}", "--log", f"asym={files['asym']}", "--json"])
    assert res.exit_code == 0, res.stderr


def test_cli_table_on_clean_log_says_nothing_found(files):
    res = CliRunner().invoke(cli, ["diagnose", files["model"], files["clean"]])
    assert res.exit_code == 0
    assert res.stdout.startswith("no missing effect found: nothing added")
    assert "rank" in res.stdout and res.stderr == ""


def test_cli_fix_on_clean_log_writes_an_equivalent_model(files):
    out = str(files["dir"] / "same.npz")
    res = CliRunner().invoke(cli, ["diagnose", files["model"], files["clean"], "--fix", "-o", out, "-q"])
    assert res.exit_code == 0 and res.stderr == ""
    fixed, fixed_meta = models.load(out)
    base, base_meta = models.load(files["model"])
    _, log = _sim(2)
    np.testing.assert_array_equal(fixed.predict(log.signals)[0], base.predict(log.signals)[0])
    # the same model, known where the base was fitted: its extrapolation warnings do not change
    assert fixed_meta["envelope"] == base_meta["envelope"]


@pytest.mark.parametrize("args, code, message", [
    (["--fix"], 2, "--fix needs -o"),
    (["-o", "x.npz"], 2, "add --fix"),
    (["--effects", "sparkle"], 2, "unknown effect"),
])
def test_cli_usage_errors(files, args, code, message):
    res = CliRunner().invoke(cli, ["diagnose", files["model"], files["clean"], *args])
    assert res.exit_code == code and message in res.stderr


def test_cli_bad_model_file_exits_4(files, tmp_path):
    bad = tmp_path / "bad.npz"
    bad.write_bytes(b"not a model")
    res = CliRunner().invoke(cli, ["diagnose", str(bad), files["clean"]])
    assert res.exit_code == 4 and res.stderr.startswith("fricli: error:")


def test_cli_failed_fix_leaves_the_previous_file(files, tmp_path):
    target = tmp_path / "keep.npz"
    target.write_bytes(b"previous")
    res = CliRunner().invoke(cli, ["diagnose", files["model"], str(tmp_path / "missing.parquet"),
                                   "--fix", "-o", str(target)])
    assert res.exit_code == 3 and target.read_bytes() == b"previous"


def test_cli_effects_option_limits_the_candidates(files):
    res = CliRunner().invoke(cli, ["diagnose", files["model"], files["asym"], "--json", "--effects", "offset,level"])
    out = json.loads(res.stdout)
    assert {e["name"] for e in out["effects"]} <= {"offset", "level"}
    assert "direction" not in out["added"]


# --------------------------------------------------------------------------- no meaningless numbers


def _with_tau_g(rng, tau_g, friction=None, noise=0.2, n=6000, **extra):
    """``synthetic`` with its tau_g replaced by ``tau_g(sig)`` (the friction sees the new one)."""
    log = synthetic(rng, n=n, noise=noise, **extra)
    sig = dict(log.signals)
    sig["tau_g"] = tau_g(sig)
    f = (friction or (lambda s: CoulombViscous().predict(s)[0]))(sig)
    cols = {k: v for k, v in sig.items() if k not in ("tau_m",)}
    cols["tau_m"] = sig["tau_g"] + f + noise * rng.standard_normal(n)
    units = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "tau_dyn": "Nm"}
    return logs.from_table(logs.table_from_arrays(cols, units), name="synthetic")


@pytest.mark.parametrize("spread", [1e-15, 0.02])
def test_a_tau_g_that_barely_varies_leaves_its_effects_untested(rng, spread):
    # a vertical first axis (rounding noise) or a wrist joint whose tau_g varies far less than the
    # residual: no coefficient up to 1 Nm/Nm could explain the residual, so none is reported
    log = _with_tau_g(rng, lambda s: spread * np.sin(3 * s["q"]), noise=0.5)
    d = diagnose(CoulombViscous(), log)
    for name in ("gravity", "load", "quadrant"):
        assert "varies too little" in d.skipped[name], name
        assert name not in {e.name for e in d.effects}
    text = table(d)
    assert "not tested: tau_g varies too little" in text and "Nm/Nm" in text


def test_the_same_spread_is_tested_when_the_residual_is_small(rng):
    log = _with_tau_g(rng, lambda s: 2.0 * np.sin(3 * s["q"]), noise=0.2)
    d = diagnose(CoulombViscous(), log)
    assert not {"gravity", "load", "quadrant"} & set(d.skipped)


def test_a_constant_column_is_not_tested(rng):
    log = synthetic(rng, humidity=np.full(6000, 40.0) + 40.0 * np.finfo(float).eps * (np.arange(6000) % 2))
    d = diagnose(CoulombViscous(), log)
    assert d.skipped["column:humidity"] == "the column 'humidity' is constant"


def test_gains_below_minus_100_percent_read_worse(rng):
    # a column that is a thousandth of the residual on nine folds and +-0.5 on the last: its
    # coefficient, fitted on the nine, predicts the last wildly wrong
    n = 6000
    log = synthetic(rng, n=n)
    h = 1e-3 * (logs.friction_target(log.signals) - CoulombViscous().predict(log.signals)[0])
    h[-n // 10:] = 0.5 * (-1.0) ** np.arange(n // 10)
    table_ = log.table.append_column("humidity", logs.table_from_arrays({"humidity": h}, {}).column(0))
    d = diagnose(CoulombViscous(), logs.from_table(table_, name="synthetic", zero=("tau_dyn",)))
    col = next(e for e in d.effects if e.name == "column:humidity")
    assert col.gain == driver.WORST_GAIN and col.step_gain >= driver.WORST_GAIN
    assert all(e.gain >= driver.WORST_GAIN for e in d.effects) and min(d.alone.values()) >= driver.WORST_GAIN
    row = next(line for line in table(d).splitlines() if "column:humidity" in line)
    assert "worse" in row and "%" not in row.split("column:humidity")[1].split("no")[0]


@pytest.mark.parametrize("lo, hi, shown", [
    (0.011130, 0.011180, "0.01113 .. 0.01118"),
    (1234.51, 1234.57, "1234.51 .. 1234.57"),
    (-0.034, 0.0, "-0.034 .. 0"),
    (1.2, 3.4, "1.2 .. 3.4"),
])
def test_ranges_print_with_the_precision_that_shows_them(lo, hi, shown):
    assert structure.span(lo, hi) == shown


def test_structure_at_rest_reads_at_rest():
    s = structure.Structure(time=structure.View(0.0, False, {"frequency_hz": None}),
                            velocity=structure.View(0.4, True, {"range": [0.0, 0.0]}),
                            position=structure.View(0.1, True, {"range": [0.0111301, 0.0111802]}))
    assert "at rest (velocity 0 rad/s)" in s.line("Nm", "rad/s", "rad")
    s.velocity = structure.View(0.0, False, {"range": None})
    assert "over position 0.01113 .. 0.01118 rad" in s.line("Nm", "rad/s", "rad")


# --------------------------------------------------------------------------- implausible corrections


def _gravity_off(rng, scale):
    """The true gravity torque is ``scale`` times the logged one."""
    return _with_tau_g(rng, lambda s: 10.0 * np.sin(s["q"] + 0.3 * np.sin(0.1 * s["t"])),
                       friction=lambda s: CoulombViscous().predict(s)[0] + (scale - 1.0) * s["tau_g"])


def test_a_plausible_gravity_scale_is_added():
    d = diagnose(CoulombViscous(), _gravity_off(np.random.default_rng(3), 1.15))
    assert d.added == ["gravity"] and d.suspected == []
    assert d.effects[0].params["scale"]["value"] == pytest.approx(1.15, abs=0.01)
    assert d.effects[0].implausible is None


def test_an_implausible_gravity_scale_is_flagged_and_not_applied(tmp_path):
    log = _gravity_off(np.random.default_rng(4), 2.0)
    d = diagnose(CoulombViscous(), log)
    assert "gravity" not in d.added and d.suspected == ["gravity"]
    g = next(e for e in d.effects if e.name == "gravity")
    assert g.params["scale"]["value"] == pytest.approx(2.0, abs=0.02) and not g.added
    for cause in ("joint's zero or sign convention against the URDF", "drive gain", "cable", "counterbalance spring",
                  "payload"):
        assert cause in g.implausible
    text = table(d)
    assert "suspicious, not added: gravity" in text and "--accept-implausible" in text
    # its twin, quadrant friction, takes the torque up: said so, not "the log does not tell them apart"
    assert d.added == ["quadrant"]
    assert "note: quadrant added where the suspicious gravity explains this log as well or better" in text
    assert "does not tell them apart" not in text
    fixed = augment(CoulombViscous(), d, log)
    assert fixed.errors == [] and "gravity" not in fixed.effects
    # asked explicitly: added, and still named implausible
    d = diagnose(CoulombViscous(), log, accept_implausible=True)
    assert d.added[0] == "gravity" and d.suspected == []
    assert "implausible, applied as asked" in table(d)
    assert augment(CoulombViscous(), d, log).errors == ["gravity"]


def test_a_ratio_beyond_one_is_not_printed_as_a_coefficient():
    ctx = E.Context({"qd": np.ones(3)}, np.zeros(3))
    params = E.Quadrant().params({"tau_g held": -4.7}, ctx)
    assert E.Quadrant().summary(params).startswith("kq < -1 Nm/Nm (not physical)")
    assert "not physical" in E.Quadrant().implausible(params, ctx)
    assert E.Load().summary(E.Load().params({"|tau_g|*sign": 0.02}, ctx)) == "kc 0.02000 Nm/Nm"
    assert E.Load().implausible(E.Load().params({"|tau_g|*sign": 0.02}, ctx), ctx) is None


def test_a_negative_payload_slope_is_an_echo_of_the_residual_not_a_payload():
    ctx = E.Context({"qd": np.ones(3)}, np.zeros(3))
    assert "not physical" in E.Payload().implausible(E.Payload().params({"(|tau_l|-|tau_g|)*sign": -0.3}, ctx), ctx)
    assert E.Payload().implausible(E.Payload().params({"(|tau_l|-|tau_g|)*sign": 0.05}, ctx), ctx) is None


@pytest.mark.parametrize("seed", [0, 1])
def test_effects_that_would_raise_the_held_out_mae_are_not_added(seed):
    """A third of one direction's rows, at random, 3 Nm off: an offset or a level lowers the
    squared error but moves every other row of that direction away from its truth."""
    rng = np.random.default_rng(seed)

    def friction(s):
        hit = (s["qd"] > 0) & (rng.random(len(s["qd"])) < 0.3)
        return CoulombViscous().predict(s)[0] + 3.0 * hit

    log = _with_tau_g(rng, lambda s: 10 * np.sin(s["q"]), friction=friction, noise=0.1)
    d = diagnose(CoulombViscous(), log)
    assert d.added == [] and d.terms == [] and d.mae_after == d.mae_before
    assert d.declined["effects"] and d.declined["mae_after"] > d.mae_before
    assert "lower the held-out squared error but not the held-out MAE" in table(d)
    assert augment(CoulombViscous(), d, log).effects == []


@pytest.mark.parametrize("inertia, flagged", [(0.5, False), (2.4, False), (-0.05, False), (-1.0, True), (3.0, True)])
def test_an_implausible_inertia_is_flagged(inertia, flagged):
    # robot model 2 kg m^2, motor torque 2.5 x qdd: a negative 50 % or a term above the motor's torque is implausible
    qdd = np.sin(np.arange(1000) / 50)
    ctx = E.Context({"qd": np.cos(np.arange(1000) / 50), "qdd": qdd, "tau_dyn": 2.0 * qdd, "tau_m": 2.5 * qdd},
                    np.zeros(1000))
    reason = E.Acceleration().implausible(E.Acceleration().params({"qdd": inertia}, ctx), ctx)
    assert (reason is not None) == flagged
    no_model = E.Context({"qd": ctx.signals["qd"], "qdd": qdd}, np.zeros(1000))
    assert (E.Acceleration().implausible(E.Acceleration().params({"qdd": -0.05}, no_model), no_model)
            is not None)


def test_envelope_lines_name_the_joint():
    from fricli.cli.options import extrapolation_line

    share = {"share": 0.025, "rows": 304, "of": 12001}
    assert extrapolation_line(share) == "2.5 % of the rows (304 of 12,001) lie outside the model's training envelope"
    assert extrapolation_line(share, "3").startswith("2.5 % of the rows of joint 3 (304 of 12,001)")
    assert extrapolation_line(None, "3") is None


def test_a_position_range_of_a_few_samples_is_not_tested():
    t = np.arange(2000) / 100.0
    qd = 0.3 * np.sin(t)
    wide = E.Context({"t": t, "q": np.cumsum(qd) / 100.0, "qd": qd}, np.zeros(2000))
    assert E.Position().applicable(wide) is None
    few = dict(wide.signals, q=np.round(wide.signals["q"] / 0.5) * 1e-4)      # one step of 1e-4 rad
    reason = E.Position().applicable(E.Context(few, np.zeros(2000)))
    # three harmonics at two samples per period, two periods: 12 steps
    assert reason.startswith("the position range 0.0001 rad is under two periods") and "(0.0012 rad)" in reason


def test_no_payload_on_a_joint_that_gravity_does_not_load(rng):
    # a vertical axis: tau_g is zero up to rounding, so a payload cannot load the gear; the gear load
    # tau_m - tau_dyn - p would only echo the residual (before: payload kc ~ 1 Nm/Nm "explained" it)
    log = _with_tau_g(rng, lambda s: 1e-15 * np.sin(s["t"]),
                      friction=lambda s: CoulombViscous().predict(s)[0] * (1 + 0.5 * np.sin(0.3 * s["t"])))
    d = diagnose(CoulombViscous(), log)
    assert "payload" not in d.added
    assert "gravity" in d.skipped["payload"] or "tau_g" in d.skipped["payload"]


# ---------------------------------------------------------------- a whole arm whose CAD masses are off


@pytest.fixture(scope="module")
def arm_with_cad_errors(tmp_path_factory):
    """A four-joint arm simulated with masses and centres of mass up to 30 % off the URDF's, imported
    with the CAD URDF (``fricli dynamics``), and a linear friction model per joint fitted on it."""
    from test_estimators import cad_arm_files

    root = tmp_path_factory.mktemp("arm")
    _, log = cad_arm_files(root)
    done = CliRunner().invoke(cli, ["identify", str(log), "--kind", "linear", "-o", str(root / "linear"), "-q"])
    assert done.exit_code == 0, done.output
    return root, str(log)


def test_whole_arm_robot_model_errors_point_to_calibration(arm_with_cad_errors):
    root, log = arm_with_cad_errors
    done = CliRunner().invoke(cli, ["diagnose", str(root / "linear"), log, "--json"])
    assert done.exit_code == 0, done.output
    out = json.loads(done.stdout)
    robot = out["robot_model"]
    assert len(robot["joints"]) >= 2
    assert robot["command"] == f"fricli calibrate {log} --urdf {root / 'cad.urdf'} --friction stribeck -o CAL.urdf"
    for j in robot["joints"]:
        assert set(out["joints"][j]["added"] + out["joints"][j]["suspected"]) & {"gravity", "acceleration"}
        assert robot["fit"][j]["rms_after"] < 0.5 * robot["fit"][j]["rms_before"]
    text = CliRunner().invoke(cli, ["diagnose", str(root / "linear"), log]).stdout
    assert text.count("robot-model errors on joints") == 1


def test_fix_calibrate_writes_the_urdf_and_the_error_falls(arm_with_cad_errors):
    root, log = arm_with_cad_errors
    cal, fixed = root / "cal.urdf", root / "fixed"
    done = CliRunner().invoke(cli, ["diagnose", str(root / "linear"), log, "--fix", "--calibrate", str(cal),
                                    "-o", str(fixed), "--json", "-q"])
    assert done.exit_code == 0, done.output
    assert "another robot model" not in done.stderr     # the models are refitted on the recomputed log
    robot = json.loads(done.stdout)["robot_model"]
    assert cal.exists() and (root / "cal.calibration.json").exists()
    assert len(robot["joints"]) >= 2
    for j in robot["joints"]:
        assert robot["mae"][j]["mae_after"] < 0.5 * robot["mae"][j]["mae_before"]
        assert not {"gravity", "acceleration"} & set(robot["mae"][j]["model_errors_after"])
    assert sorted(p.name for p in fixed.iterdir()) == [f"joint_{j}.npz" for j in (1, 2, 3, 4)]


def test_calibrate_friction_is_the_calibrations(arm_with_cad_errors):
    """Stribeck by default (the friction models are refitted afterwards), linear when asked."""
    root, log = arm_with_cad_errors
    for given, kind in (([], "stribeck"), (["--calibrate-friction", "linear"], "linear")):
        cal = root / f"cal-{kind}.urdf"
        done = CliRunner().invoke(cli, ["diagnose", str(root / "linear"), log, "--fix", "--calibrate", str(cal),
                                        *given, "-o", str(root / f"fixed-{kind}"), "-q"])
        assert done.exit_code == 0, done.output
        assert json.loads((root / f"cal-{kind}.calibration.json").read_text())["friction"]["kind"] == kind
    done = CliRunner().invoke(cli, ["diagnose", str(root / "linear"), log, "--calibrate-friction", "stribeck"])
    assert done.exit_code == 2 and "--calibrate-friction applies to --calibrate" in done.output


def test_a_run_imported_with_the_calibrated_urdf_matches_the_refitted_models(arm_with_cad_errors):
    """The calibrated URDF carries every joint's armature, which replaces a mapping's rotor inertia:
    a run imported with both is the robot model the models were refitted on, without a warning."""
    root, log = arm_with_cad_errors
    runner = CliRunner()
    cal, fixed, other = root / "cal-r.urdf", root / "fixed-r", root / "other.parquet"
    done = runner.invoke(cli, ["diagnose", str(root / "linear"), log, "--fix", "--calibrate", str(cal),
                               "-o", str(fixed), "-q"])
    assert done.exit_code == 0, done.output
    done = runner.invoke(cli, ["dynamics", str(root / "raw.parquet"), "--urdf", str(cal), "--match", "order",
                               "--rotor-inertia", "2=0.5", "-o", str(other), "-q"])
    assert done.exit_code == 0, done.output
    assert logs.robot_record(logs.read_table(str(other))[0].schema)["rotor_inertia"]["2"] is None
    done = runner.invoke(cli, ["predict", str(fixed), str(other), "-o", str(root / "p.parquet")])
    assert done.exit_code == 0 and "another robot model" not in done.stderr, done.stderr


def test_calibrate_needs_fix_and_a_whole_arm(arm_with_cad_errors):
    root, log = arm_with_cad_errors
    done = CliRunner().invoke(cli, ["diagnose", str(root / "linear"), log, "--calibrate", str(root / "c.urdf")])
    assert done.exit_code == 2 and "--calibrate applies to --fix" in done.output
    done = CliRunner().invoke(cli, ["diagnose", str(root / "linear" / "joint_2.npz"), log, "--joint", "2", "--fix",
                                    "--calibrate", str(root / "c.urdf"), "-o", str(root / "j2.npz")])
    assert done.exit_code == 2 and "whole-arm log" in done.output


def test_a_joint_held_still_is_refused_not_diagnosed(lugre_base):
    """A held joint's torque is whatever holds it (stiction, a push on the arm): no friction effect
    or robot-model error can be read from it, so diagnose refuses it as identify does."""
    from fricli.core.errors import DataError

    from fricli import sim

    table = sim.simulate("base", joint=2, seed=3)
    n = table.num_rows
    held = table.set_column(table.schema.get_field_index("q"), table.schema.field("q"),
                            [np.full(n, 0.3) + 1e-4 * np.sin(np.arange(n))])
    with pytest.raises(DataError, match=r"spans 0.0002 rad, less than 0.01 rad, over the whole log: it is held still"):
        diagnose(lugre_base, logs.from_table(held, name="held"))
    # in degrees: the span and the limit are said in rad, which the check compares (0.3 deg = 0.0052 rad)
    deg = held.set_column(table.schema.get_field_index("q"), pa.field("q", pa.float64(), metadata={"unit": "deg"}),
                          [np.full(n, 10.0) + 0.15 * np.sin(np.arange(n))])
    with pytest.raises(DataError, match=r"spans 0.0052\d* rad, less than 0.01 rad"):
        diagnose(lugre_base, logs.from_table(deg, name="held"))
    diagnose(lugre_base, logs.from_table(table, name="moving"))     # the same log in motion is diagnosed


def test_a_negative_gravity_scale_names_the_joint_zero_and_sign_convention():
    """Gravity acting against the measured torque: no mass, gain or spring does that; a joint zero a
    quarter or half turn off, or a joint turning the other way, does."""
    d = diagnose(CoulombViscous(), _gravity_off(np.random.default_rng(5), -0.5))
    g = next(e for e in d.effects if e.name == "gravity")
    assert g.params["scale"]["value"] == pytest.approx(-0.5, abs=0.02)
    assert g.implausible.startswith("a gravity scale of -0.5")
    assert "likely cause is the joint's zero or sign convention against the URDF" in g.implausible
    assert "fricli import checks the mapping" in g.implausible


def test_a_log_without_position_is_diagnosed_and_trained_without_the_position_effects(tmp_path):
    """A log with qd and no q (the log contract allows it): diagnose, and train-base's memory test,
    leave out what needs the position instead of failing with an internal error (KeyError 'q')."""
    import pyarrow.parquet as pq
    from conftest import invoke

    from fricli.sim import simulate

    table = simulate("extended", 2, seed=4, duration=60.0).drop_columns(["q"])   # no velocity levels
    log = tmp_path / "noq.parquet"
    pq.write_table(table, log)
    model = tmp_path / "linear.npz"
    assert invoke("identify", log, "--kind", "linear", "-o", model, "-q").exit_code == 0
    res = invoke("diagnose", model, log, "--json")
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert "position" not in out["unexplained"]
    res = invoke("train-base", log, "-o", tmp_path / "nn.npz", "--steps", "200", "--json", "-q")
    assert res.exit_code == 0, res.output
    assert json.loads(res.stdout)["memory"]["tested"] is False


def test_a_named_column_the_log_lacks_is_reported_not_tested():
    """--effects column:NAME for a column the log does not have is listed as not tested, with the
    reason, instead of dropped without a word."""
    sig = {"t": np.arange(10.0), "qd": np.linspace(-1, 1, 10), "temp": np.linspace(20, 30, 10)}
    names = [e.name for e in E.library(sig, only=["column:nothere", "column:temp", "level"])]
    assert "column:nothere" in names and "column:temp" in names and "level" in names
    missing = next(e for e in E.library(sig, only=["column:nothere"]) if e.name == "column:nothere")

    class Context:
        signals = sig

    assert missing.applicable(Context()) == "the log has no column 'nothere'"
