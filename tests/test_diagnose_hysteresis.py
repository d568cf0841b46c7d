"""The hysteresis effect of the diagnosis: the slip-element term factor, the candidate effect on
simulated joints with and without Maxwell-slip friction, and on the shared Franka data."""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import export_check as check
from conftest import invoke, shared_data
from fricli import models
from fricli.core import logs, metrics
from fricli.export import c
from fricli.fitting.diagnosis import diagnose
from fricli.fitting.diagnosis import effects as E
from fricli.models import terms as T
from fricli.numerics import physics


def _stop(q, d, z0=0.0, q0=None):
    """The stop operator stepped row by row, from z0 at position q0 (default: the first row's)."""
    z, out = z0, []
    for k in range(len(q)):
        z = min(max(z + (q[k] - (q[k - 1] if k else q[0] if q0 is None else q0)), -d), d)
        out.append(z)
    return np.array(out)


def test_the_slip_factor_is_the_stop_operator_of_q_and_carries_its_deflection_across_batches(rng):
    n = 3000
    q = np.cumsum(rng.normal(0.0, 0.002, n))
    sig = {"t": np.arange(n) * 0.01, "q": q, "qd": np.gradient(q, 0.01)}
    terms = [T.term("slip@0.004", T.slip_(0.004)), T.term("slip@0.02", T.slip_(0.02))]
    whole = T.Columns(sig).matrix(terms)
    np.testing.assert_array_equal(whole[:, 0], _stop(q, 0.004) / 0.004)
    assert whole.min() == -1.0 and whole.max() == 1.0 and whole[0, 0] == 0.0   # at rest before the first row
    state, parts = None, []
    for a, b in ((0, 1000), (1000, 1001), (1001, n)):
        cols = T.Columns({k: v[a:b] for k, v in sig.items()}, state=state)
        parts.append(cols.matrix(terms))
        state = cols.state
    np.testing.assert_array_equal(np.vstack(parts), whole)
    assert T.inputs(terms) == {"q"}


@pytest.mark.parametrize("n", [1, 5, 255, 256, 257, 3000, 70_000])
def test_the_stop_operator_in_blocks_is_the_row_by_row_one_bit_for_bit(rng, n):
    """Limits that slip at every reversal, now and then, and never; elements that start deflected."""
    limits = np.array([1e-6, 0.004, 0.05, 0.5, 10.0])
    at_rest = np.where(rng.random(n) < 0.5, -0.0, 0.0)   # signed zeros: equal as floats, not as bits
    for noise in (0.002, 1e-5, 0.0, None):
        q = at_rest if noise is None else np.cumsum(rng.normal(0.0, noise, n)) + 0.5 * np.sin(np.arange(n) * 0.005)
        z0 = rng.uniform(-1.0, 1.0, limits.size) * limits if noise is not None else -0.0 * limits
        q0 = 0.1 if noise is not None else -0.0
        got = physics.stop(q, limits, z0, q0)
        for i, d in enumerate(limits):
            np.testing.assert_array_equal(got[:, i].view(np.int64), _stop(q, d, z0[i], q0).view(np.int64))


def test_a_slip_element_needs_a_positive_limit():
    for d in (0.0, -0.01, float("inf"), "0.01"):
        with pytest.raises(ValueError, match="limit d"):
            T.check({"name": "slip", "factors": [{"f": "slip", "d": d}]})
    T.check(T.term("slip", T.slip_(0.01)))


def test_the_grid_follows_the_logs_position_steps_and_range():
    def ctx(q):
        qd = np.gradient(q, 0.01)
        return E.Context({"t": np.arange(len(q)) * 0.01, "q": q, "qd": qd}, np.zeros(len(q)))

    t = np.arange(20000) * 0.01
    fine = ctx(2.0 * np.sin(0.1 * t))
    coarse = ctx(2.0 * np.sin(0.1 * t[::10]))
    h = E.Hysteresis()
    for c in (fine, coarse):
        d = h.limits(c)
        assert len(d) == h.elements and np.isclose(d[-1], h.high_share * np.ptp(c.signals["q"]))
        assert np.isclose(d[0], h.low_steps * E.Position().step(c))
        np.testing.assert_allclose(np.diff(np.log(d)), np.log(d[1] / d[0]))
    assert h.limits(coarse)[0] > 5 * h.limits(fine)[0]
    assert h.applicable(ctx(2.0 * np.sin(0.1 * t[:1000]))) is not None   # never reverses


def test_energy_given_back_makes_the_effect_implausible():
    h = E.Hysteresis()
    unit = {"value": 0.0, "unit": "Nm"}

    def params(fc, *forces):
        out = {"Fc model": {**unit, "value": fc}}
        for i, (d, f) in enumerate(forces, 1):
            out[f"d{i}"], out[f"F{i}"] = {"value": d, "unit": "rad"}, {**unit, "value": f}
        return out

    assert h.implausible(params(0.0, (0.01, 1.0), (0.1, 0.5)), None) is None
    assert h.implausible(params(0.0, (0.01, -0.1), (0.1, 0.5)), None)          # small cycles give energy back
    assert h.implausible(params(0.0, (0.01, 1.0), (0.1, -1.5)), None)          # large cycles do
    assert h.implausible(params(1.0, (0.01, -0.1), (0.1, 0.5)), None) is None  # the model's Coulomb level pays


@pytest.fixture(scope="module")
def lugre_base():
    from fricli import sim
    from fricli.fitting.identify import identify

    return identify(logs.from_table(sim.simulate("base", joint=2, seed=1), name="base seed 1")).model_


def test_a_simulated_joint_without_memory_tests_hysteresis_and_does_not_add_it(lugre_base):
    from fricli import sim

    log = logs.from_table(sim.simulate("extended", joint=2, seed=2, duration=60.0, friction_state="base"), name="s2")
    d = diagnose(lugre_base, log)
    tested = {e.name: e for e in d.effects}
    assert "hysteresis" in tested and "hysteresis" not in d.skipped
    assert not tested["hysteresis"].significant and "hysteresis" not in d.added


def _franka(speed: str):
    path = shared_data("franka") / f"joint2_{speed}.csv"
    d = np.genfromtxt(path, delimiter=",", names=True, usecols=(0, 1, 2, 3, 4))
    n = len(d)
    table = pa.table({"t": d["time"], "joint": np.full(n, 2), "q": d["q2"], "qd": d["dq2"], "qdd": d["ddq2"],
                      "tau_m": d["q2_tau_J_compensate"], "tau_g": np.zeros(n), "tau_dyn": np.zeros(n)})
    return logs.from_table(table, name=path.name)


def test_franka_slow_file_lugre_lacks_hysteresis_and_the_fix_lowers_the_held_out_error():
    """The identified LuGre model on the slow Franka file (continuous motion, 1000 reversals): the
    diagnosis adds the elements, and leaves less held-out error than without the candidate."""
    from fricli.fitting.diagnosis.fix import augment
    from fricli.fitting.identify import identify

    log = _franka("slow")
    base = identify(log).model_
    d = diagnose(base, log)
    assert "hysteresis" in d.added
    others = [e for e in E.NAMES if e != "hysteresis"]
    without = diagnose(base, log, only=others)
    assert d.mae_after < without.mae_after < d.mae_before
    fixed = augment(base, d, log)
    target = logs.friction_target(log.signals)
    assert (metrics.errors(target, fixed.predict(log.signals)[0])["mae"]
            < metrics.errors(target, base.predict(log.signals)[0])["mae"])


def test_fixed_hysteresis_model_is_read_by_every_command(tmp_path):
    run = lambda *a: invoke(*a, "-q")   # noqa: E731
    for args in (("simulate", "--scenario", "base", "--seed", "1", "-o", tmp_path / "base.parquet"),
                 ("simulate", "--scenario", "extended", "--seed", "2", "--effect", "hysteresis", "-o",
                  tmp_path / "h2.parquet"),
                 ("simulate", "--scenario", "extended", "--seed", "3", "--effect", "hysteresis", "-o",
                  tmp_path / "h3.parquet"),
                 ("identify", tmp_path / "base.parquet", "-o", tmp_path / "lugre.npz"),
                 ("diagnose", tmp_path / "lugre.npz", tmp_path / "h2.parquet", "--fix", "-o", tmp_path / "fixed.npz")):
        res = run(*args)
        assert res.exit_code == 0, res.output
    model, _ = models.load(str(tmp_path / "fixed.npz"))
    assert model.effects[0] == "hysteresis" and "hysteresis" in model.params
    assert any(f["f"] == "slip" for t in model.terms for f in t["factors"])
    h3 = tmp_path / "h3.parquet"
    for args in (("predict", tmp_path / "fixed.npz", h3, "-o", tmp_path / "p.parquet", "--batch-rows", "700",
                  "--precision", "double"),
                 ("estimate-ext", tmp_path / "fixed.npz", h3, "-o", tmp_path / "e.parquet"),
                 ("evaluate", "--model", tmp_path / "fixed.npz", "--log", h3),
                 ("report", tmp_path / "fixed.npz", h3, "-o", tmp_path / "report"),
                 ("export", tmp_path / "fixed.npz", "-o", tmp_path / "fixed.h", "--prefix", "fr"),
                 ("inspect", tmp_path / "fixed.npz")):
        res = run(*args)
        assert res.exit_code == 0, (args[0], res.output)
    log = logs.load_log(str(h3))
    if check.compiler() is not None:   # the exported C equals predict --precision double
        exe = str(tmp_path / "driver")
        assert check.build(str(tmp_path / "fixed.h"), "fr", exe) == ""
        got = check.run(exe, check.signal_matrix(log.signals, c.signals_of(model)))
        ref = pq.read_table(tmp_path / "p.parquet").column("tau_f_pred").to_numpy()
        assert np.max(np.abs(got - ref) / (1e-9 + 1e-9 * np.abs(ref))) <= 1.0
    batched = pq.read_table(tmp_path / "p.parquet").column("tau_f_pred").to_numpy()   # in batches of 700 rows
    np.testing.assert_allclose(batched, model.predict(log.signals)[0], rtol=1e-12, atol=1e-12)
