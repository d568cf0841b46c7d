"""Bad input through every command that reads a log or a model file.

Each bad input gets its documented exit code (docs/exit-codes.md) and one line on stderr that
starts with ``fricli: error:``, no traceback, nothing on stdout, and every output that was
already there is left byte for byte as it was, with no temporary or lock file beside it.
Also: --drop-invalid, failed fits, a missing output folder, the output lock, --if-changed and
--debug.
"""

import json
import os
import pathlib

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import invoke as run, no_inertia
from fricli import models
from fricli.core import errors, jobs, logs, modelfile
from fricli.models.lugre import LuGreModel

PARAMS = dict(fc=5.0, fs=6.0, vs=0.05, delta=1.0, fv=10.0, kc=0.03, ks=0.04, sigma0=1e4, sigma1=5.0)
UNITS = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm", "tau_g": "Nm"}
PREVIOUS = {"out.npz": b"previous model", "out.parquet": b"previous table", "rep/index.html": b"previous report"}


def good_columns(n=4000, seed=0):
    """Constant-velocity sweeps at four speeds in both directions, then rest: enough for every
    command (identify needs steady samples at several speeds in both directions)."""
    t = np.arange(n) * 0.01
    seg = n // 10
    qd = np.concatenate([s * v * np.ones(seg) for v in (0.05, 0.1, 0.2, 0.4) for s in (1, -1)])
    qd = np.concatenate([qd, np.zeros(n - qd.size)])
    q = np.cumsum(qd) * 0.01
    tau_g = 10 * np.sin(q + 0.3)
    tau_f = LuGreModel(**PARAMS).predict({"t": t, "qd": qd, "tau_g": tau_g})[0]
    tau_m = tau_g + tau_f + np.random.default_rng(seed).normal(0, 0.05, n)
    return {"t": t, "q": q, "qd": qd, "qdd": np.gradient(qd, t), "tau_m": tau_m, "tau_g": tau_g}


def write_log(folder, name, columns, units=UNITS):
    path = folder / f"{name}.parquet"
    pq.write_table(no_inertia(logs.table_from_arrays(columns, units)), path)   # no inertia in tau_m
    return str(path)


def _bad_logs(folder):
    out = {"missing": str(folder / "no-such-log.parquet"), "folder": str(folder)}
    (folder / "text.parquet").write_text("t,tau_m\n0,1\n")
    out["not-parquet"] = str(folder / "text.parquet")
    (folder / "zero.parquet").write_bytes(b"")
    out["zero-bytes"] = str(folder / "zero.parquet")
    out["no-rows"] = write_log(folder, "no-rows", {k: v[:0] for k, v in good_columns().items()})

    def variant(name, change, units=UNITS):
        cols = good_columns()
        change(cols)
        out[name] = write_log(folder, name, cols, units)

    variant("no-tau_m", lambda c: c.pop("tau_m"))
    variant("no-t", lambda c: c.pop("t"))
    variant("no-motion-columns", lambda c: [c.pop(k) for k in ("q", "qd", "qdd")])
    variant("string-column", lambda c: c.update(tau_m=np.array([f"{x:.3f}" for x in c["tau_m"]])))
    variant("string-time", lambda c: c.update(t=pa.array(["2024-01-01"] * len(c["t"]))))

    def nan(c):
        c["tau_m"][[100, 200, 300]] = np.nan
        c["qd"][50] = np.inf
    variant("nan-inf", nan)
    variant("nulls", lambda c: c.update(tau_g=pa.array([None if i == 7 else x for i, x in enumerate(c["tau_g"])])))
    variant("t-decreasing", lambda c: c["t"].__setitem__(500, c["t"][498]))
    variant("t-duplicate", lambda c: c["t"].__setitem__(500, c["t"][499]))
    variant("unknown-unit", lambda c: None, dict(UNITS, tau_m="furlongs"))
    variant("bool-column", lambda c: c.update(qd=c["qd"] > 0))
    doubled = no_inertia(logs.table_from_arrays(good_columns(), UNITS))
    doubled = doubled.append_column(doubled.schema.field("tau_m"), doubled.column("tau_m"))
    pq.write_table(doubled, folder / "duplicate-column.parquet")
    out["duplicate-column"] = str(folder / "duplicate-column.parquet")
    variant("current-no-kt", lambda c: c.update(i_m=c.pop("tau_m") / 0.2), dict(UNITS, i_m="A"))
    variant("joint-2", lambda c: c.update(joint=np.full(len(c["t"]), 2)))
    linear = {"t": "s", "q": "m", "qd": "m/s", "qdd": "m/s^2", "tau_m": "N", "tau_g": "N"}
    variant("linear", lambda c: None, linear)
    two = {k: np.concatenate([v, v]) for k, v in good_columns().items()}
    two["joint"] = np.repeat([2, 4], len(two["t"]) // 2)
    out["two-joints"] = write_log(folder, "two-joints", two)
    # a valid log that holds too little to fit
    variant("one-direction", lambda c: c.update(qd=np.abs(c["qd"])))
    variant("standstill", lambda c: [c[k].__setitem__(slice(None), 0.0) for k in ("q", "qd", "qdd")])
    out["ten-rows"] = write_log(folder, "ten-rows", {k: v[np.r_[0:5, 400:405]] for k, v in good_columns().items()})
    return out


class Evil:
    """Unpickling this object makes a folder: proof that a pickle was (not) loaded."""

    def __init__(self, marker):
        self.marker = marker

    def __reduce__(self):
        return (os.mkdir, (self.marker,))


def _bad_models(folder, good):
    data = pathlib.Path(good).read_bytes()
    meta, arrays = modelfile.loads(data)
    out = {"missing": str(folder / "no-such-model.npz"), "folder": str(folder)}

    def put(name, content):
        (folder / name).write_bytes(content)
        out[name.split(".")[0]] = str(folder / name)

    put("truncated.npz", data[: len(data) // 2])
    put("text.npz", b"not a model at all")
    put("empty.npz", b"")
    np.savez(folder / "other.npz", x=np.ones(3))
    out["other"] = str(folder / "other.npz")
    put("version-99.npz", modelfile.dumps(dict(meta, format_version=99), arrays))
    put("unknown-kind.npz", modelfile.dumps(dict(meta, model={"kind": "crystal-ball", "params": {}}), arrays))
    bad_params = dict(meta, model=dict(meta["model"], params=dict(meta["model"]["params"], fc="lots")))
    put("damaged.npz", modelfile.dumps(bad_params, arrays))
    evil = np.empty(1, dtype=object)
    evil[0] = Evil(str(folder / "pickle-was-loaded"))
    np.savez(folder / "pickle.npz", meta=np.array(json.dumps(meta)), evil=evil)
    out["pickle"] = str(folder / "pickle.npz")
    return out


@pytest.fixture(scope="module")
def inputs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("inputs")
    good = write_log(folder, "good", good_columns())
    model = str(folder / "lugre.npz")
    models.save(model, LuGreModel(**PARAMS), joint=None, axis="rotary", units=logs.CANONICAL["rotary"],
                provenance={})
    bad_models = folder / "models"
    bad_models.mkdir()
    bad_logs = folder / "logs"
    bad_logs.mkdir()
    return {"dir": folder, "good": good, "model": model, "logs": _bad_logs(bad_logs),
            "models": _bad_models(bad_models, model)}


def command_args(name, log, model, out):
    """Arguments of a quick run of command ``name``; outputs go into folder ``out``."""
    return {
        "identify": ["identify", log, "-o", out / "out.npz"],
        "train-base": ["train-base", log, "-o", out / "out.npz", "--steps", "5"],
        "adapt": ["adapt", model, log, "-o", out / "out.npz", "--epochs", "1"],
        "predict": ["predict", model, log, "-o", out / "out.parquet"],
        "estimate-ext": ["estimate-ext", model, log, "-o", out / "out.parquet"],
        "evaluate": ["evaluate", "--model", model, "--log", log],
        "report": ["report", model, log, "-o", out / "rep"],
        "diagnose": ["diagnose", model, log, "--fix", "-o", out / "out.npz"],
        "inspect": ["inspect", model],
    }[name]


LOG_COMMANDS = ["identify", "train-base", "adapt", "predict", "estimate-ext", "evaluate", "report", "diagnose"]
MODEL_COMMANDS = ["adapt", "predict", "estimate-ext", "evaluate", "report", "diagnose", "inspect"]
FITTING = ["identify", "train-base", "adapt"]


def previous_outputs(folder):
    (folder / "rep").mkdir()
    for name, content in PREVIOUS.items():
        (folder / name).write_bytes(content)


def listing(folder):
    return sorted(str(p.relative_to(folder)) for p in folder.rglob("*"))


def assert_clean_error(res, code, needle):
    """Exit ``code``, one line ``fricli: error: ...`` holding ``needle`` on stderr, nothing on stdout."""
    assert res.exit_code == code, f"exit {res.exit_code}, stderr: {res.stderr}"
    assert isinstance(res.exception, SystemExit), res.exception  # no other exception escaped
    lines = res.stderr.splitlines()
    assert len(lines) == 1, res.stderr
    assert lines[0].startswith("fricli: error: ")
    assert needle in lines[0], lines[0]
    assert res.stdout == ""
    assert "Traceback" not in res.output


def check_untouched(folder, before):
    assert listing(folder) == before  # no temporary file, no lock file, nothing new
    for name, content in PREVIOUS.items():
        assert (folder / name).read_bytes() == content


# case -> (exit code, text the message holds; a dict gives it per command)
LOG_CASES = {
    "missing": (errors.INPUT, "no-such-log.parquet: no such file"),
    "folder": (errors.INPUT, "is a folder, not a log"),
    "not-parquet": (errors.INPUT, "text.parquet: not a Parquet file"),
    "zero-bytes": (errors.INPUT, "not a Parquet"),
    "no-rows": (errors.INPUT, "the log is empty"),
    "no-tau_m": (errors.INPUT, "missing required column 'tau_m'"),
    "no-t": (errors.INPUT, "missing required column 't'"),
    "no-motion-columns": (errors.INPUT, "needs at least one of the columns 'q', 'qd'"),
    "string-column": (errors.INPUT, "column 'tau_m' has type string, expected numbers"),
    "string-time": (errors.INPUT, "column 't' has type string, expected numbers"),
    "nan-inf": (errors.INPUT, "4 rows hold NaN, infinite or absurd values (beyond 1e+09 in magnitude) "
                "(first at row 50, columns qd, tau_m)"),
    "nulls": (errors.INPUT, "column 'tau_g' has 1 missing values (first at row 7)"),
    "t-decreasing": (errors.INPUT, "'t' is not increasing (first at row 500"),
    "t-duplicate": (errors.INPUT, "duplicate timestamps (first at row 500"),
    "unknown-unit": (errors.INPUT, "column 'tau_m' has an unknown unit 'furlongs'"),
    "bool-column": (errors.INPUT, "column 'qd' has type bool, expected numbers"),
    "duplicate-column": (errors.INPUT, "column 'tau_m' appears 2 times"),
    "current-no-kt": (errors.INPUT, "give --kt"),
    "two-joints": (errors.INPUT, "the log holds joints 2, 4: choose one with --joint"),
}


@pytest.mark.parametrize("case", sorted(LOG_CASES))
@pytest.mark.parametrize("command", LOG_COMMANDS)
def test_bad_log(inputs, tmp_path, command, case):
    code, needle = LOG_CASES[case]
    previous_outputs(tmp_path)
    before = listing(tmp_path)
    res = run(*command_args(command, inputs["logs"][case], inputs["model"], tmp_path))
    assert_clean_error(res, code, needle)
    check_untouched(tmp_path, before)


@pytest.mark.parametrize("command", LOG_COMMANDS)
def test_joint_the_log_does_not_have(inputs, tmp_path, command):
    previous_outputs(tmp_path)
    before = listing(tmp_path)
    res = run(*command_args(command, inputs["logs"]["joint-2"], inputs["model"], tmp_path), "--joint", "7")
    assert_clean_error(res, errors.INPUT, "no joint 7 in the log (it holds 2)")
    check_untouched(tmp_path, before)


def test_file_contents_quoted_in_a_message_stay_on_one_line(tmp_path):
    cols = good_columns()
    cols["joint"] = np.where(np.arange(len(cols["t"])) < 2000, "left\narm", "\x1b[31mright")
    log = write_log(tmp_path, "odd-joints", cols)
    res = run("identify", log, "-o", tmp_path / "out.npz", "--joint", "7")
    assert_clean_error(res, errors.INPUT, "no joint 7 in the log (it holds left\\narm, \\x1b[31mright)")


@pytest.mark.parametrize("command", [c for c in LOG_COMMANDS if c not in ("identify", "train-base")])
def test_units_that_disagree_with_the_model(inputs, tmp_path, command):
    previous_outputs(tmp_path)
    before = listing(tmp_path)
    res = run(*command_args(command, inputs["logs"]["linear"], inputs["model"], tmp_path))
    assert_clean_error(res, errors.MODEL, "the model was fitted in rad, Nm but the log")
    assert "is in m, N" in res.stderr
    check_untouched(tmp_path, before)


TOO_LITTLE = {
    ("identify", "one-direction"): "no samples with negative velocity",
    ("train-base", "one-direction"): "no samples with negative velocity",
    ("adapt", "one-direction"): "moves only in the positive direction",
    ("identify", "standstill"): "does not move (qd is zero everywhere)",
    ("train-base", "standstill"): "holds no motion (qd is zero everywhere)",
    ("adapt", "standstill"): "holds no motion (qd is zero everywhere)",
    ("identify", "ten-rows"): "too few steady-state samples with positive velocity (0, need at least 20)",
    ("train-base", "ten-rows"): "only 5 samples with positive velocity; train-base needs at least 20",
    ("adapt", "ten-rows"): "only 5 samples with positive velocity; adapt needs at least 20",
}


@pytest.mark.parametrize("command,case", sorted(TOO_LITTLE))
def test_too_little_to_fit_says_what_is_missing(inputs, tmp_path, command, case):
    previous_outputs(tmp_path)
    before = listing(tmp_path)
    res = run(*command_args(command, inputs["logs"][case], inputs["model"], tmp_path))
    assert_clean_error(res, errors.DATA, TOO_LITTLE[command, case])
    check_untouched(tmp_path, before)


def _extreme(name):
    cols = good_columns()
    if name == "huge-torque":
        cols["tau_m"][:] = 1e308
    elif name == "huge-velocity":
        cols["qd"] *= 1e300
        cols["q"] *= 1e300
    elif name == "huge-gravity":
        cols["tau_g"][:] = -1e200
    elif name == "tiny-time-steps":
        cols["t"] = cols["t"] * 1e-300
    return cols


@pytest.mark.filterwarnings("error")
@pytest.mark.parametrize("case", ["huge-torque", "huge-velocity", "huge-gravity", "tiny-time-steps"])
@pytest.mark.parametrize("command", LOG_COMMANDS)
def test_extreme_values_never_give_an_internal_error(inputs, tmp_path, command, case):
    """Finite but absurd numbers: refused like NaN (their squares overflow: no figure of them
    means anything), or a result (figures that overflow are JSON null) or a clean error; never a
    numpy warning on stderr."""
    log = write_log(tmp_path, case, _extreme(case))
    args = command_args(command, log, inputs["model"], tmp_path) + ([] if command == "report" else ["--json"])
    res = run(*args)
    if case.startswith("huge"):
        assert_clean_error(res, errors.INPUT, "NaN, infinite or absurd values (beyond 1e+09 in magnitude)")
        return
    assert res.exit_code in (errors.OK, errors.DATA, errors.FIT), res.stderr
    assert isinstance(res.exception, (SystemExit, type(None))), res.exception
    assert "internal error" not in res.stderr and "Traceback" not in res.output
    if res.exit_code:
        assert res.stderr.splitlines()[-1].startswith("fricli: error: ")
    elif command != "report":
        json.loads(res.stdout)


def test_figures_over_no_rows_are_null_in_json(inputs, tmp_path):
    """evaluate on a log where the joint never moves: the in-motion figures are undefined."""
    res = run("evaluate", "--model", inputs["model"], "--log", inputs["logs"]["standstill"], "--json")
    assert res.exit_code == 0, res.stderr
    assert "null" in res.stdout and "NaN" not in res.stdout
    json.loads(res.stdout)


def test_a_model_with_non_finite_meta_is_not_written(tmp_path):
    out = tmp_path / "m.npz"
    out.write_bytes(b"previous model")
    with pytest.raises(errors.FitError, match="meta.fit.val.mae is not a finite number"):
        modelfile.write(str(out), dict(modelfile.base_meta(), fit={"val": {"mae": float("nan")}}), {})
    assert out.read_bytes() == b"previous model" and listing(tmp_path) == ["m.npz"]


MODEL_CASES = {
    "missing": (errors.MODEL, "no-such-model.npz: no such file"),
    "folder": (errors.MODEL, "is a folder, not a model file"),
    "truncated": (errors.MODEL, "not a fricli model file (or truncated)"),
    "text": (errors.MODEL, "not a fricli model file (not an .npz archive)"),
    "empty": (errors.MODEL, "not a fricli model file"),
    "other": (errors.MODEL, "not a fricli model file (no 'meta' entry)"),
    "version-99": (errors.MODEL, "model format version 99 is not supported"),
    "unknown-kind": (errors.MODEL, "unknown model kind 'crystal-ball'"),
    "damaged": (errors.MODEL, "damaged lugre model"),
    "pickle": (errors.MODEL, "holds a pickled object; refused"),
}


@pytest.mark.parametrize("case", sorted(MODEL_CASES))
@pytest.mark.parametrize("command", MODEL_COMMANDS)
def test_bad_model_file(inputs, tmp_path, command, case):
    code, needle = MODEL_CASES[case]
    previous_outputs(tmp_path)
    before = listing(tmp_path)
    res = run(*command_args(command, inputs["good"], inputs["models"][case], tmp_path))
    if case == "folder":
        # a folder is read as a model set (one model per joint): its files are checked
        assert_clean_error(res, errors.MODEL, "records no joint; a model folder holds one model per named joint")
    else:
        assert_clean_error(res, code, needle)
    check_untouched(tmp_path, before)
    assert not (inputs["dir"] / "models" / "pickle-was-loaded").exists()


def test_the_pickle_in_the_test_really_runs_code_when_unpickled(inputs, tmp_path):
    """The refusal above means something: loading that file with pickles allowed runs code."""
    import shutil

    evil = tmp_path / "pickle.npz"
    shutil.copy(inputs["models"]["pickle"], evil)
    with np.load(evil, allow_pickle=True) as npz:
        npz["evil"]
    marker = inputs["dir"] / "models" / "pickle-was-loaded"
    assert marker.is_dir()
    marker.rmdir()


@pytest.mark.parametrize("command", ["identify", "train-base", "adapt", "predict", "estimate-ext"])
def test_drop_invalid_drops_with_a_count(inputs, tmp_path, command):
    res = run(*command_args(command, inputs["logs"]["nan-inf"], inputs["model"], tmp_path), "--drop-invalid", "-q")
    assert res.exit_code == 0, res.stderr
    assert "dropped 4" in res.stderr and "NaN, infinite or absurd values" in res.stderr
    out = tmp_path / ("out.parquet" if command in ("predict", "estimate-ext") else "out.npz")
    if out.suffix == ".parquet":
        assert pq.read_table(out).num_rows == 4000 - 4
    else:
        assert models.load(str(out))[1]["provenance"]["log_rows"] == 4000 - 4


@pytest.mark.parametrize("command,args", [
    ("train-base", ["--lr", "1e8", "--steps", "50", "--arch", "mlp"]),   # the dissipative head saturates instead
    ("adapt", ["--lr", "1e9", "--epochs", "5"]),
])
def test_failed_fit_keeps_the_previous_model(inputs, tmp_path, command, args):
    previous_outputs(tmp_path)
    before = listing(tmp_path)
    argv = command_args(command, inputs["good"], inputs["model"], tmp_path)
    argv = [a for a in argv if a not in ("--steps", "5", "--epochs", "1")] + args
    res = run(*argv)
    assert_clean_error(res, errors.FIT, "the loss is not finite")
    check_untouched(tmp_path, before)


@pytest.mark.parametrize("command", ["identify", "train-base", "adapt", "predict", "estimate-ext", "diagnose"])
def test_missing_output_folder(inputs, tmp_path, command):
    args = [str(a).replace(str(tmp_path), str(tmp_path / "nowhere")) for a in
            command_args(command, inputs["good"], inputs["model"], tmp_path)]
    res = run(*args)
    assert_clean_error(res, errors.OUTPUT, "does not exist")
    assert listing(tmp_path) == []


def test_usage_errors_keep_click_code_2(inputs):
    res = run("predict", inputs["model"])
    assert res.exit_code == errors.USAGE and "Missing argument" in res.stderr
    res = run("train-base", inputs["good"], "-o", "x.npz", "--steps", "0")
    assert res.exit_code == errors.USAGE
    for hidden, needle in (("4", "needs more than 10 units"), ("20,20", "has one hidden layer")):
        res = run("train-base", inputs["good"], "-o", "x.npz", "--arch", "selmic", "--hidden", hidden)
        assert res.exit_code == errors.USAGE and needle in res.stderr and "internal error" not in res.stderr


def test_debug_shows_the_exception(inputs):
    res = run("inspect", inputs["models"]["truncated"], "--debug")
    assert isinstance(res.exception, errors.ModelFileError)
    res = run("inspect", inputs["models"]["truncated"])
    assert isinstance(res.exception, SystemExit) and res.exit_code == errors.MODEL


def test_exit_codes_are_distinct_and_documented():
    codes = {row.name: row.code for row in errors.TABLE}
    assert len(set(codes.values())) == len(codes) == len(errors.TABLE)
    doc = pathlib.Path(__file__).resolve().parents[1].joinpath("docs", "exit-codes.md").read_text()
    for name, code in codes.items():
        assert f"| {code} | {name} |" in doc
    for cls in (errors.LogError, errors.ModelFileError, errors.FitError, errors.DataError, errors.OutputError,
                errors.LockedError, errors.MissingDependencyError):
        assert cls.exit_code not in (errors.OK, errors.USAGE)


# ----------------------------------------------------------------------- the output lock


@pytest.mark.parametrize("command", ["identify", "train-base", "adapt", "diagnose"])
def test_locked_output(inputs, tmp_path, command):
    previous_outputs(tmp_path)
    before = listing(tmp_path)
    with jobs.output_lock(str(tmp_path / "out.npz")):
        res = run(*command_args(command, inputs["good"], inputs["model"], tmp_path))
        assert_clean_error(res, errors.LOCKED, "out.npz is being written by another fricli job")
    check_untouched(tmp_path, before)
    res = run(*command_args(command, inputs["good"], inputs["model"], tmp_path), "-q")
    assert res.exit_code == 0, res.stderr  # the lock is gone with the job that held it
    assert models.load(str(tmp_path / "out.npz"))
    assert sorted(set(listing(tmp_path)) - set(before)) == []


def test_lock_on_a_lock_file_removed_meanwhile_is_not_held(tmp_path, monkeypatch):
    """Job B opens the lock file, job A (its holder) ends and removes it, job C locks a new one:
    B's flock on the old, removed file succeeds, but B must not think it holds the lock."""
    out = str(tmp_path / "m.npz")
    job_a = jobs.output_lock(out)
    job_a.__enter__()
    job_c = jobs.output_lock(out)
    real_open = os.open
    raced = []

    def open_then_race(path, flags, mode=0o777):
        fd = real_open(path, flags, mode)
        if not raced:
            raced.append(path)
            job_a.__exit__(None, None, None)
            job_c.__enter__()
        return fd

    monkeypatch.setattr(jobs.os, "open", open_then_race)
    with pytest.raises(errors.LockedError):
        with jobs.output_lock(out):  # job B
            pass
    monkeypatch.undo()
    assert raced and (tmp_path / ".m.npz.lock").exists()
    job_c.__exit__(None, None, None)
    assert listing(tmp_path) == []


# ------------------------------------------------------------------------ --if-changed


def test_if_changed_skips_an_up_to_date_model(inputs, tmp_path):
    out = tmp_path / "lugre.npz"
    args = ["identify", inputs["good"], "-o", out, "--if-changed"]
    assert run(*args, "-q").exit_code == 0
    content, mtime = out.read_bytes(), out.stat().st_mtime_ns
    res = run(*args, "--json")
    assert res.exit_code == errors.UNCHANGED
    assert "is up to date" in res.stderr and res.stdout == ""
    assert out.read_bytes() == content and out.stat().st_mtime_ns == mtime
    assert listing(tmp_path) == ["lugre.npz"]
    # the lock holds the check too
    with jobs.output_lock(str(out)):
        assert run(*args).exit_code == errors.LOCKED


@pytest.mark.parametrize("change", ["option", "reading-option", "log"])
def test_if_changed_refits_when_something_changed(inputs, tmp_path, change):
    out = tmp_path / "lugre.npz"
    args = ["identify", inputs["good"], "-o", out, "--if-changed", "-q"]
    assert run(*args).exit_code == 0
    if change == "option":
        args += ["--hold", "0.3"]
    elif change == "reading-option":
        args += ["--cutoff", "20"]
    else:
        args[1] = write_log(tmp_path, "other", good_columns(seed=1))
    res = run(*args)
    assert res.exit_code == 0, res.stderr
    assert run(*args).exit_code == errors.UNCHANGED


def test_if_changed_sees_a_changed_input_model(inputs, tmp_path):
    base = tmp_path / "base.npz"
    models.save(str(base), LuGreModel(**PARAMS), joint=None, axis="rotary", units=logs.CANONICAL["rotary"],
                provenance={})
    args = ["adapt", base, inputs["good"], "-o", tmp_path / "adapted.npz", "--epochs", "1", "--if-changed", "-q"]
    assert run(*args).exit_code == 0
    assert run(*args).exit_code == errors.UNCHANGED
    models.save(str(base), LuGreModel(**dict(PARAMS, fc=5.5)), joint=None, axis="rotary",
                units=logs.CANONICAL["rotary"], provenance={})
    assert run(*args).exit_code == 0
    assert run(*args, "--seed", "1").exit_code == 0
    assert run(*args, "--seed", "1").exit_code == errors.UNCHANGED


@pytest.mark.parametrize("command", ["train-base", "diagnose"])
def test_if_changed_for_the_other_model_writers(inputs, tmp_path, command):
    args = command_args(command, inputs["good"], inputs["model"], tmp_path) + ["--if-changed", "-q"]
    assert run(*args).exit_code == 0
    res = run(*args)
    assert res.exit_code == errors.UNCHANGED and res.stdout == ""


def test_if_changed_replaces_a_file_that_is_not_a_model(inputs, tmp_path):
    out = tmp_path / "lugre.npz"
    out.write_bytes(b"garbage")
    assert run("identify", inputs["good"], "-o", out, "--if-changed", "-q").exit_code == 0
    assert models.load(str(out))


def test_provenance_records_how_to_reproduce(inputs, tmp_path):
    out = tmp_path / "nn.npz"
    assert run("train-base", inputs["good"], "-o", out, "--steps", "5", "--seed", "3", "--cutoff", "20", "-q",
               "--json").exit_code == 0
    res = run("inspect", out)
    assert res.exit_code == 0
    prov = json.loads(res.stdout)["provenance"]
    assert prov["log_sha256"] == logs.load_log(inputs["good"]).sha256
    assert "seed" not in prov           # recorded once, with the other options
    job = prov["job"]
    assert job["command"] == "train-base" and job["inputs"] == {}
    assert job["options"]["steps"] == 5 and job["options"]["seed"] == 3 and job["options"]["cutoff"] == 20.0
    assert not {"output", "quiet", "as_json", "if_changed", "log"} & set(job["options"])


def test_diagnose_if_changed_needs_fix(inputs):
    res = run("diagnose", inputs["model"], inputs["good"], "--if-changed")
    assert res.exit_code == errors.USAGE
