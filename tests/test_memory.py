"""train-base --memory: Maxwell-slip elements on top of the network, chosen on held-out blocks of
time, on simulated joints with and without memory; --memory off; adapt over a base with memory."""

from __future__ import annotations

import numpy as np
import pytest

from conftest import no_inertia, write
from fricli.core import logs, metrics
from fricli.core.logs import table_from_arrays
from fricli.fitting import learning

UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "tau_f_true": "Nm"}
RATE, INTERNAL = 100.0, 10     # output rate [Hz]; the friction integrated at 10 times that


def joint_log(seed: int, slip: float | None, seconds: float = 60.0, level: float = 1.0):
    """The simulator's joint 2 (``fricli.sim``: extended LuGre friction, gravity, the torque noise
    ``noise_sd``) moved by a sum of three harmonics (no velocity levels: benchmarks/run.py's
    harmonic log), with the simulator's Maxwell-slip elements (``--effect hysteresis=slip``: slip
    [Nm] their total break-away force, None the default 0.3 fc; 0 none), the Coulomb and viscous
    friction scaled by ``level`` (``--effect level``)."""
    from fricli.numerics import physics
    from fricli.sim import effects as fx
    from fricli.sim import joints, simulator

    rng = np.random.default_rng(seed)
    j = joints.joint(2)
    t = np.arange(int(seconds * RATE * INTERNAL) + 1) / (RATE * INTERNAL)
    qd = sum(a * np.sin(2 * np.pi * f * t + p) for a, f, p in
             zip((0.4, 0.25, 0.15), (0.11, 0.23, 0.41), rng.uniform(0, 2 * np.pi, 3)))
    qdd = np.gradient(qd, t)
    q = np.concatenate([[0.0], np.cumsum(0.5 * (qd[1:] + qd[:-1]) * np.diff(t))])
    state = joints.state_params(j, "base")
    g = j.gravity_amplitude * np.sin(q)
    scene = fx.Scene(joint=j, t=t, q=q, v=qd, qdd=qdd, phi=np.zeros_like(t), tau_g=g, tau_ext=np.zeros_like(t),
                     temp=np.full_like(t, state["temperature"]), loaded=False, kq=state["kq"],
                     shift_pos=state["fc_shift_pos"], shift_neg=state["fc_shift_neg"])
    if level != 1.0:
        fx.EFFECTS["level"].apply(scene, level, rng)
    if slip != 0:
        fx.EFFECTS["hysteresis"].apply(scene, fx.EFFECTS["hysteresis"].default(j) if slip is None else slip, rng)
    f = simulator.friction(scene, physics.intervals(t))[::INTERNAL]
    out = slice(None, None, INTERNAL)
    cols = {"t": t[out], "q": q[out], "qd": qd[out], "qdd": qdd[out], "tau_g": g[out],
            "tau_m": g[out] + f + rng.normal(0, j.noise_sd, f.size), "tau_f_true": f}
    return no_inertia(table_from_arrays(cols, UNITS))


def benchmarks_run():
    """The module benchmarks/run.py (its ``harmonic_log``: friction of velocity and load alone)."""
    import sys

    from conftest import ROOT

    sys.path.insert(0, str(ROOT / "benchmarks"))
    try:
        import run as bench
    finally:
        sys.path.remove(str(ROOT / "benchmarks"))
    return bench


def train_cli(tmp, name: str, table, *options):
    """``fricli train-base`` of ``table`` written as tmp/name.parquet, with --json: (model, the
    --json record, stderr)."""
    import json

    from conftest import invoke
    from fricli import models

    path = write(table, tmp / f"{name}.parquet")
    out = tmp / f"{name}.npz"
    res = invoke("train-base", path, "-o", out, "--json", *options)
    assert res.exit_code == 0, res.stderr
    return models.load(str(out))[0], json.loads(res.stdout), res.stderr


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    """The default train-base on a joint with the simulator's Maxwell-slip elements and on the same
    joint without them (the same motion and noise)."""
    tmp = tmp_path_factory.mktemp("memory")
    with_slip = train_cli(tmp, "slip", joint_log(1, None))
    without = train_cli(tmp, "plain", joint_log(1, 0.0))
    return {"dir": tmp, "slip": with_slip, "plain": without}


def test_memory_is_chosen_on_a_joint_with_maxwell_slip_elements(trained):
    model, record, stderr = trained["slip"]
    memory = record["memory"]
    assert memory["mode"] == "auto" and memory["tested"] and memory["significant"] and memory["chosen"]
    assert model.kind == "augmented" and model.effects == ["hysteresis"] and model.base.kind == "dissipative"
    assert sum(1 for t in model.terms for f in t["factors"] if f["f"] == "slip") == 4
    assert record["kind"] == "augmented" and record["arch"] == "dissipative" and "memory: held-out MAE" in stderr and "chosen on held-out" in stderr
    # the held-out error falls to near what the same network reaches on the same joint without the
    # elements (its floor: the torque noise and what a network of speed and load misses at reversals):
    # the elements close at least half of the gap between the network alone and that floor
    floor = trained["plain"][1]["memory"]["rmse_before"]
    before, after = memory["rmse_before"], memory["rmse_after"]
    assert before > floor and after < before - 0.5 * (before - floor)
    # and so does the error against the true friction on the rows in motion
    log = logs.load_log(str(trained["dir"] / "slip.parquet"))
    sig, moving = log.signals, metrics.in_motion(log.signals["qd"])
    truth = sig["tau_f_true"][moving]
    error = {name: metrics.errors(truth, m.predict(sig)[0][moving])["rmse"] for name, m in (("net", model.base),
                                                                                           ("memory", model))}
    assert error["memory"] < error["net"]


def test_memory_is_not_chosen_where_the_friction_has_none(tmp_path):
    bench = benchmarks_run()
    path = bench.harmonic_log(str(tmp_path))
    model, summary = learning.train_base(logs.load_log(path))
    memory = summary["memory"]
    assert memory["tested"] and not memory["significant"] and not memory["chosen"]
    assert model.kind == "dissipative" and "not chosen" in memory["why"]


def test_memory_off_gives_the_network_alone_byte_for_byte(trained, tmp_path):
    from fricli import models

    log = logs.load_log(str(trained["dir"] / "slip.parquet"))
    off, summary = learning.train_base(log, memory="off")
    auto, _ = learning.train_base(log, memory="auto")
    assert off.kind == "dissipative" and "memory" not in summary and auto.kind == "augmented"
    parts_off, parts_base = models.to_parts(off), models.to_parts(auto.base)
    assert parts_off[0] == parts_base[0]
    assert parts_off[1].keys() == parts_base[1].keys()
    for key, value in parts_off[1].items():
        np.testing.assert_array_equal(value, parts_base[1][key])
    on, on_summary = learning.train_base(log, memory="on")
    assert on.kind == "augmented" and on_summary["memory"]["chosen"]


def test_adapt_over_a_base_with_memory(trained, tmp_path):
    """NN_add learns a friction level 25 % higher on top of the network with the elements; the
    elements stay in the adapted model, and its prediction carries their deflections over batches."""
    from conftest import invoke
    from fricli import models

    base = trained["dir"] / "slip.npz"
    new_day = write(joint_log(3, None, seconds=40.0, level=1.25), tmp_path / "day.parquet")
    res = invoke("adapt", base, new_day, "-o", tmp_path / "adapted.npz", "--json")
    assert res.exit_code == 0, res.stderr
    import json

    record = json.loads(res.stdout)
    assert record["adapted"] and record["kind"] == "residual"
    assert record["val"]["mae"] < 0.5 * record["base_val"]["mae"]
    model, _ = models.load(str(tmp_path / "adapted.npz"))
    assert model.base.kind == "augmented" and model.base.effects == ["hysteresis"]
    sig = logs.load_log(str(new_day)).signals
    models.set_precision(model, "double")     # float32 rounds with the batch's size
    whole = model.predict(sig)[0]
    state, parts = None, []
    for a, b in ((0, 1234), (1234, 1235), (1235, len(whole))):
        pred, state = model.predict({k: v[a:b] for k, v in sig.items()}, state)
        parts.append(pred)
    np.testing.assert_allclose(np.concatenate(parts), whole, rtol=1e-12, atol=1e-12)


def test_export_of_a_model_with_memory_equals_predict_double(trained, tmp_path):
    import pyarrow.parquet as pq

    import export_check as check
    from conftest import invoke
    from fricli.export import c

    if check.compiler() is None:
        pytest.skip("no C compiler")
    model_path, log_path = trained["dir"] / "slip.npz", trained["dir"] / "plain.parquet"
    for args in (("predict", model_path, log_path, "-o", tmp_path / "p.parquet", "--precision", "double"),
                 ("export", model_path, "-o", tmp_path / "m.h", "--prefix", "fr")):
        res = invoke(*args, "-q")
        assert res.exit_code == 0, (args[0], res.stderr)
    model = trained["slip"][0]
    exe = str(tmp_path / "driver")
    assert check.build(str(tmp_path / "m.h"), "fr", exe) == ""
    got = check.run(exe, check.signal_matrix(logs.load_log(str(log_path)).signals, c.signals_of(model)))
    ref = pq.read_table(tmp_path / "p.parquet").column("tau_f_pred").to_numpy()
    assert np.max(np.abs(got - ref) / (1e-9 + 1e-9 * np.abs(ref))) <= 1.0


def test_a_memory_choice_that_does_not_exist_is_refused_naming_the_option():
    from fricli.fitting import optionspec

    assert optionspec.check("train-base", {})["memory"] == "auto"
    with pytest.raises(optionspec.OptionError, match="memory") as err:
        optionspec.check("train-base", {"memory": "sometimes"})
    assert err.value.option == "memory"
    with pytest.raises(ValueError, match="memory"):
        learning.train_base(logs.from_table(joint_log(1, 0.0, seconds=20.0), name="short"), memory="sometimes")


def test_a_log_too_short_for_the_test_trains_the_network_and_says_why():
    log = logs.from_table(joint_log(1, None, seconds=1.9), name="short")
    model, summary = learning.train_base(log, steps=200)
    assert summary["velocity_groups"] == "moving" and model.kind == "dissipative"
    assert not summary["memory"]["tested"] and "too few rows" in summary["memory"]["why"]
