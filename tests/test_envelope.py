"""The training envelope: recorded in every model file, reported by predict, estimate-ext,
evaluate, report and adapt."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import invoke as run, no_inertia, write
from fricli import models
from fricli.core import logs, modelfile
from fricli.core.envelope import Envelope
from fricli.core.logs import table_from_arrays

UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "tau_m": "Nm", "tau_g": "Nm", "tau_ext": "Nm"}


def uniform_log(seed=0, n=20000, speed=1.0):
    """qd and tau_g uniform over a rectangle (every grid cell covered), friction 5 sign(qd) + 10 qd."""
    rng = np.random.default_rng(seed)
    qd = speed * rng.uniform(-0.5, 0.5, n)
    g = rng.uniform(-30, 30, n)
    t = np.arange(n) * 0.01
    f = 5 * np.sign(qd) + 10 * qd
    cols = {"t": t, "q": np.cumsum(qd) * 0.01, "qd": qd, "tau_m": g + f + rng.normal(0, 0.1, n), "tau_g": g,
            "tau_ext": np.zeros(n)}
    return no_inertia(table_from_arrays(cols, UNITS))   # no inertia torque in tau_m


def test_outside_is_the_cell_rule():
    """``outside`` counts edges by comparison: the same rows as the definition (a row's cell by
    searchsorted on the inner edges, plus the ranges), on bin edges, NaN, infinities, an input
    the log lacks, a constant input and a sparse three-input grid."""
    rng = np.random.default_rng(3)
    fit = {"qd": rng.normal(0, 1, 400) * rng.uniform(0, 1, 400) ** 4, "tau_g": rng.uniform(-5, 20, 400),
           "temp": np.full(400, 40.0)}
    for inputs in ({"qd", "tau_g", "temp"}, {"qd", "tau_g"}, {"tau_g"}):
        env = Envelope.fit(fit, inputs)
        n = 3000
        probe = {"qd": rng.normal(0, 1.2, n), "tau_g": rng.uniform(-8, 24, n), "temp": rng.choice([39.0, 40.0], n)}
        edges = [env._edges(i) for i in range(len(env.inputs))]
        for i, name in enumerate(env.inputs):   # rows exactly on edges and range ends
            k = rng.integers(0, n, 300)
            probe[name][k] = rng.choice(np.r_[edges[i], env.lo[i], env.hi[i]], 300)
        probe["qd"][:5] = [np.nan, np.inf, -np.inf, 0.0, -0.0]
        cols = [probe[name] for name in env.inputs]
        inside = env.covered[env._cells(cols)]
        for i, x in enumerate(cols):
            inside &= (x >= env.lo[i]) & (x <= env.hi[i])
        assert env.outside(probe).tolist() == (~inside).tolist()
        assert 0 < inside.mean() < 1
        assert env.outside({k: v for k, v in probe.items() if k != "tau_g"}).tolist() == \
            env.outside({**probe, "tau_g": np.zeros(n)}).tolist()


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    d = tmp_path_factory.mktemp("env")
    train = write(uniform_log(0), d / "train.parquet")
    out = {"dir": d, "train": train, "inside": write(uniform_log(1, n=5000), d / "inside.parquet"),
           "fast": write(uniform_log(2, n=5000, speed=2.0), d / "fast.parquet"), "model": d / "m.npz"}
    assert run("train-base", train, "-o", out["model"], "--steps", 20, "-q").exit_code == 0
    return out


def test_fit_and_outside():
    sig = {"qd": np.array([-1.0, -0.5, 0.0, 0.5, 1.0]), "tau_g": np.array([-3.0, 0.0, 1.0, 2.0, 3.0])}
    env = Envelope.fit(sig, {"qd", "tau_g", "t"})
    assert env.inputs == ("qd", "tau_g") and env.lo.tolist() == [-1, -3] and env.hi.tolist() == [1, 3]
    assert not env.outside(sig).any()
    probe = {"qd": np.array([1.5, 0.0, -1.0, np.nan, -1.0]), "tau_g": np.array([0.0, 4.0, 3.0, 0.0, -3.0])}
    # outside the qd range, outside the tau_g range, inside both but in an empty cell, not a number, a training row
    assert env.outside(probe).tolist() == [True, True, True, True, False]
    again = Envelope.from_meta(json.loads(json.dumps(env.to_meta())))
    assert again.outside(probe).tolist() == env.outside(probe).tolist()
    for damage in ({"inputs": ["qd"], "min": [1.0], "max": [0.0], "bins": 8, "covered": []},
                   {"inputs": ["qd"], "min": [0.0], "max": [1.0], "bins": 8, "covered": [8]},
                   {"inputs": ["q"], "min": [0.0], "max": [1.0], "bins": 8, "covered": []}, {"inputs": 3}):
        with pytest.raises(ValueError):
            Envelope.from_meta(damage)


def test_every_model_file_records_its_envelope(files, tmp_path):
    _, meta = models.load(str(files["model"]))
    env = models.envelope(meta)
    assert env.inputs == ("qd", "tau_g") and env.covered.all()
    from fricli.models.lugre import LuGreModel

    lugre = LuGreModel(fc=5, fs=7, vs=0.04, delta=1.0, fv=10, kc=0.04, ks=0.05, sigma0=1e4, sigma1=5)
    path = str(tmp_path / "lugre.npz")
    models.save_for_log(path, lugre, logs.load_log(files["train"]), rows_used=1)
    env = models.envelope(models.load(path)[1])
    assert env.inputs == tuple(name for name in ("qd", "tau_g", "temp") if name in lugre.required_inputs())


def test_a_log_inside_reports_zero(files, tmp_path):
    result = run("predict", files["model"], files["train"], "-o", tmp_path / "p.parquet", "--json",
                 "--flag-extrapolation")
    assert result.exit_code == 0, result.stderr
    out = json.loads(result.stdout)
    assert out["extrapolation"] == {"rows": 0, "of": 20000, "share": 0.0}
    assert "0.0 % of the rows" in result.stderr
    assert not pq.read_table(tmp_path / "p.parquet").column("extrapolating").to_numpy().any()


@pytest.mark.parametrize("command", ["predict", "estimate-ext"])
def test_twice_the_speed_is_flagged_exactly(files, tmp_path, command):
    _, meta = models.load(str(files["model"]))
    lo, hi = meta["envelope"]["min"][0], meta["envelope"]["max"][0]
    qd = logs.load_log(files["fast"]).signals["qd"]
    expected = (qd < lo) | (qd > hi)
    assert 0.3 < expected.mean() < 0.7
    out = tmp_path / "p.parquet"
    result = run(command, files["model"], files["fast"], "-o", out, "--json", "--flag-extrapolation", "--batch-rows", 777)
    assert result.exit_code == 0, result.stderr
    report = json.loads(result.stdout)["extrapolation"]
    assert report["rows"] == int(expected.sum()) and report["share"] == pytest.approx(expected.mean())
    table = pq.read_table(out)
    assert table.column_names[-1] == "extrapolating"
    np.testing.assert_array_equal(table.column("extrapolating").to_numpy(zero_copy_only=False), expected)
    # without the column the rows are counted all the same (after each batch's prediction)
    result = run(command, files["model"], files["fast"], "-o", out, "--json", "--batch-rows", 777)
    assert json.loads(result.stdout)["extrapolation"] == report
    assert "extrapolating" not in pq.read_table(out).column_names


def test_evaluate_reports_the_share(files):
    result = run("evaluate", "--model", f"nn={files['model']}", "--log", f"in={files['inside']}",
                 "--log", f"fast={files['fast']}", "--json")
    assert result.exit_code == 0, result.stderr
    found = {r["log"]: r["extrapolation"] for r in json.loads(result.stdout)["results"]}
    assert found["in"]["share"] == 0.0 and found["fast"]["share"] > 0.3
    fast = found["fast"]
    assert (f"nn on fast: {100 * fast['share']:.1f} % of the rows ({fast['rows']:,} of {fast['of']:,}) lie outside"
            in result.stderr)
    # the evaluations with no row outside are one line, not one each (a six-joint arm and three models: 18)
    assert "nn on in:" not in result.stderr
    assert "no row lies outside the model's training envelope in the other 1 of the 2 evaluations" in result.stderr
    result = run("evaluate", "--model", f"nn={files['model']}", "--log", f"in={files['inside']}")
    assert result.stderr.strip().splitlines()[-1] == \
        "no row lies outside the model's training envelope"


def test_adapt_reports_the_share_outside_the_base(files, tmp_path):
    out = tmp_path / "a.npz"
    result = run("adapt", files["model"], files["fast"], "-o", out, "--epochs", 2, "--json")
    assert result.exit_code == 0, result.stderr
    share = json.loads(result.stdout)["outside_base_envelope"]
    assert share["share"] > 0.3 and "outside the base model's training envelope" in result.stderr
    assert models.load(str(out))[1]["envelope"] == models.load(str(files["model"]))[1]["envelope"]


def test_old_files_without_an_envelope(files, tmp_path):
    meta, arrays = modelfile.read(str(files["model"]))
    del meta["envelope"]
    old = tmp_path / "old.npz"
    modelfile.write(str(old), meta, arrays)
    result = run("predict", old, files["fast"], "-o", tmp_path / "p.parquet", "--json")
    assert result.exit_code == 0 and "extrapolation" not in json.loads(result.stdout)
    result = run("predict", old, files["fast"], "-o", tmp_path / "p.parquet", "--flag-extrapolation")
    assert result.exit_code == 4 and "no training envelope" in result.stderr
    meta["envelope"] = {"inputs": ["qd"], "min": [1.0], "max": [0.0], "bins": 8, "covered": []}
    modelfile.write(str(old), meta, arrays)
    result = run("predict", old, files["fast"], "-o", tmp_path / "p.parquet")
    assert result.exit_code == 4 and "damaged training envelope" in result.stderr


def test_report_shades_the_uncovered_region(files, tmp_path):
    from fricli.applying import report

    summary = report.write_report(str(files["model"]), logs.load_log(files["fast"]), str(tmp_path / "r"))
    assert summary["extrapolation"]["share"] > 0.3
    assert "outside the model's training envelope" in (tmp_path / "r" / "index.html").read_text()
    env = models.envelope(models.load(str(files["model"]))[1])
    v = np.array([-0.8, -0.4, 0.0, 0.4, 0.8])       # training speeds within +-0.5
    mask = env.covered_grid("qd", v, "tau_g", np.array([0.0, 40.0]))
    assert mask.tolist() == [[False, True, True, True, False], [False] * 5]
