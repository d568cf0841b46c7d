"""The dissipative network's pre-sliding (bristle) state: LuGre's bristle equations with the
learned magnitude as the steady state (``DissipativeFriction.fit_bristles``)."""

import copy
import dataclasses
import json

import numpy as np
import pytest
from click.testing import CliRunner
from conftest import SAMPLE
from test_export import _compare, needs_cc

from fricli import models
from fricli.cli import cli
from fricli.core import metrics
from fricli.models.dissipative import DissipativeFriction
from fricli.sim import joints, simulator

SIGMA0 = 1000.0   # the simulated joint's bristle stiffness [Nm/rad]: a deflection fs / sigma0 of 4 mrad


def simulated(seed: int) -> dict[str, np.ndarray]:
    """A LuGre joint (simulated joint 4, soft bristles, no bristle damping) under varying velocity
    levels with reversals; the true friction as the target."""
    j = dataclasses.replace(joints.joint(4), sigma0=SIGMA0, sigma1=0.0)
    table = simulator.simulate("extended", j, seed=seed, duration=30.0, rate=200.0)
    return {k: table.column(k).to_numpy() for k in ("t", "q", "qd", "tau_g", "tau_f_true")}


@pytest.fixture(scope="module")
def fitted():
    """(static model, the same network with the state, training log, other log)."""
    train, other = simulated(0), simulated(1)
    moving = metrics.in_motion(train["qd"])
    static = DissipativeFriction(steps=1000).fit({k: v[moving] for k, v in train.items()},
                                                 train["tau_f_true"][moving], rng=np.random.default_rng(0))
    state = copy.deepcopy(static)
    state.fit_bristles(train, train["tau_f_true"], np.flatnonzero(moving))
    return static, state, train, other


def after_reversal(sig: dict[str, np.ndarray], distance: float) -> np.ndarray:
    """Rows (n,) bool within ``distance`` [rad] of travel after a reversal of the velocity."""
    s = np.sign(sig["qd"])
    start = np.zeros(s.size, dtype=int)
    turns = np.flatnonzero(s[1:] * s[:-1] < 0) + 1
    start[turns] = turns
    start = np.maximum.accumulate(start)
    return (start > 0) & (np.abs(sig["q"] - sig["q"][start]) < distance)


def rms(e: np.ndarray) -> float:
    return float(np.sqrt(np.mean(e ** 2)))


def test_the_state_follows_the_reversals_of_a_lugre_joint(fitted):
    static, state, _, other = fitted
    near = after_reversal(other, 5 * joints.joint(4).fs / SIGMA0)   # five bristle deflections of travel
    assert near.sum() > 50
    y = other["tau_f_true"]
    e_static, e_state = rms((y - static.predict(other)[0])[near]), rms((y - state.predict(other)[0])[near])
    assert e_state < 0.5 * e_static                      # measured: 0.61 against 3.33 Nm
    assert rms(y - state.predict(other)[0]) < rms(y - static.predict(other)[0])
    assert SIGMA0 / 2 < state.sigma0_ < 2 * SIGMA0         # the stiffness found is the joint's


def test_steady_sliding_gives_the_learned_curve(fitted):
    _, state, _, _ = fitted
    state = copy.deepcopy(state)
    state.precision = "double"   # float32 sums vary from row to row with the BLAS kernel
    for qd in (0.05, -0.2, 0.7):
        for tau_g in (0.0, -8.0, 12.0):
            t = np.arange(2000) * 1e-3
            sig = {"t": t, "qd": np.full(t.size, qd), "tau_g": np.full(t.size, tau_g)}
            tau = state.predict(sig)[0]
            np.testing.assert_allclose(tau[-1], np.sign(qd) * state.magnitude(sig)[-1], rtol=1e-9)


def test_passive_and_pulled_through_zero_at_a_reversal(fitted):
    """Work done on the joint, integrated exactly for the velocity held over each interval, is at
    least the change of the bristle energy sigma0 z^2 / 2, for any motion and load."""
    _, state, _, _ = fitted
    rng = np.random.default_rng(3)
    n = 4000
    dt = rng.uniform(1e-4, 2e-2, n)
    t = np.cumsum(dt)
    qd = np.cumsum(rng.normal(0, 0.05, n)) * rng.choice([1.0, 30.0], n)
    sig = {"t": t, "qd": qd, "tau_g": rng.normal(0, 30, n)}
    tau = state.predict(sig)[0]
    s0 = state.sigma0_
    z = tau / s0
    g = np.maximum(state.magnitude(sig), 1e-12)
    rate = s0 * np.abs(qd) / g
    zss = np.sign(qd) * g / s0
    a = np.exp(-np.minimum(rate * dt, 700.0))
    z_prev = np.concatenate([[zss[0]], z[:-1]])
    with np.errstate(invalid="ignore", divide="ignore"):
        mean_z = np.where(rate * dt > 1e-12, zss + (z_prev - zss) * (1 - a) / (rate * dt), z_prev)
    work = np.cumsum(s0 * qd * mean_z * dt)
    stored = 0.5 * s0 * (z ** 2 - z_prev[0] ** 2)
    assert (work >= stored - 1e-9 * np.maximum(1.0, np.abs(work))).all()
    assert np.abs(z).max() <= g.max() / s0 * (1 + 1e-12)
    turns = np.flatnonzero(np.sign(qd[1:]) * np.sign(qd[:-1]) < 0) + 1
    assert (tau[turns] * qd[turns] < 0).any()           # friction from before the reversal, not at qd = 0


def test_save_and_load_give_the_same_numbers(fitted, tmp_path):
    static, state, _, other = fitted
    for model in (static, state):
        path = str(tmp_path / "m.npz")
        models.save(path, model, joint=4, axis="rotary", units={}, provenance={})
        loaded, meta = models.load(path)
        assert loaded.sigma0_ == model.sigma0_
        assert np.array_equal(loaded.predict(other)[0], model.predict(other)[0])
        assert ("t" in meta["inputs"]) == (model.sigma0_ is not None)
        assert ("sigma0" in loaded.describe()) == (model.sigma0_ is not None)
    assert "bristles" not in models.to_parts(static)[0]["params"]   # files without the state stay as they were
    tanh = np.tanh(other["qd"] / static.v_ps_)
    np.testing.assert_allclose(static.predict(other)[0], tanh * static.magnitude(other), rtol=1e-6, atol=1e-9)
    assert static.predict(other)[1] is None


def test_state_carried_across_batches_equals_one_pass(fitted):
    _, state, _, other = fitted
    state = copy.deepcopy(state)
    state.precision = "double"
    whole, last = state.predict(other)
    parts, carried = [], None
    for cut in np.array_split(np.arange(other["t"].size), 7):
        tau, carried = state.predict({k: v[cut] for k, v in other.items()}, carried)
        parts.append(tau)
    np.testing.assert_allclose(np.concatenate(parts), whole, rtol=1e-12, atol=1e-12)
    assert carried[1] == last[1] and abs(carried[0] - last[0]) <= 1e-15


def test_damaged_bristle_parameters_are_refused(fitted):
    _, state, _, _ = fitted
    spec, arrays = models.to_parts(state)
    for bad in (-1.0, 0.0, float("nan"), "x", None):
        spec["params"]["bristles"] = {"sigma0": bad}
        with pytest.raises(ValueError, match="bristle"):
            DissipativeFriction.from_parts(spec["params"], arrays, {})


def test_train_base_bristles_option(tmp_path):
    """--bristles on gives the state, fitted on the training log; auto says what it measured."""
    from fricli.core.logs import table_from_arrays
    from conftest import write

    sig = simulated(0)
    units = dict(simulator.UNITS)
    zeros = np.zeros_like(sig["t"])
    table = table_from_arrays({"t": sig["t"], "q": sig["q"], "qd": sig["qd"], "qdd": zeros,
                               "tau_m": sig["tau_g"] + sig["tau_f_true"], "tau_g": sig["tau_g"], "tau_dyn": zeros},
                              {k: units[k] for k in ("t", "q", "qd", "qdd", "tau_m", "tau_g", "tau_dyn")})
    log = write(table, tmp_path / "log.parquet")
    for choice in ("on", "off", "auto"):
        out = tmp_path / f"{choice}.npz"
        res = CliRunner().invoke(cli, ["train-base", str(log), "--steps", "300", "--bristles", choice,
                                       "-o", str(out), "--json", "-q"])
        assert res.exit_code == 0, res.output
        model = models.load(str(out))[0]
        check = json.loads(res.stdout).get("bristles")
        if choice == "off":
            assert model.sigma0_ is None and check is None
            continue
        assert check["bristles_rmse"] < check["static_rmse"]     # held out: the joint's bristles show
        assert check["kept"] == (model.sigma0_ is not None) == (choice == "on" or check["helps"])


@needs_cc
def test_export_with_the_state_matches_predict(fitted, tmp_path):
    """The exported C code carries the bristle state as predict --precision double does (1e-9)."""
    from fricli.core import logs
    from fricli.models.residual import ResidualFriction

    _, state, train, _ = fitted
    log = logs.load_log(str(SAMPLE / "joint2_extended_asym.parquet"), cutoff_hz=50.0)
    rows = np.arange(0, train["t"].size, 7)
    adapted = ResidualFriction(state, epochs=2).fit(train, train["tau_f_true"], rows[::2], rows[1::2],
                                                    rng=np.random.default_rng(1))
    for name, model in (("state", state), ("adapted", adapted)):      # alone and as the base of adapt's model
        path = str(tmp_path / f"{name}.npz")
        models.save_for_log(path, model, log, rows_used=len(log))
        assert _compare(path, str(SAMPLE / "joint2_extended_asym.parquet"), tmp_path) <= 1.0


def test_bristles_auto_drops_a_state_that_does_not_help_on_velocity_levels(tmp_path):
    """A log of constant-velocity levels whose friction has no pre-sliding: --bristles auto measures
    no gain and writes the static network (the check used to leave its state on the model)."""
    from fricli.core import logs
    from fricli.fitting import learning

    qd = np.concatenate([np.r_[np.full(300, s * v), np.zeros(50)] for v in (0.05, 0.1, 0.2, 0.4) for s in (1, -1)])
    t = np.arange(qd.size) / 100.0
    zeros = np.zeros_like(t)
    tau_m = 3 * np.tanh(qd / 0.01) + 5 * qd + 0.05 * np.random.default_rng(0).standard_normal(qd.size)
    table = logs.table_from_arrays(
        {"t": t, "q": np.cumsum(qd) / 100.0, "qd": qd, "qdd": zeros, "tau_m": tau_m, "tau_g": zeros, "tau_dyn": zeros},
        {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "tau_dyn": "Nm"})
    from conftest import write
    log = logs.load_log(str(write(table, tmp_path / "levels.parquet")), cutoff_hz=50.0)
    model, summary = learning.train_base(log, steps=200, seed=0, bristles="auto")
    assert summary["velocity_groups"] == "levels"
    check = summary["bristles"]
    assert not check["helps"]
    assert model.sigma0_ is None and not check["kept"]


def test_sigma0_is_fitted_where_the_bristles_act_the_slow_rows_through_a_reversal(tmp_path):
    """A LuGre joint with stiff bristles (sigma0 1e6 Nm/rad, a deflection of 3 urad) under continuous
    motion: its reversals pass within the rows below the in-motion share, and on the settled rows in
    motion every stiffness fits alike. Fitted on those alone, sigma0 went where the flat error put it
    (5e7) and the slow rows were nearly a switch of the sign; when the rows in motion do not
    determine it, the rows of slow motion do, and it is near the joint's."""
    from fricli.core import logs
    from fricli.fitting import learning
    from fricli.numerics import physics
    from conftest import write

    rate, sub = 100.0, 10
    t = np.arange(int(60 * rate * sub)) / (rate * sub)
    v = 0.2 * np.pi * np.cos(0.4 * np.pi * t) + 0.1 * np.cos(2 * np.pi * 0.53 * t)
    tau_f, _ = physics.lugre_friction(v, physics.stribeck(v, 3.0, 3.0, 0.05, 1.0), 5.0, 1e6, 0.0,
                                      physics.intervals(t))
    k = slice(None, None, sub)
    n, zeros = t[k].size, np.zeros(t[k].size)
    noise = 0.05 * np.random.default_rng(0).standard_normal(n)
    table = logs.table_from_arrays(
        {"t": t[k], "q": np.cumsum(v)[k] / (rate * sub), "qd": v[k], "qdd": zeros, "tau_m": tau_f[k] + noise,
         "tau_g": zeros, "tau_dyn": zeros},
        {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "tau_dyn": "Nm"})
    log = logs.load_log(str(write(table, tmp_path / "stiff.parquet")), cutoff_hz=50.0)
    model, summary = learning.train_base(log, steps=300, seed=0, memory="off")
    assert summary["velocity_groups"] == "moving"
    assert 1e5 < model.sigma0_ < 1e7
    slow = ~metrics.in_motion(log.signals["qd"])
    err = logs.friction_target(log.signals) - model.predict(log.signals)[0]
    assert np.mean(np.abs(err[slow])) < 0.2          # was 0.29 Nm with sigma0 at the stiff end
