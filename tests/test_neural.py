"""Neural friction models, train-base and adapt, on synthetic logs (and the sample/real data when present)."""

import json
import sys
import time

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import SAMPLE, invoke as run, no_inertia, shared_data, write
from fricli import models
from fricli.core import logs, metrics, modelfile
from fricli.fitting import learning, training_data
from fricli.cli import cli
from fricli.core.errors import DataError
from fricli.core.logs import table_from_arrays
from fricli.models.neural import MLPFriction, NNACMFriction, SelmicFriction, feature
from fricli.models.residual import ResidualFriction
from fricli.numerics.nn.network import PREDICT_CHUNK, predict_in_chunks, prediction_threads

UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm", "tau_f_true": "Nm"}
LEVELS = (0.02, 0.05, 0.1, 0.2, 0.4)


def static_friction(v, g, shift=None):
    """Load-dependent Stribeck + viscous friction; ``shift`` adds a (tau_g, direction) term."""
    fc, fs = 5 + 0.04 * np.abs(g), 7 + 0.05 * np.abs(g)
    f = np.sign(v) * (fc + (fs - fc) * np.exp(-np.abs(v / 0.04))) + 10 * v
    if shift:
        f = f + np.where(v > 0, 1.5 + 0.04 * g, -0.5 + 0.03 * g) * (v != 0)
    return f


def motion_log(levels, seed=0, rate=50.0, seconds=6.0, shift=False, rest=0.4, noise=0.2):
    """Constant-velocity stretches at each level, out and back, with rests between."""
    rng = np.random.default_rng(seed)
    pieces = []
    for v in levels:
        for d in (1, -1):
            pieces += [np.zeros(int(rest * rate)), np.full(int(seconds * rate), d * v)]
    qd = np.concatenate(pieces + [np.zeros(int(rest * rate))])
    t = np.arange(qd.size) / rate
    q = np.cumsum(qd) / rate + rng.uniform(-1, 1)
    g = 30 * np.sin(2 * q + 0.3)
    f = static_friction(qd, g, shift)
    tau_m = g + f + rng.normal(0, noise, qd.size)
    # no qdd column: zeros would contradict the steps of qd (read as not measured, with a note)
    cols = {"t": t, "q": q, "qd": qd, "tau_m": tau_m, "tau_g": g, "tau_f_true": f}
    return no_inertia(table_from_arrays(cols, UNITS))   # no inertia torque in tau_m


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("logs")
    return {
        "base": write(motion_log(LEVELS, seed=1), d / "base.parquet"),
        "base2": write(motion_log(LEVELS, seed=2), d / "base2.parquet"),
        "adapt": write(motion_log((0.1,), seed=3, seconds=20, shift=True), d / "adapt.parquet"),
        "shifted": write(motion_log(LEVELS, seed=4, shift=True), d / "shifted.parquet"),
        "dir": d,
    }


def load(path):
    return logs.load_log(str(path))


def mae(model, path, moving=False):
    """Friction MAE of ``model`` on the log at ``path`` (only the rows in motion if ``moving``)."""
    sig = load(path).signals
    rows = sig["qd"] != 0 if moving else slice(None)
    return metrics.errors(logs.friction_target(sig)[rows], model.predict(sig)[0][rows])["mae"]


# ---------------------------------------------------------------------------- row selection


def test_velocity_levels_are_found_and_balanced(rng):
    qd = np.concatenate([np.full(n, v) for v, n in ((0.01, 5000), (-0.01, 5000), (0.3, 200), (-0.3, 150), (0, 400))]
                        + [np.linspace(0.3, -0.3, 30)])
    labels, mode = training_data.velocity_groups(qd)
    assert mode == "levels"
    assert len(np.unique(labels[labels >= 0])) == 5
    assert (labels[-30:] == -1).mean() > 0.8             # the ramp belongs to no level (but where it crosses one)
    rows = training_data.balanced(np.arange(qd.size), labels, 600, rng)
    counts = np.bincount(labels[rows])
    assert counts.sum() <= 600
    assert sorted(counts) == [120, 120, 120, 120, 120]


def test_continuous_velocities_use_bins(rng):
    qd = 0.5 * np.sin(np.linspace(0, 40, 20000))
    labels, mode = training_data.velocity_groups(qd)
    assert mode == "bins" and (labels >= 0).all() and labels.max() == training_data.CONTINUOUS_BINS - 1


def test_validation_rows_are_whole_pieces_of_every_run(rng):
    qd = np.concatenate([np.full(1000, v) for v in (0.05, -0.05, 0.2, -0.2)])
    sel = training_data.select(qd, val_fraction=0.2, max_samples=None, rng=rng)
    val = np.zeros(qd.size, bool)
    val[sel.val] = True
    assert val.sum() == 800
    for start in range(0, 4000, 1000):                    # each run: two contiguous pieces of 100 rows
        run_val = val[start:start + 1000]
        assert run_val.sum() == 200
        assert np.count_nonzero(np.diff(run_val.astype(int)) == 1) + run_val[0] <= 2
    assert np.intersect1d(sel.train, sel.val).size == 0


def test_no_motion_is_a_data_error(files, tmp_path):
    table = table_from_arrays({"t": np.arange(100.0), "qd": np.zeros(100), "tau_m": np.ones(100),
                               "tau_g": np.zeros(100), "tau_dyn": np.zeros(100)},
                              {"t": "s", "qd": "rad/s", "tau_m": "Nm", "tau_g": "Nm", "tau_dyn": "Nm"})
    result = run("train-base", write(table, tmp_path / "still.parquet"), "-o", tmp_path / "m.npz", "--steps", 5)
    assert result.exit_code == 6
    assert "no motion" in result.stderr and not (tmp_path / "m.npz").exists()


# ---------------------------------------------------------------------------- models


def test_features():
    sig = {"t": np.arange(4.0), "qd": np.array([-0.2, 0.0, 0.1, 0.3])}
    np.testing.assert_array_equal(feature(sig, "sign(qd)"), [-1, 0, 1, 1])
    np.testing.assert_array_equal(feature(sig, "pos(qd)"), [0, 0.5, 1, 1])
    np.testing.assert_array_equal(feature(sig, "neg(qd)"), [1, 0.5, 0, 0])
    with pytest.raises(DataError, match="no 'tau_g' column.*--urdf.*--no-gravity"):
        feature(sig, "tau_g", 1, 3)                                          # unknown, not zero
    np.testing.assert_array_equal(feature(dict(sig, tau_g=np.arange(4.0)), "tau_g", 1, 3), [1, 2])


@pytest.mark.parametrize("cls", [MLPFriction, SelmicFriction, NNACMFriction])
def test_each_kind_learns_and_round_trips(cls, files, tmp_path):
    log = load(files["base"])
    model, summary = learning.train_base(log, arch=cls.kind, steps=1500, seed=0)
    assert isinstance(model, cls)
    target = logs.friction_target(log.signals)
    assert summary["train"]["mae"] < 0.25 * np.mean(np.abs(target))
    path = str(tmp_path / "m.npz")
    models.save_for_log(path, model, log, rows_used=summary["train_rows"], seed=0, fit=summary)
    loaded, meta = models.load(path)
    assert meta["kind"] == cls.kind and meta["inputs"] == ["qd", "tau_g"]
    np.testing.assert_array_equal(loaded.predict(log.signals)[0], model.predict(log.signals)[0])
    assert loaded.history_train_.size > 0 and loaded.history_val_.size > 0
    assert cls.kind in loaded.describe()


def test_velocity_input_is_asinh_of_qd_over_v0(files, tmp_path):
    log = load(files["base"])
    model, summary = learning.train_base(log, arch="mlp", steps=30, seed=0)
    assert summary["velocity_input"] == "asinh" and model.velocity_scale == "auto"
    sel = training_data.select(log.signals["qd"], rng=np.random.default_rng(0),
                               keep=np.abs(log.signals["qd"]) > training_data.LOW * 0.4)
    speeds = np.abs(log.signals["qd"][sel.train])
    assert model.v0_ == summary["v0"] == pytest.approx(np.quantile(speeds, 0.05))
    sig = log.signals
    x = model._features(sig)
    np.testing.assert_allclose(x[model.inputs.index("qd")], np.arcsinh(sig["qd"] / model.v0_))
    assert f"asinh(qd / {model.v0_:.4g} rad/s)" in model.describe()
    path = str(tmp_path / "m.npz")
    models.save_for_log(path, model, log, rows_used=1, seed=0, fit=summary)
    loaded, meta = models.load(path)
    assert meta["model"]["params"]["velocity"]["v0"] == model.v0_ and loaded.v0_ == model.v0_
    np.testing.assert_array_equal(loaded.predict(sig)[0], model.predict(sig)[0])


def test_velocity_input_options(files, tmp_path):
    linear, scaled = tmp_path / "linear.npz", tmp_path / "scaled.npz"
    assert run("train-base", files["base"], "-o", linear, "--steps", 20, "--velocity-input", "linear", "--arch", "mlp",
               "-q").exit_code == 0
    assert run("train-base", files["base"], "-o", scaled, "--steps", 20, "--velocity-scale", 0.01, "--arch", "mlp",
               "-q").exit_code == 0
    model, meta = models.load(str(linear))
    assert "velocity" not in meta["model"]["params"] and model.v0_ is None
    assert meta["provenance"]["job"]["options"]["velocity_input"] == "linear"
    model, meta = models.load(str(scaled))
    assert meta["model"]["params"]["velocity"] == {"transform": "asinh", "scale": 0.01, "v0": 0.01}
    sig = load(files["base"]).signals
    np.testing.assert_allclose(model._features(sig)[1], np.arcsinh(sig["qd"] / 0.01))
    # the residual network has no velocity input and no transform
    adapted, _ = learning.adapt(model, load(files["adapt"]), epochs=2, seed=0, val_fraction=0)
    assert adapted.add.velocity_scale is None and "velocity" not in adapted.add.get_params()
    with pytest.raises(ValueError):
        MLPFriction(velocity_scale=-1.0)


def test_asinh_velocity_input_resolves_slow_speeds():
    # slow levels below the Stribeck velocity (0.04) crowd around 0 in standardised qd; the
    # asinh input spreads them apart, so the network fits the jump at zero velocity better
    levels = (0.005, 0.01, 0.02, 0.05, 0.1, 0.2, 0.4)
    log = logs.from_table(motion_log(levels, seed=5, seconds=3.0), name="slow")
    sig = log.signals
    slow = (sig["qd"] != 0) & (np.abs(sig["qd"]) < 0.04)
    err = {}
    for how in learning.VELOCITY_INPUTS:
        model, _ = learning.train_base(log, arch="mlp", steps=3000, seed=0, velocity_input=how)
        err[how] = np.mean(np.abs(model.predict(sig)[0] - sig["tau_f_true"])[slow])
    assert err["asinh"] < err["linear"], err


def test_nnacm_betas_are_the_direction_terms(files):
    model, _ = learning.train_base(load(files["base"]), arch="nnacm", steps=300, seed=0)
    b1, b2 = model.betas()
    assert f"beta1 {b1:.4g} Nm, beta2 {b2:.4g} Nm" in model.describe()
    sig = {"qd": np.array([0.1, 0.1, -0.1]), "tau_g": np.zeros(3)}
    zero = model.predict(sig)[0]
    w = model.net_.weights[-1]
    w[0, -2:] = 0                                       # switch the direction terms off
    np.testing.assert_allclose(zero - model.predict(sig)[0], [b1, b1, b2], rtol=1e-4, atol=1e-4)


def test_selmic_layer_has_sigmoid_and_jump_units():
    model = SelmicFriction()
    net = model.new_network()
    (units, act), = net.hidden
    assert units == 30
    assert [(n, type(a).__name__) for n, a in act.parts] == [(20, "Sigmoid"), (10, "Jump")]
    assert list(act.parts[1][1].ks) == list(range(1, 11))


def test_predict_is_chunked_and_threaded_consistently(files):
    log = load(files["base"])
    model, _ = learning.train_base(log, steps=100, seed=0, bristles="off")   # rows independent of each other
    rng = np.random.default_rng(0)
    n = 200_000
    sig = {"t": np.arange(n) * 1e-3, "qd": rng.uniform(-0.4, 0.4, n), "tau_g": rng.uniform(-30, 30, n)}
    whole = model.predict(sig)[0]
    part = model.predict({k: v[12345:23456] for k, v in sig.items()})[0]
    np.testing.assert_allclose(part, whole[12345:23456], rtol=1e-6, atol=1e-6)
    for threads in (1, 3):   # every row once, whichever thread computes it: the same bits
        with prediction_threads(threads):
            assert np.array_equal(model.predict(sig)[0], whole)


def test_predict_in_chunks_covers_every_row_once():
    for n in (0, 1, PREDICT_CHUNK - 1, 5 * PREDICT_CHUNK + 3):
        for threads in (1, 2, 3):
            seen = np.zeros(n, dtype=int)

            def run(part):
                for start, stop in part:
                    assert 0 < stop - start <= PREDICT_CHUNK
                    seen[start:stop] += 1

            with prediction_threads(threads):
                predict_in_chunks(n, run)
            assert (seen == 1).all()


# ---------------------------------------------------------------------------- train-base CLI


def test_train_base_cli(files, tmp_path):
    out = tmp_path / "nn.npz"
    result = run("train-base", files["base"], "-o", out, "--steps", 400, "--hidden", "12,12", "--seed", 1, "--arch", "mlp")
    assert result.exit_code == 0, result.stderr
    assert result.stdout == ""
    assert "friction MAE [Nm]: training" in result.stderr and "validation" in result.stderr
    model, meta = models.load(str(out))
    assert meta["kind"] == "mlp" and meta["provenance"]["job"]["options"]["seed"] == 1
    assert meta["provenance"]["job"]["options"]["hidden"] == [12, 12]
    assert [n for n, _ in model.hidden] == [12, 12]
    assert meta["fit"]["val"]["n"] > 0


def test_train_base_json(files, tmp_path):
    result = run("train-base", files["base"], "-o", tmp_path / "nn.npz", "--steps", 50, "--json", "-q",
                 "--arch", "selmic", "--batch-size", 64)
    assert result.exit_code == 0, result.stderr
    assert result.stderr == ""
    out = json.loads(result.stdout)
    assert out["kind"] == "selmic" and out["steps"] == 50 and out["velocity_groups"] == "levels"
    assert set(out["train"]) == {"mae", "rmse", "max", "n"}


def test_same_seed_same_bytes(files, tmp_path):
    paths = [tmp_path / f"{name}.npz" for name in ("a", "b", "c")]
    for path, seed in zip(paths, (5, 5, 6)):
        result = run("train-base", files["base"], "-o", path, "--steps", 120, "--seed", seed, "-q")
        assert result.exit_code == 0, result.stderr
    assert paths[0].read_bytes() == paths[1].read_bytes()
    assert paths[0].read_bytes() != paths[2].read_bytes()


def test_divergence_leaves_the_previous_model(files, tmp_path):
    out = tmp_path / "nn.npz"
    assert run("train-base", files["base"], "-o", out, "--steps", 20, "-q").exit_code == 0
    before = out.read_bytes()
    result = run("train-base", files["base"], "-o", out, "--steps", 300, "--lr", "1e30", "-q")
    assert result.exit_code == 5
    assert "not finite" in result.stderr and "Traceback" not in result.stderr
    assert out.read_bytes() == before


def test_bad_hidden_is_a_usage_error(files, tmp_path):
    result = run("train-base", files["base"], "-o", tmp_path / "m.npz", "--hidden", "30,x")
    assert result.exit_code == 2 and "layer sizes" in result.stderr


# ---------------------------------------------------------------------------- adapt


@pytest.fixture(scope="module")
def base_model(files):
    path = files["dir"] / "nn_base.npz"
    # the network alone: on these logs the LuGre static curve (the default's prior) is the friction itself
    assert run("train-base", files["base"], "-o", path, "--steps", 1500, "--no-prior", "-q").exit_code == 0
    return path


def test_adapt_learns_the_residual(files, base_model, tmp_path):
    out = tmp_path / "adapted.npz"
    result = run("adapt", base_model, files["adapt"], "-o", out, "--epochs", 60)
    assert result.exit_code == 0, result.stderr
    assert "base" in result.stderr and "adapted" in result.stderr
    adapted, meta = models.load(str(out))
    base, _ = models.load(str(base_model))
    assert meta["kind"] == "residual" and meta["model"]["children"]["base"]["kind"] == "dissipative"
    assert meta["provenance"]["base"]["kind"] == "dissipative"
    assert isinstance(adapted, ResidualFriction)
    # on a new log with the same shift, the adapted model errs no more than the base does without it
    assert mae(adapted, files["shifted"], moving=True) < mae(base, files["base2"], moving=True)
    assert mae(adapted, files["shifted"]) < mae(base, files["shifted"])
    sig = load(files["shifted"]).signals
    np.testing.assert_allclose(adapted.predict(sig)[0], adapted.on_base(sig, base.predict(sig)[0]))
    assert adapted.add.inputs == ("tau_g", "sign(qd)")
    assert adapted.add.history_train_.size == 60


def test_adapt_a_lugre_base(files, tmp_path):
    lugre = pytest.importorskip("fricli.models.lugre")
    log = load(files["base"])
    model = lugre.LuGreModel(fc=5, fs=7, vs=0.04, delta=1.0, fv=10, kc=0.04, ks=0.05, sigma0=1e4, sigma1=5)
    path = tmp_path / "lugre.npz"
    models.save_for_log(str(path), model, log, rows_used=len(log))
    out = tmp_path / "adapted.npz"
    result = run("adapt", path, files["adapt"], "-o", out, "--epochs", 60, "--json", "-q")
    assert result.exit_code == 0, result.stderr
    summary = json.loads(result.stdout)
    assert summary["moving"]["mae"] < 0.5 * summary["base_moving"]["mae"]
    adapted, meta = models.load(str(out))
    assert meta["model"]["children"]["base"]["kind"] == "lugre"
    assert mae(adapted, files["shifted"]) < mae(model, files["shifted"])
    # this base is the true friction of the logs, so NN_add must have learned the shift itself
    sig = load(files["shifted"]).signals
    moving = sig["qd"] != 0
    shift = (static_friction(sig["qd"], sig["tau_g"], shift=True) - static_friction(sig["qd"], sig["tau_g"]))[moving]
    learned = adapted.add.predict(sig)[0][moving]
    assert np.mean(np.abs(learned - shift)) < 0.1 * np.mean(np.abs(shift))


def test_adapt_an_adapted_model(files, base_model, tmp_path):
    once, twice = tmp_path / "once.npz", tmp_path / "twice.npz"
    # --val-fraction 0: the residual is kept unchecked, whatever 5 epochs gave
    for base, out in ((base_model, once), (once, twice)):
        assert run("adapt", base, files["adapt"], "-o", out, "--epochs", 5, "--val-fraction", 0, "-q").exit_code == 0
    model, meta = models.load(str(twice))
    assert meta["model"]["children"]["base"]["kind"] == "residual"
    assert model.predict(load(files["adapt"]).signals)[0].shape == (len(load(files["adapt"])),)


def test_adapt_max_seconds_uses_the_start_of_the_log(files, base_model, tmp_path):
    result = run("adapt", base_model, files["adapt"], "-o", tmp_path / "a.npz", "--max-seconds", 30,
                 "--epochs", 3, "--json", "-q")
    assert result.exit_code == 0, result.stderr
    summary = json.loads(result.stdout)
    rate = 50.0
    assert summary["rows_used"] == int(30 * rate) + 1
    assert summary["seconds_used"] == pytest.approx(30.0)


def test_adapt_needs_both_directions(files, base_model, tmp_path):
    # the adapt log's first 20 s (after 0.4 s of rest) move in the positive direction only
    result = run("adapt", base_model, files["adapt"], "-o", tmp_path / "a.npz", "--max-seconds", 15)
    assert result.exit_code == 6
    assert "only in the positive direction" in result.stderr


def test_adapt_leaves_rest_out(files, base_model):
    model, _ = models.load(str(base_model))
    log = load(files["adapt"])
    _, summary = learning.adapt(model, log, epochs=2)
    moving = int(np.count_nonzero(np.abs(log.signals["qd"]) >= summary["min_speed"]))
    assert summary["train_rows"] + summary["val_rows"] == moving < len(log)


def test_adapt_refuses_a_log_in_other_units(files, base_model, tmp_path):
    table = motion_log((0.1,), seconds=5)
    units = dict(UNITS, q="m", qd="m/s", qdd="m/s^2", tau_m="N", tau_g="N", tau_f_true="N")
    linear = table_from_arrays({name: table.column(name).to_numpy() for name in table.column_names}, units)
    result = run("adapt", base_model, write(linear, tmp_path / "lin.parquet"), "-o", tmp_path / "a.npz")
    assert result.exit_code == 4 and "fitted in rad" in result.stderr


# ---------------------------------------------------------------------------- real and sample data


def test_train_base_on_emps(tmp_path):
    path = shared_data("emps/emps.parquet")
    result = run("train-base", path, "-o", tmp_path / "emps.npz", "--steps", 300, "--no-gravity", "--no-dynamics",
                 "--json", "-q")
    assert result.exit_code == 0, result.stderr
    out = json.loads(result.stdout)
    model, meta = models.load(str(tmp_path / "emps.npz"))
    assert meta["axis"] == "linear" and meta["units"]["tau"] == "N"
    assert out["velocity_groups"] in ("levels", "moving")
    # better than the best constant (the EMPS target also holds the inertial force: no tau_dyn)
    target = logs.friction_target(logs.load_log(str(path), zero=("tau_g", "tau_dyn")).signals)
    assert out["log"]["mae"] < np.mean(np.abs(target - np.median(target)))


@pytest.mark.slow
def test_sample_data_adapted_beats_base():
    for name in ("joint2_base", "joint2_adapt", "joint2_extended_asym"):
        if not (SAMPLE / f"{name}.parquet").exists():
            pytest.skip("sample data absent")
    base_log = load(SAMPLE / "joint2_base.parquet")
    model, _ = learning.train_base(base_log, steps=5000, seed=0)
    adapted, _ = learning.adapt(model, load(SAMPLE / "joint2_adapt.parquet"), seed=0)
    for load_kind in ("asym", "sym"):
        ext = SAMPLE / f"joint2_extended_{load_kind}.parquet"
        assert mae(adapted, ext) < mae(model, ext)
        # the bar (at most half of NN_base's error), on the rows in motion: a map of
        # (tau_g, qd) cannot know the friction the bristles hold at rest
        assert mae(adapted, ext, moving=True) < 0.5 * mae(model, ext, moving=True)


def test_model_to_stdout(files):
    result = CliRunner().invoke(cli, ["train-base", str(files["base"]), "-o", "-", "--steps", "20", "-q"])
    assert result.exit_code == 0, result.stderr
    meta, arrays = modelfile.loads(result.stdout_bytes)
    assert meta["kind"] == "dissipative" and "W0" in arrays
    clash = run("train-base", files["base"], "-o", "-", "--json")
    assert clash.exit_code == 2 and "stdout" in clash.stderr


# ---------------------------------------------------------------------------- continuous excitation


def harmonic_motion(seed=0, rate=100.0, seconds=40.0):
    """(rng, signals t, q, qd, qdd, tau_g) of a sum of harmonics (no steady velocity level)."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(seconds * rate)) / rate
    qd = sum(a * np.sin(2 * np.pi * f * t + p) for a, f, p in
             zip((0.4, 0.25, 0.15), (0.11, 0.23, 0.41), rng.uniform(0, 2 * np.pi, 3)))
    q = np.cumsum(qd) / rate
    return rng, {"t": t, "q": q, "qd": qd, "qdd": np.gradient(qd, t), "tau_g": 30 * np.sin(2 * q + 0.3)}


def harmonic_log(seed=0, rate=100.0, seconds=40.0, residual=None, base=None, noise=0.2):
    """A sum of harmonics, friction static_friction plus noise; with ``base`` (a model) the
    friction is base's prediction plus ``residual(qd, tau_g)`` instead."""
    rng, sig = harmonic_motion(seed, rate, seconds)
    t, qd, g = sig["t"], sig["qd"], sig["tau_g"]
    f = static_friction(qd, g) if base is None else base.predict(sig)[0]
    if residual is not None:
        f = f + residual(qd, g)
    cols = {**sig, "tau_m": g + f + rng.normal(0, noise, t.size), "tau_f_true": f}
    return no_inertia(table_from_arrays(cols, UNITS))   # no inertia torque in tau_m


@pytest.fixture(scope="module")
def harmonic(tmp_path_factory):
    d = tmp_path_factory.mktemp("harmonic")
    path = write(harmonic_log(seed=5), d / "harmonic.parquet")
    model, summary = learning.train_base(load(path), steps=300, seed=0)
    base = str(d / "base.npz")
    models.save_for_log(base, model, load(path), rows_used=1, seed=0, fit=summary)
    return {"log": path, "base": base, "model": model, "summary": summary, "dir": d}


def test_train_base_on_continuous_excitation_uses_the_moving_rows_in_time_blocks(harmonic):
    sig, summary = load(harmonic["log"]).signals, harmonic["summary"]
    assert summary["velocity_groups"] == "moving"
    sel = training_data.select(sig["qd"], rng=np.random.default_rng(0), keep=metrics.in_motion(sig["qd"], training_data.LOW),
                               moving=metrics.in_motion(sig["qd"]))
    # the folds validate on these blocks and others; the model written trains on all of the rows
    assert sel.mode == "moving" and sel.train.size + sel.val.size == summary["train_rows"]
    assert metrics.in_motion(sig["qd"])[np.concatenate([sel.train, sel.val])].all()
    assert np.intersect1d(sel.train, sel.val).size == 0
    # the validation rows lie in two of ten blocks of time, none of them trained on
    cuts = np.linspace(0, sig["qd"].size, training_data.PIECES + 1).astype(int)
    block = np.searchsorted(cuts, np.arange(sig["qd"].size), side="right") - 1
    assert np.unique(block[sel.val]).size == 2 and not np.isin(block[sel.train], block[sel.val]).any()
    # it learned the friction: far below the friction's own size on the rows in motion
    target, moving = logs.friction_target(sig), metrics.in_motion(sig["qd"])
    assert summary["moving"]["rmse"] < 0.3 * np.sqrt(np.mean(target[moving] ** 2))


def test_train_base_says_it_trains_on_the_moving_rows(harmonic, tmp_path):
    result = run("train-base", harmonic["log"], "-o", tmp_path / "m.npz", "--steps", 20)
    assert result.exit_code == 0, result.stderr
    assert "rows in motion" in result.stderr and "no steady velocity levels" in result.stderr
    assert "one network on all of them" in result.stderr
    assert "the 10 time blocks held out by halves from 2 networks, each trained on the other half" in result.stderr
    assert len(models.load(str(tmp_path / "m.npz"))[0].nets_) == 1
    five = run("train-base", harmonic["log"], "-o", tmp_path / "five.npz", "--steps", 20, "--ensemble", 5, "--json")
    assert five.exit_code == 0, five.stderr
    out = json.loads(five.stdout)
    assert out["cross_validation"]["folds"] == 5 and "held_out_choice" not in out
    assert "the mean of 5 networks, each validated on 2 of 10 time blocks" in five.stderr
    assert len(models.load(str(tmp_path / "five.npz"))[0].nets_) == 5
    # more networks than folds of time blocks: one line on stderr, exit code 6 (DATA)
    many = run("train-base", harmonic["log"], "-o", tmp_path / "many.npz", "--steps", 20, "--ensemble", 6)
    assert many.exit_code == 6 and "needs 6 folds of time blocks" in many.stderr and "Traceback" not in many.stderr
    levels = run("train-base", write(motion_log(LEVELS, seed=1), tmp_path / "b.parquet"), "-o", tmp_path / "b.npz",
                 "--steps", 20)
    assert "velocity levels" in levels.stderr and "rows in motion" not in levels.stderr


def test_adapt_keeps_the_base_when_the_residual_is_noise(harmonic, tmp_path):
    noise = write(harmonic_log(seed=6, base=harmonic["model"], noise=0.5), tmp_path / "noise.parquet")
    result = run("adapt", harmonic["base"], noise, "-o", tmp_path / "a.npz", "--epochs", 40, "--json")
    assert result.exit_code == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["adapted"] is False and out["kind"] == "dissipative" and out["velocity_groups"] == "moving"
    assert "the base model is kept" in result.stderr and "(the base model unchanged)" in result.stderr
    held = out["held_out"]   # the message names what failed
    if held["adapted_rmse"] >= held["base_rmse"]:
        assert "the residual network makes the held-out rows worse" in result.stderr
    else:
        names = ("later half", "earlier half", "slower half", "faster half")
        for name, r in zip(names, held["half_ratios"] + held["speed_ratios"]):
            assert (f"{name} x{r:.4f}" in result.stderr) == (r > 1 - learning.MIN_GAIN), name
    written, meta = models.load(str(tmp_path / "a.npz"))
    assert meta["kind"] == "dissipative" and meta["fit"]["adapted"] is False
    held = meta["fit"]["held_out"]
    assert held["helps"] is False and held["pieces"] == training_data.PIECES
    sig = load(noise).signals
    np.testing.assert_array_equal(written.predict(sig)[0], harmonic["model"].predict(sig)[0])


def test_adapt_keeps_a_residual_that_helps(harmonic, tmp_path):
    shifted = write(harmonic_log(seed=7, base=harmonic["model"], residual=lambda v, g: np.sign(v) * (1.5 + 0.04 * g)),
                    tmp_path / "shifted.parquet")
    result = run("adapt", harmonic["base"], shifted, "-o", tmp_path / "a.npz", "--epochs", 40, "--json")
    assert result.exit_code == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["adapted"] is True and out["kind"] == "residual"
    assert out["held_out"]["adapted_rmse"] < 0.5 * out["held_out"]["base_rmse"]
    assert "the residual network is kept" in result.stderr
    assert models.load(str(tmp_path / "a.npz"))[1]["fit"]["adapted"] is True


class _Curve:
    """A stand-in network whose validation loss, one record per 10 steps, is (i - m)^2 + 1 with m
    set by the first time block it validates on; it notes the rows it trained and validated on."""

    made = []

    def __init__(self, steps):
        self.steps = steps

    def fit(self, sig, target, val_sig, val_target, *, rng, on_eval=None, stop=None):
        first = int(training_data.time_block(1000)[int(val_sig["t"][0])])
        m = {0: 1, 2: 1}.get(first, 8)
        self.history_val_ = (np.arange(self.steps // 10) - m) ** 2 + 1.0
        self.y_scale_, self.eval_every_ = 1.0, 10
        self.best_step_ = 10 * (int(np.argmin(self.history_val_)) + 1)
        self.rows = (sig["t"].astype(int), val_sig["t"].astype(int))
        _Curve.made.append(self)
        return self


def test_trainings_side_by_side_stop_together_when_one_fails():
    """A failure (or an interruption) in one training stops the others at their next loss record:
    a command interrupted while two networks train does not wait for the other's steps."""
    import threading
    import time

    stop = threading.Event()
    report = learning.shared_progress(None, 100, 2, stop)
    records = []

    def fails():
        time.sleep(0.05)
        raise ValueError("diverged")

    def trains():
        for step in range(10 ** 6):   # far longer than the test allows, unless stopped
            records.append(step)
            report[1](step, 100, 0.0, None)
            time.sleep(0.001)

    start = time.perf_counter()
    with pytest.raises(ValueError, match="diverged"):
        learning.run_parallel([fails, trains], stop)
    assert stop.is_set() and len(records) < 10 ** 6 and time.perf_counter() - start < 60


def test_cross_validated_steps_come_from_the_mean_validation_curve_of_the_folds(monkeypatch):
    from fricli.numerics import forked

    monkeypatch.setattr(forked, "AVAILABLE", False)   # the stand-ins, in this process
    _Curve.made.clear()
    n = 1000
    sig = {"t": np.arange(n, dtype=float)}
    blocks = training_data.time_block(n)
    drawn = training_data.time_folds(0.2, np.random.default_rng(3))
    assert len(drawn) == 5 and np.array_equal(np.sort(np.concatenate(drawn)), np.arange(training_data.PIECES))
    folds = [np.array([k, k + 1]) for k in range(0, training_data.PIECES, 2)]
    cv = learning.cross_validated_steps(_Curve, 100, sig, np.zeros(n), np.arange(n), blocks, folds,
                                        np.random.default_rng(0))
    assert sorted(map(id, cv["models"])) == sorted(map(id, _Curve.made))   # trained side by side
    # every fold validates on its own blocks and trains on all the others
    for fold, held in zip(cv["models"], folds):
        train, val = fold.rows
        assert np.array_equal(val, np.flatnonzero(np.isin(blocks, held)))
        assert np.array_equal(train, np.flatnonzero(~np.isin(blocks, held)))
    # two folds are best at step 20, three at step 90; the mean curve (i - m)^2 is least at the
    # mean m = 5.2, record 5, step 60: the step of no single fold
    assert cv["folds"] == 5 and sorted(cv["fold_best_steps"]) == [20, 20, 90, 90, 90]
    pooled_least = np.mean((5 - np.array([1, 1, 8, 8, 8])) ** 2) + 1
    assert cv["step"] == 60 and cv["held_out_rmse"] == pytest.approx(np.sqrt(pooled_least))


def test_train_base_on_continuous_excitation_stops_every_fold_at_the_mean_curves_step(harmonic):
    model, summary = learning.train_base(load(harmonic["log"]), steps=300, seed=0, ensemble=5)
    cv = summary["cross_validation"]
    assert cv["folds"] == len(model.nets_) == 5 and len(cv["fold_best_steps"]) == 5
    # the weights are those of the step chosen on the pooled curve (recorded as the model's
    # validation history), not each fold's own best
    assert summary["best_step"] == cv["step"] == model.eval_every_ * (int(np.argmin(model.history_val_)) + 1)
    assert cv["held_out_rmse"] == pytest.approx(model.y_scale_ * np.sqrt(model.history_val_.min()))
    # every selected row served for training (in four folds of five) and none is set apart
    assert summary["val_rows"] == 0 and model.n_train_ == summary["train_rows"]
    # the same seed gives the same networks, whichever thread or process trained which fold
    from fricli.numerics import forked

    forked_before, forked.AVAILABLE = forked.AVAILABLE, not forked.AVAILABLE and sys.platform.startswith("linux")
    try:
        again, again_summary = learning.train_base(load(harmonic["log"]), steps=300, seed=0, ensemble=5)
    finally:
        forked.AVAILABLE = forked_before
    for a, b in zip(model.nets_, again.nets_):
        np.testing.assert_array_equal(a.theta, b.theta)
    assert again_summary["cross_validation"] == cv and again_summary["prior"] == summary["prior"]


def test_train_base_on_continuous_excitation_trains_one_network_at_the_held_out_step(harmonic):
    summary, model = harmonic["summary"], harmonic["model"]
    choice = summary["held_out_choice"]
    assert len(model.nets_) == 1 and "cross_validation" not in summary
    # one network on every selected row, stopped at the step least on the probe's held-out blocks
    assert summary["val_rows"] == 0 and model.n_train_ == summary["train_rows"]
    assert summary["best_step"] == choice["step"] == model.eval_every_ * (int(np.argmin(model.history_val_)) + 1)
    assert choice["held_out_rmse"] == pytest.approx(model.y_scale_ * np.sqrt(model.history_val_.min()))
    # two networks trained side by side on spawned generators: the same seed, the same network
    sig = load(harmonic["log"]).signals
    last, _ = learning.train_base(load(harmonic["log"]), steps=300, seed=0)
    np.testing.assert_array_equal(last.net_.theta, model.net_.theta)   # the same seed, the same network
    assert "prior" in summary and 0.0 <= summary["prior"]["blend"] <= 1.0
    assert np.isfinite(model.predict(sig)[0]).all()


def test_the_probe_in_a_child_process_gives_the_network_of_the_probe_in_a_thread(harmonic, monkeypatch):
    """The probe trains in a forked process where fricli can fork, else in a thread: the same
    bytes either way, the prior's share and the pre-sliding choice included."""
    from fricli.numerics import forked

    log = load(harmonic["log"])
    results = []
    for apart in (True, False):
        monkeypatch.setattr(forked, "AVAILABLE", apart and forked.AVAILABLE)
        results.append(learning.train_base(log, steps=300, seed=0))
    (a, sa), (b, sb) = results
    np.testing.assert_array_equal(a.net_.theta, b.net_.theta)
    np.testing.assert_array_equal(a.history_val_, b.history_val_)
    assert sa["held_out_choice"] == sb["held_out_choice"] and sa["prior"] == sb["prior"]
    assert sa["bristles"] == sb["bristles"] and sa["steps"] == sb["steps"]


def test_what_is_kept_does_not_depend_on_which_training_runs_ahead(harmonic, monkeypatch):
    """The model trains on until it has passed the probe's best record, so how far it ran depends on
    timing; its weights, recorded steps and losses do not: the same bytes either way."""
    import time

    from fricli.models.dissipative import DissipativeFriction

    fit = DissipativeFriction.fit
    results = []
    for late in ("probe", "model"):
        def delayed(self, *args, snapshots=False, _late=late, **kwargs):
            if (_late == "model") == snapshots:
                time.sleep(1.0)
            return fit(self, *args, snapshots=snapshots, **kwargs)

        monkeypatch.setattr(DissipativeFriction, "fit", delayed)
        model, _ = learning.train_base(load(harmonic["log"]), steps=600, seed=0)
        results.append((model.get_params(), model.get_arrays()))
    (pa, aa), (pb, ab) = results
    assert pa == pb and aa.keys() == ab.keys()
    for key in aa:
        np.testing.assert_array_equal(aa[key], ab[key])


def test_what_the_steps_after_training_load_is_loaded_while_the_probes_train(harmonic, monkeypatch):
    """The prior fit's imports run in this process after the model's training, while the probes
    train on: called once, here, and the same network."""
    import os

    calls = []
    monkeypatch.setattr(learning, "load_prior_fit", lambda: calls.append(os.getpid()))
    model, summary = learning.train_base(load(harmonic["log"]), steps=300, seed=0)
    assert calls == [os.getpid()]
    np.testing.assert_array_equal(model.net_.theta, harmonic["model"].net_.theta)
    learning.train_base(load(harmonic["log"]), steps=300, seed=0, prior=False)
    assert calls == [os.getpid()]      # without the prior there is nothing to load


def test_the_probes_stop_after_their_patience_and_the_model_at_their_pooled_best_record(harmonic, monkeypatch):
    """Two probes, each trained on one half of the time blocks and scored on the other, end once
    their held-out loss has not improved by 0.1 % over their patience (given, else
    PATIENCE_SHARE of the steps), or once the other has ended and they have recorded as many
    losses (the pooled curve, weighted by their held-out rows, ends there); the model and both
    probes keep their weights of the pooled curve's best record."""
    seen = {}
    chosen = learning.chosen_on_held_out

    def spy(new_model, steps, sig, target, splits, *args, **kwargs):
        model, probes, summary = chosen(new_model, steps, sig, target, splits, *args, **kwargs)
        # each probe's held-out loss with the weights it keeps, evaluated as its training did
        from fricli.numerics.nn.training import Evaluator

        losses = []
        for p, (_, val) in zip(probes, splits):
            limits, (p.v_max_, p.v_min_) = (p.v_max_, p.v_min_), (None, None)   # the inputs as training saw them
            x = np.ascontiguousarray(p._rows({k: v[val] for k, v in sig.items()}), dtype=p.net_.dtype)
            p.v_max_, p.v_min_ = limits
            t = np.ascontiguousarray((target[val] / p.y_scale_)[None, :], dtype=p.net_.dtype)
            losses.append(Evaluator(p.net_, x, t).sse() / t.size)
        seen.update(probes=probes, splits=splits, losses=losses)
        return model, probes, summary

    monkeypatch.setattr(learning, "chosen_on_held_out", spy)
    steps = 2000
    model, summary = learning.train_base(load(harmonic["log"]), steps=steps, seed=0, patience=40)
    probes, splits = seen["probes"], seen["splits"]
    assert len(probes) == summary["held_out_choice"]["folds"] == 2
    # the halves: every selected row held out by one probe, none by both, each trained on the rest
    held = [val for _, val in splits]
    assert not np.intersect1d(*held).size
    assert np.array_equal(np.union1d(*held), np.union1d(*splits[0]))
    for train, val in splits:
        assert not np.intersect1d(train, val).size
    patience = 40 // model.eval_every_
    own = []   # whether each probe ended on its own patience
    for probe in probes:
        history = probe.history_val_
        assert history.size < steps // model.eval_every_   # stopped early
        level, since = np.inf, 0   # the trainer's plateau rule over the recorded losses
        for k, loss in enumerate(history):
            if loss < level * (1 - 1e-3):
                level, since = loss, k
        own.append(history.size - 1 - since == patience)
    length = min(p.history_val_.size for p in probes)
    first = [p.history_val_.size == length for p in probes]
    # the probe that ended first ended on its patience; the other on it or on the first one's end
    assert any(o and f for o, f in zip(own, first)) and all(o or f or p.history_val_.size >= length
                                                             for o, f, p in zip(own, first, probes))
    pooled = np.average([p.history_val_[:length] for p in probes], axis=0, weights=[v.size for v in held])
    np.testing.assert_array_equal(model.history_val_, pooled)
    best = int(np.argmin(pooled))
    assert summary["best_step"] == (best + 1) * model.eval_every_
    assert summary["steps"] == length * model.eval_every_ and best * model.eval_every_ < summary["steps"] <= steps
    # the probes keep their weights of that record too (not their own best)
    for probe, loss in zip(probes, seen["losses"]):
        assert loss == pytest.approx(probe.history_val_[best], rel=1e-4)


def test_the_model_waits_one_record_past_the_probes_best_while_they_train(monkeypatch):
    """On a target that no function of the velocity gives (a level drifting in time) the probes'
    held-out best comes early: the model stops training one record past it and waits there,
    while the probes train on for their patience. The probes are slowed (2 ms a record), so that
    the model waits for them however the host shares its cores (on a loaded host they ran ahead
    of it, and it had nothing to wait for)."""
    rng, sig = harmonic_motion(7, 100.0, 40.0)
    target = 3.0 * np.sin(2 * np.pi * sig["t"] / 7.0)
    seen = {"model": []}
    chosen = learning.chosen_on_held_out

    def spy(new_model, steps, *args, **kwargs):
        made = []

        def watched(n_steps):
            net = new_model(n_steps)
            if not made:   # the first network made is the model: its reports are its steps
                fit = net.fit

                def fit_seen(*a, on_eval=None, **kw):
                    def report(step, *rest):
                        seen["model"].append(step)
                        return on_eval(step, *rest)
                    return fit(*a, on_eval=report, **kw)
                net.fit = fit_seen
            else:          # the probes slowed down, so that the model reaches their best first on any load
                fit_probe = net.fit

                def fit_slowed(*a, on_eval=None, fit_probe=fit_probe, **kw):
                    def report(*args):
                        time.sleep(0.002)
                        return on_eval(*args)
                    return fit_probe(*a, on_eval=report, **kw)
                net.fit = fit_slowed
            made.append(net)
            return net

        model, probes, summary = chosen(watched, steps, *args, **kwargs)
        seen.update(probes=probes, summary=summary)
        return model, probes, summary

    monkeypatch.setattr(learning, "chosen_on_held_out", spy)
    shown = []
    model, summary = learning.train(sig, target, name="x", units={"tau": "Nm", "qd": "rad/s"},
                                    rng=np.random.default_rng(0), steps=2000, patience=400,
                                    on_eval=lambda step, *_: shown.append(step))
    every, best = model.eval_every_, summary["held_out_choice"]["step"]
    probe_steps = max(p.history_val_.size for p in seen["probes"]) * every
    # the model: one record past the best at most, while the probes trained on
    assert max(seen["model"]) <= best + 2 * every < probe_steps
    from fricli.numerics import forked

    if forked.AVAILABLE:   # the one progress report follows the probes while the model waits, never back
        assert shown == sorted(shown) and max(shown) > best + 2 * every
    assert summary["best_step"] == best


@pytest.mark.parametrize("moving_until", [4.0, 12.0])
def test_a_half_of_the_time_blocks_without_motion_scores_no_choice(moving_until, monkeypatch):
    """A log that moves in its first seconds only: a probe whose half of the time blocks leaves
    fewer than MIN_RUN rows in motion to train or to score on is not trained; with no probe left,
    the one network trains on every row without a held-out choice (as with --val-fraction 0)."""
    rng, sig = harmonic_motion(5, 100.0, 40.0)
    rest = sig["t"] > moving_until
    sig["qd"][rest], sig["qdd"][rest], sig["q"][rest] = 0.0, 0.0, sig["q"][~rest][-1]
    sig["tau_dyn"] = np.zeros_like(sig["t"])
    target = static_friction(sig["qd"], sig["tau_g"]) + rng.normal(0, 0.2, sig["t"].size)
    seen = []
    chosen = learning.chosen_on_held_out

    def spy(new_model, steps, sig_, target_, splits, *args, **kwargs):
        seen.append([(train.size, val.size) for train, val in splits])
        return chosen(new_model, steps, sig_, target_, splits, *args, **kwargs)

    monkeypatch.setattr(learning, "chosen_on_held_out", spy)
    for seed in range(4):
        model, summary = learning.train(sig, target, name="x", units={"tau": "Nm", "qd": "rad/s"},
                                        rng=np.random.default_rng(seed), steps=300)
        assert np.isfinite(model.predict(sig)[0]).all()
        if "held_out_choice" in summary:
            assert summary["held_out_choice"]["folds"] == len(seen[-1]) >= 1
            assert min(min(pair) for pair in seen[-1]) >= training_data.MIN_RUN
            assert np.isfinite(summary["held_out_choice"]["held_out_rmse"])
        else:
            assert summary["val_rows"] == 0
    # motion in the first block alone: no half of the blocks can both train and score
    assert moving_until > 10 or not seen


def test_a_best_step_early_in_the_planned_steps_is_a_warning_when_training_stopped_early(tmp_path):
    """The Franka joint's slow file (first 60 %): the probe's held-out loss is least within the first
    1 % of the 7,000 steps, and the probe stops a quarter of them later; the warning counts the
    steps planned, not the steps run."""
    d = np.genfromtxt(shared_data("franka") / "joint2_slow.csv", delimiter=",", names=True, usecols=(0, 1, 2, 4))
    keep = d["time"] < d["time"][0] + 0.6 * (d["time"][-1] - d["time"][0])
    cols = {"t": d["time"][keep], "q": d["q2"][keep], "qd": d["dq2"][keep], "tau_m": d["q2_tau_J_compensate"][keep]}
    log = write(table_from_arrays(cols, {k: UNITS[k] for k in cols}), tmp_path / "slow.parquet")
    res = CliRunner().invoke(cli, ["train-base", log, "-o", str(tmp_path / "nn.npz"), "--no-gravity",
                                   "--no-dynamics", "--json", "-q"])
    assert res.exit_code == 0, res.stderr
    out = json.loads(res.stdout)
    assert out["steps"] < out["max_steps"] == 7000 and out["best_step"] <= 70
    assert f"least at step {out['best_step']} of 7000: training learned nothing" in res.stderr


def test_a_long_stepped_log_trains_on_its_plateaus(tmp_path):
    """Ten minutes of velocity steps lie too close together for the level histogram (no levels):
    train-base then trains on the steady rows, not on the ramps between them, and stays as good
    as the LuGre model on the log."""
    log = str(tmp_path / "long.parquet")
    runner = CliRunner()
    for args in (["simulate", "--scenario", "extended", "--duration", "600", "--joint", "2", "--friction-state", "base",
                  "--seed", "2", "-o", log, "-q"], ["identify", log, "-o", str(tmp_path / "lugre.npz"), "-q"]):
        assert runner.invoke(cli, args).exit_code == 0
    res = runner.invoke(cli, ["train-base", log, "-o", str(tmp_path / "nn.npz"), "--json", "-q"])
    assert res.exit_code == 0, res.output
    summary = json.loads(res.stdout)
    assert summary["velocity_groups"] == "moving" and summary["plateaus"] is True
    data = logs.from_table(logs.read_table(log)[0], name=log)
    target = logs.friction_target(data.signals)
    mae = {name: float(np.mean(np.abs(models.load(str(tmp_path / f"{name}.npz"))[0].predict(data.signals)[0] - target)))
           for name in ("nn", "lugre")}
    assert mae["nn"] <= 1.1 * mae["lugre"], mae
    res = runner.invoke(cli, ["adapt", str(tmp_path / "lugre.npz"), log, "-o", str(tmp_path / "a.npz"), "--epochs", "1"])
    assert res.exit_code == 0 and "--max-seconds 60 adapts on the first minute of the 600 s" in res.stderr, res.output


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="the probes train in child processes on Linux")
def test_a_probe_process_killed_while_the_model_waits_ends_the_training_with_an_error(monkeypatch):
    """The model waits for the probes' records; the probes' processes killed outright at the
    model's first record record nothing more: after PROBE_SILENCE without a record the model
    trains on, once, and the training ends with the children's failure instead of waiting for good."""
    import os
    import signal
    import time

    from fricli.fitting import heldout
    from fricli.models.dissipative import DissipativeFriction

    monkeypatch.setattr(heldout, "PROBE_SILENCE", 1.0)
    fit, me = DissipativeFriction.fit, os.getpid()

    def fit_killing(self, sig, target, val_sig=None, val_target=None, *, on_eval=None, **kwargs):
        def report(*args):
            if os.getpid() == me:   # the model, in this process: its probes are this process's children
                with open(f"/proc/{me}/task/{me}/children") as f:
                    for pid in f.read().split():
                        os.kill(int(pid), signal.SIGKILL)
            return on_eval(*args)
        return fit(self, sig, target, val_sig, val_target, on_eval=report if val_sig is None else on_eval, **kwargs)

    monkeypatch.setattr(DissipativeFriction, "fit", fit_killing)
    rng, sig = harmonic_motion(7, 100.0, 40.0)
    target = 3.0 * np.sin(2 * np.pi * sig["t"] / 7.0)
    start = time.monotonic()
    with pytest.raises(RuntimeError, match="ended without a result"):
        learning.train(sig, target, name="x", units={"tau": "Nm", "qd": "rad/s"},
                       rng=np.random.default_rng(0), steps=1000, patience=500)
    assert time.monotonic() - start < 60
