"""Every command run as a real process, as cron or a shell runs it: the exit code is the
documented one and the interpreter exits cleanly (pyarrow has been seen to abort at
interpreter exit, turning a success into a failure code)."""

import importlib.util
import io
import os
import pathlib
import re
import subprocess
import sys
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

import test_urdf
from conftest import ROOT, SAMPLE
from fricli import models
from fricli.core import errors, logs
from fricli.cli import cli
from fricli.models.lugre import LuGreModel

PARAMS = dict(fc=5.0, fs=6.0, vs=0.05, delta=1.0, fv=10.0, kc=0.03, ks=0.04, sigma0=1e4, sigma1=5.0)

CRASH_SIGNS = ("Traceback", "Aborted", "terminate called", "Fatal Python error", "core dumped", "Segmentation")


def base_env():
    return dict(os.environ, OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1",
                PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))


def fricli(args, cwd, stdin=None):
    return subprocess.run([sys.executable, "-m", "fricli", *map(str, args)], cwd=cwd, env=base_env(),
                          input=stdin, capture_output=True, timeout=300)


def run_all(runs: dict, cwd) -> dict:
    """Run the commands two at a time; name -> CompletedProcess."""
    with ThreadPoolExecutor(max_workers=2) as pool:
        futures = {name: pool.submit(fricli, args, cwd) for name, args in runs.items()}
        return {name: future.result() for name, future in futures.items()}


def check(name, proc, code=0):
    err = proc.stderr.decode(errors="replace")
    assert proc.returncode == code, f"{name}: exit {proc.returncode}, expected {code}\n{err}"
    for sign in CRASH_SIGNS:
        assert sign not in err, f"{name}: {sign!r} on stderr\n{err}"


COMMANDS = ["adapt", "calibrate", "demo", "diagnose", "dynamics", "estimate-ext", "evaluate", "export", "fit-arm", "fleet", "identify",
            "import", "inspect", "payload", "predict", "replay", "report", "simulate", "thresholds", "train-base", "trend"]


def test_fricli_never_uses_the_threaded_dataset_reader():
    """``pq.read_table`` (pyarrow's dataset reader) leaves worker threads that abort the
    interpreter at exit now and then ("terminate called without an active exception", about
    one run in two of a bare read_table script here); fricli reads through ``pq.ParquetFile``."""
    for path in (ROOT / "fricli").rglob("*.py"):
        text = path.read_text()
        assert not re.search(r"\b(pq|parquet)\.read_table\(|import read_table|pyarrow\.dataset", text), path


def test_fricli_reads_bytes_through_arrow_buffers():
    """Bytes in memory go to pyarrow as ``pa.BufferReader``, not as a Python ``io.BytesIO``: its
    threaded readers reading through a Python file object aborted the interpreter at exit in
    about one run in thirty (``fricli payload`` refusing a log, 2 of 60 runs; a bare
    ``ParquetFile(io.BytesIO(data)).read()`` script, 4 of 200; with ``pa.BufferReader``, 0 of 200)."""
    for path in (ROOT / "fricli").rglob("*.py"):
        text = path.read_text()
        assert not re.search(r"(ParquetFile|read_csv|open_csv)\(\s*io\.BytesIO", text), path


def test_fricli_reads_through_pyarrow_on_one_thread():
    """pyarrow's reader threads aborted the interpreter at exit now and then on a loaded machine:
    ``train-base --joint nosuch`` refusing a log, with two busy loops running, exited 134 in 4 of
    25 runs (its one-line error printed, then "terminate called without an active exception");
    reading with ``use_threads=False``, 0 of 40."""
    calls = re.compile(r"(?:\biter_batches|\bReadOptions|\bpf\.read(?:_row_group)?|ParquetFile\([^()]*\)\.read)\(([^()]*)\)")
    found = 0
    for path in (ROOT / "fricli").rglob("*.py"):
        for args in calls.findall(path.read_text()):
            found += 1
            assert "use_threads=False" in args, (path, args)
    assert found >= 5


def test_every_command_is_smoke_tested():
    assert cli.list_commands(None) == COMMANDS


@pytest.mark.parametrize("command", COMMANDS)
def test_every_command_is_in_the_readme_table(command):
    readme = (ROOT / "README.md").read_text()
    assert re.search(rf"^\| `fricli {re.escape(command)}[ `]", readme, re.M), command


@pytest.mark.slow
def test_every_command_in_a_process(tmp_path):
    base, adapt, ext = SAMPLE / "joint2_base.parquet", SAMPLE / "joint2_adapt.parquet", \
        SAMPLE / "joint2_extended_asym.parquet"
    test_urdf.write_case(tmp_path, np.random.default_rng(0), n=100)
    first = run_all({
        "--version": ["--version"],
        "simulate": ["simulate", "--scenario", "adapt", "--joint", "2", "-o", "sim.parquet", "-q"],
        "identify": ["identify", base, "-o", "lugre.npz", "--json"],
        "train-base": ["train-base", base, "-o", "nn.npz", "--steps", "20", "-q"],
        "demo": ["demo", "--steps", "3", "-o", "demo", "-q"],
        "bad model": ["predict", "missing.npz", ext, "-o", "x.parquet"],
        "import": ["import", "rec.csv", "--mapping", "map.toml", "-o", "rec.parquet", "-q"],
    }, tmp_path)
    for name, proc in first.items():
        check(name, proc, errors.MODEL if name == "bad model" else 0)
    assert first["--version"].stdout.decode().startswith("fricli, version")
    assert first["bad model"].stderr.decode().startswith("fricli: error: missing.npz: no such file")
    second = run_all({
        "adapt": ["adapt", "nn.npz", adapt, "-o", "adapted.npz", "--epochs", "2", "-q"],
        "predict": ["predict", "lugre.npz", "sim.parquet", "-o", "pred.parquet", "-q"],
        "estimate-ext": ["estimate-ext", "nn.npz", ext, "-o", "ext.parquet", "--lowpass", "2", "-q"],
        "evaluate": ["evaluate", "--model", "lugre.npz", "--model", "nn.npz", "--log", ext, "--json"],
        "report": ["report", "nn.npz", ext, "-o", "report", "-q"],
        "diagnose": ["diagnose", "lugre.npz", ext, "--fix", "-o", "fixed.npz", "--folds", "5", "-q"],
        "inspect": ["inspect", "lugre.npz"],
        "export": ["export", "lugre.npz", "-o", "friction.h", "-q"],
        "thresholds": ["thresholds", "lugre.npz", base, "-o", "thresholds.json", "-q"],
        "unchanged": ["identify", base, "-o", "lugre.npz", "--if-changed", "-q"],
        "dynamics": ["dynamics", "rec.parquet", "--urdf", "two_link.urdf", "--match", "order", "-o", "dyn.parquet",
                     "-q"],
        "calibrate": ["calibrate", "rec.parquet", "--urdf", "two_link.urdf", "--match", "order", "--edge", "0.05",
                      "-o", "cal.urdf", "-q"],
    }, tmp_path)
    has_pinocchio = importlib.util.find_spec("pinocchio") is not None
    for name, proc in second.items():
        code = {"unchanged": errors.UNCHANGED, "dynamics": 0 if has_pinocchio else errors.DEPENDENCY,
                "calibrate": 0 if has_pinocchio else errors.DEPENDENCY}.get(name, 0)
        check(name, proc, code)
    third = run_all({"replay": ["replay", "lugre.npz", ext, "--adapt", "--thresholds", "thresholds.json", "-o",
                                "replay.parquet", "-q"]}
                    | ({"payload": ["payload", "dyn.parquet", "--frame", "link2", "--edge", "0.05", "-q"]}
                       if has_pinocchio else {}), tmp_path)
    for name, proc in third.items():
        check(name, proc)
    for name in ("lugre.npz", "nn.npz", "adapted.npz", "fixed.npz", "sim.parquet", "pred.parquet", "ext.parquet",
                 "report/index.html", "demo/table.md", "rec.parquet", "friction.h", "thresholds.json", "replay.parquet") + (("dyn.parquet", "cal.urdf") if has_pinocchio else ()):
        assert (tmp_path / name).stat().st_size > 0, name
    assert not [p for p in tmp_path.rglob("*") if p.name.endswith((".tmp", ".lock"))]


def test_stdin_to_stdout_in_processes(tmp_path):
    """estimate-ext reading Parquet from stdin and writing it to stdout (predict's pipeline is in
    test_predict.py), and an empty stdin refused."""
    model = tmp_path / "lugre.npz"
    models.save(str(model), LuGreModel(**PARAMS), joint=4, axis="rotary", units=logs.CANONICAL["rotary"],
                provenance={})
    log = (SAMPLE / "joint4_adapt.parquet").read_bytes()
    with ThreadPoolExecutor(max_workers=2) as pool:
        ext = pool.submit(fricli, ["estimate-ext", model, "-", "-o", "-", "-q"], tmp_path, log)
        empty = pool.submit(fricli, ["predict", model, "-", "-o", "-"], tmp_path, b"")
        ext, empty = ext.result(), empty.result()
    check("estimate-ext", ext)
    table = pq.read_table(io.BytesIO(ext.stdout))
    assert table.num_rows == pq.read_metadata(SAMPLE / "joint4_adapt.parquet").num_rows
    assert {"tau_f_pred", "tau_ext_pred"} <= set(table.column_names)
    check("empty stdin", empty, errors.INPUT)
    assert empty.stdout == b"" and empty.stderr.decode().startswith("fricli: error: stdin: empty input")


@pytest.mark.parametrize("command", COMMANDS)
def test_help_has_an_example(command):
    res = CliRunner().invoke(cli, [command, "-h"])
    assert res.exit_code == 0 and "Example:" in res.stdout and res.stderr == ""
    assert "None" not in res.stdout   # e.g. an unbounded range shown as "x<=None"


# ------------------------------------------------------------- what a newcomer runs into first


def test_a_csv_log_points_to_fricli_import(tmp_path):
    """Every log reader (whole-table, streaming, stdin) names the command that converts text."""
    csv = tmp_path / "run.csv"
    csv.write_text("t,q,tau_m\n0,0,1\n0.01,0.1,1\n")
    model = str(tmp_path / "lugre.npz")
    models.save(model, LuGreModel(**PARAMS), joint=None, axis="rotary", units=logs.CANONICAL["rotary"], provenance={})
    runner = CliRunner()
    for args, stdin in ((["identify", str(csv), "-o", str(tmp_path / "m.npz")], None),
                        (["predict", model, str(csv), "-o", str(tmp_path / "p.parquet")], None),
                        (["evaluate", "--model", model, "--log", str(csv)], None),
                        (["predict", model, "-", "-o", str(tmp_path / "p.parquet")], csv.read_bytes())):
        res = runner.invoke(cli, args, input=stdin)
        assert res.exit_code == errors.INPUT, (args, res.output)
        assert "not a Parquet file" in res.stderr and "fricli import" in res.stderr, res.stderr
    damaged = tmp_path / "damaged.parquet"
    damaged.write_bytes(b"PAR1 cut short")
    res = runner.invoke(cli, ["identify", str(damaged), "-o", str(tmp_path / "m.npz")])
    assert res.exit_code == errors.INPUT and "fricli import" not in res.stderr   # Parquet, only damaged
    assert "damaged (truncated, or written only in part)" in res.stderr, res.stderr


def test_an_unknown_payload_frame_lists_the_frames():
    pytest.importorskip("pinocchio")
    from fricli.robot.dynamics import RobotModel
    from fricli.robot.mapping import Payload

    with pytest.raises(errors.ModelFileError, match="no frame 'tool0'") as caught:
        RobotModel(test_urdf.URDF, "two_link.urdf", payload=Payload(1.0, (0, 0, 0), "tool0"))
    listed = str(caught.value).split("the frames are:")[1]
    assert {"flange", "link2", "elbow", "base"} <= {f.strip() for f in listed.split(",")}


def test_trend_figures_creates_its_folder(tmp_path, rng):
    import test_fleet

    test_fleet.synthetic_history(tmp_path / "h", rng)
    res = CliRunner().invoke(cli, ["trend", str(tmp_path / "h"), "--figures", str(tmp_path / "wear" / "today"), "-q"])
    assert res.exit_code == errors.WEAR, res.output
    assert [p.name for p in (tmp_path / "wear" / "today").iterdir()] == ["r1-joint2.png"]
    (tmp_path / "file").write_text("")
    res = CliRunner().invoke(cli, ["trend", str(tmp_path / "h"), "--figures", str(tmp_path / "file" / "x"), "-q"])
    assert res.exit_code == errors.OUTPUT and "cannot create the folder" in res.stderr


def _model_folder(folder):
    from fricli.core import modelset

    folder.mkdir()
    for joint in (1, 2):
        models.save(modelset.path_for(str(folder), joint), LuGreModel(**PARAMS), joint=joint, axis="rotary",
                    units=logs.CANONICAL["rotary"], provenance={})
    return folder


def test_inspect_reads_a_model_folder_as_export_does(tmp_path):
    import json

    folder = _model_folder(tmp_path / "arm")
    res = CliRunner().invoke(cli, ["inspect", str(folder)])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    assert sorted(out["joints"]) == ["1", "2"] and out["joints"]["2"]["joint"] == 2
    assert CliRunner().invoke(cli, ["export", str(folder), "-o", str(tmp_path / "arm.h"), "-q"]).exit_code == 0


def test_deploy_doc_names_the_files_and_symbols_the_code_writes(tmp_path):
    """The per-joint file names and C symbols docs/deploy.md quotes are those of fricli's own model
    folder and export, and the header and the doc say that linking needs -lm."""
    from fricli.core import modelset
    from fricli.export import c

    doc = (ROOT / "docs" / "deploy.md").read_text()
    folder = _model_folder(tmp_path / "models")
    names = {modelset.file_name(j) for j in (1, 2)}
    quoted_files = set(re.findall(r"`(joint[^`]*\.npz)`", doc))
    assert quoted_files and quoted_files <= names, quoted_files
    arm, default = c.export(str(folder), "arm"), c.export(str(folder))
    quoted_steps = set(re.findall(r"`((?:arm|friction)_joint[A-Za-z0-9_]*_step)`", doc))
    assert {"arm_joint_1_step", "friction_joint_1_step"} <= quoted_steps
    for symbol in quoted_steps:
        assert f"double {symbol}(" in (arm if symbol.startswith("arm") else default), symbol
    assert "Link with -lm" in arm.split("*/")[0] and "Link with `-lm`" in doc


def test_an_output_that_names_an_input_is_refused(tmp_path):
    """Nothing the user had is overwritten by a mistyped -o: the input stays byte for byte."""
    log = tmp_path / "log.parquet"
    log.write_bytes((SAMPLE / "joint2_base.parquet").read_bytes())
    model = tmp_path / "m.npz"
    models.save(str(model), LuGreModel(**PARAMS), joint=2, axis="rotary", units=logs.CANONICAL["rotary"], provenance={})
    (tmp_path / "link.parquet").symlink_to(log)
    before = {p: p.read_bytes() for p in (log, model)}
    runner = CliRunner()
    for args, named in ((["identify", log, "-o", log], "LOG"), (["predict", model, log, "-o", model], "MODEL"),
                        (["adapt", model, log, "-o", model], "BASE"),
                        (["predict", model, tmp_path / "link.parquet", "-o", log], "LOG"),
                        (["export", model, "-o", model], "MODEL"),
                        (["calibrate", log, "--urdf", model, "-o", tmp_path / "c.urdf", "--report", log], "LOG")):
        res = runner.invoke(cli, [str(a) for a in args])
        assert res.exit_code == errors.USAGE, (args, res.output)
        assert "it would be overwritten" in res.stderr and named in res.stderr, res.stderr
    assert {p: p.read_bytes() for p in (log, model)} == before
    res = runner.invoke(cli, ["calibrate", str(log), "--urdf", "u.urdf", "-o", "same", "--report", "same"])
    assert res.exit_code == errors.USAGE and "name the same file" in res.stderr
    for args, says in ((["calibrate", log, "--urdf", "u.urdf", "-o", "-", "--json"], "give the report a file"),
                       (["calibrate", log, "--urdf", "u.urdf", "-o", "-", "--report", "-"], "give the report a file"),
                       (["report", model, log, "-o", "-"], "stdout (-) cannot take it"),
                       (["demo", "-o", "-"], "stdout (-) cannot take it"),
                       (["evaluate", "--model", model, "--log", "a=-", "--log", "b=-"], "can be read only once")):
        res = runner.invoke(cli, [str(a) for a in args])
        assert res.exit_code == errors.USAGE and says in res.stderr, (args, res.stderr)
    assert not (pathlib.Path.cwd() / "-").exists()


@pytest.mark.parametrize("stdout", ["closed", "full"])
def test_stdout_that_cannot_be_written_is_an_output_error(tmp_path, stdout):
    model = tmp_path / "m.npz"
    models.save(str(model), LuGreModel(**PARAMS), joint=2, axis="rotary", units=logs.CANONICAL["rotary"], provenance={})
    if stdout == "full" and not os.path.exists("/dev/full"):
        pytest.skip("no /dev/full on this system")
    for args in (["predict", model, SAMPLE / "joint2_adapt.parquet", "-o", "-", "-q"], ["inspect", model],
                 ["export", model, "-o", "-"]):
        with open("/dev/full" if stdout == "full" else os.devnull, "wb") as full:
            res = subprocess.run([sys.executable, "-m", "fricli", *map(str, args)], cwd=tmp_path, env=base_env(),
                                 stdout=full, stderr=subprocess.PIPE, timeout=300,
                                 preexec_fn=(lambda: os.close(1)) if stdout == "closed" else None)
        check(args[0], res, errors.OUTPUT)
        assert res.stderr.decode().startswith("fricli: error: cannot write"), res.stderr


def test_a_reader_that_closes_stdout_early_is_an_output_error(tmp_path):
    """``fricli predict ... -o - | head -c 10``: exit 7 with one line, where it was exit 7 without one."""
    model = tmp_path / "m.npz"
    models.save(str(model), LuGreModel(**PARAMS), joint=2, axis="rotary", units=logs.CANONICAL["rotary"], provenance={})
    args = ["predict", model, SAMPLE / "joint2_adapt.parquet", "-o", "-", "-q", "--batch-rows", "1000"]
    proc = subprocess.Popen([sys.executable, "-m", "fricli", *map(str, args)], cwd=tmp_path, env=base_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert len(proc.stdout.read(10)) == 10
    proc.stdout.close()
    stderr = proc.stderr.read().decode()
    assert proc.wait(timeout=300) == errors.OUTPUT
    assert stderr == "fricli: error: cannot write to stdout: the command reading it has closed it\n", stderr


def test_binary_output_to_a_terminal_is_refused_and_text_is_written(tmp_path):
    import pty

    model = tmp_path / "m.npz"
    models.save(str(model), LuGreModel(**PARAMS), joint=2, axis="rotary", units=logs.CANONICAL["rotary"], provenance={})
    primary, terminal = pty.openpty()
    try:
        for args, code in ((["predict", model, SAMPLE / "joint2_adapt.parquet", "-o", "-", "-q"], errors.OUTPUT),
                           (["identify", SAMPLE / "joint2_base.parquet", "-o", "-", "-q"], errors.OUTPUT),
                           (["export", model, "-o", "-"], errors.OK)):
            res = subprocess.run([sys.executable, "-m", "fricli", *map(str, args)], cwd=tmp_path, env=base_env(),
                                 stdout=terminal, stderr=subprocess.PIPE, timeout=300)
            check(args[0], res, code)
            if code:
                assert res.stderr.decode().startswith("fricli: error: stdout is a terminal"), res.stderr
    finally:
        os.close(primary)
        os.close(terminal)
