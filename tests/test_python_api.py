"""docs/python-api.md: every python example runs, in order, on the files a user has (the bundled
sample logs, a whole-arm log and its URDF), and imports only names of ``fricli.__all__``."""

import ast
import re
import shutil
import subprocess
import sys

import pytest

import fricli
from conftest import ROOT, SAMPLE

PAGE = ROOT / "docs" / "python-api.md"
BLOCKS = re.findall(r"```python\n(.*?)```", PAGE.read_text(), re.S)
HEAVY = ("numpy", "pyarrow", "scipy", "pinocchio", "dask", "click", "fricli.core", "fricli.fitting", "fricli.models")


def fricli_imports(source: str) -> list[tuple[str, str | None]]:
    """(module, name) of every import of fricli in ``source``."""
    found = []
    for node in ast.walk(ast.parse(source)):
        if isinstance(node, ast.Import):
            found += [(a.name, None) for a in node.names if a.name.split(".")[0] == "fricli"]
        elif isinstance(node, ast.ImportFrom) and (node.module or "").split(".")[0] == "fricli":
            found += [(node.module, a.name) for a in node.names]
    return found


def test_the_page_has_the_examples():
    text = "\n".join(BLOCKS)
    for name in ("LuGre", "Network", "load_model", "external_torque", "Residual", "Diagnosis", "Calibration",
                 "diagnose_arm"):
        assert name in text, name
    assert all(len(block.strip().splitlines()) <= 10 for block in BLOCKS)


@pytest.mark.parametrize("block", BLOCKS, ids=[f"example{i + 1}" for i in range(len(BLOCKS))])
def test_an_example_imports_only_the_public_names(block):
    imports = fricli_imports(block)
    assert imports
    for module, name in imports:
        assert module == "fricli" and name in fricli.__all__, (module, name)


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("python-api")
    (out / "sample_data").mkdir()
    for name in ("joint2_base", "joint2_adapt", "joint2_extended_asym"):
        shutil.copy(SAMPLE / f"{name}.parquet", out / "sample_data" / f"{name}.parquet")
    return out


@pytest.mark.parametrize("index", range(len(BLOCKS)), ids=[f"example{i + 1}" for i in range(len(BLOCKS))])
def test_an_example_runs(index, folder, monkeypatch):
    block = BLOCKS[index]
    if "Calibration" in block and not (folder / "arm.urdf").exists():
        from test_estimators import arm_files

        arm_files(folder)
    if "diagnose_arm" in block and not (folder / "arm-cad.parquet").exists():
        from test_estimators import cad_arm_files

        cad_arm_files(folder, "arm-cad.urdf", "arm-raw.parquet", "arm-cad.parquet")
    monkeypatch.chdir(folder)
    exec(compile(block, f"{PAGE.name} example {index + 1}", "exec"), {"__name__": "__example__"})


def test_import_fricli_is_cheap():
    """``import fricli`` loads none of the numerical libraries; the first public name loads them."""
    code = ("import sys, fricli; before = set(sys.modules); fricli.read_log; "
            "print(sorted(m for m in before if m.startswith({0!r}))); "
            "print('pinocchio' in sys.modules or 'dask' in sys.modules)").format(HEAVY)
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, check=True)
    assert out.stdout.splitlines() == ["[]", "False"], out.stdout


def test_every_public_name_is_there():
    for name in fricli.__all__:
        assert getattr(fricli, name) is not None, name
    assert set(fricli.__all__) <= set(dir(fricli))
    with pytest.raises(AttributeError):
        fricli.train_base


def test_read_log_reads_stdin_as_the_commands_do():
    """``read_log("-")`` reads the log from stdin (as LOG "-" of every command), named stdin."""
    code = "import fricli; log = fricli.read_log('-'); print(log.name, len(log.signals['t']))"
    with open(SAMPLE / "joint2_adapt.parquet", "rb") as fh:
        out = subprocess.run([sys.executable, "-c", code], stdin=fh, capture_output=True, text=True, cwd=ROOT)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["stdin", "3582"]


def test_every_command_is_a_call():
    """Each command is in the page's table of calls, and each call of the table is in ``fricli.__all__``."""
    from fricli.cli import COMMANDS

    text = PAGE.read_text()
    table = set(re.findall(r"^\|[^|]*\| `fricli ([a-z-]+)", text, re.M)) | {"fit-arm"}
    assert table == set(COMMANDS), sorted(set(COMMANDS) ^ table)
    assert "no call in `fricli`" not in text
    called = set(re.findall(r"^\| `([a-z_A-Z]+)\(", text, re.M))
    assert called <= set(fricli.__all__), sorted(called - set(fricli.__all__))


def test_inspect_of_a_file_is_load_models_meta(folder):
    """What python-api.md says: ``fricli inspect FILE`` prints ``load_model(FILE).meta``."""
    import json

    from conftest import invoke

    fricli.Linear().fit(folder / "sample_data" / "joint2_base.parquet").save(folder / "inspected.npz")
    done = invoke("inspect", folder / "inspected.npz")
    assert done.exit_code == 0
    assert json.loads(done.stdout) == json.loads(json.dumps(fricli.load_model(folder / "inspected.npz").meta))


def test_evaluate_is_the_command(folder):
    """``fricli.evaluate`` gives what ``fricli evaluate --json`` prints, the table it prints, and its errors."""
    import json

    from conftest import invoke

    base, ext = folder / "sample_data" / "joint2_base.parquet", folder / "sample_data" / "joint2_extended_asym.parquet"
    fricli.Linear().fit(base).save(folder / "linear-eval.npz")
    done = invoke("evaluate", "--model", f"lin={folder / 'linear-eval.npz'}", "--log", f"asym={ext}", "--lowpass", "5",
                  "--until", "50%", "--json")
    assert done.exit_code == 0, done.output
    run = fricli.evaluate({"lin": folder / "linear-eval.npz"}, {"asym": ext}, lowpass_hz=5, time_until="50%")
    assert json.loads(json.dumps(run.to_json())) == json.loads(done.stdout)
    assert run.results[0].friction["n"] == 6000          # --until 50% of the 12,001 rows
    table = invoke("evaluate", "--model", f"lin={folder / 'linear-eval.npz'}", "--log", f"asym={ext}", "--lowpass", "5",
                   "--until", "50%")
    assert run.markdown() in table.stdout
    for wrong in ({"lowpass_hz": 0}, {"cutoff": -1}, {"time_until": "150%"}, {"speed": 1}):
        with pytest.raises(fricli.OptionError):
            fricli.evaluate({"lin": folder / "linear-eval.npz"}, {"asym": ext}, **wrong)
    with pytest.raises(fricli.FricliError) as missing:
        fricli.evaluate({"lin": folder / "nope.npz"}, {"asym": ext})
    assert missing.value.exit_code == invoke("evaluate", "--model", folder / "nope.npz", "--log", ext).exit_code


def test_predict_file_is_the_command(folder):
    """``fricli.predict_file`` writes what ``fricli predict`` and ``estimate-ext`` write, gives what
    ``--json`` prints, and refuses options that do not go together."""
    import json

    import pyarrow.parquet as pq

    from conftest import invoke
    from fricli.fitting.optionspec import OptionError

    log = folder / "sample_data" / "joint2_extended_asym.parquet"
    fricli.Linear().fit(folder / "sample_data" / "joint2_base.parquet").save(folder / "linear-pred.npz")
    model = str(folder / "linear-pred.npz")
    for command, kwargs in (("predict", {}), ("estimate-ext", {"external": True, "lowpass_hz": 5.0})):
        extra = ["--lowpass", "5"] if kwargs else []
        done = invoke(command, model, log, "-o", folder / f"{command}-cmd.parquet", "--until", "80%", "--json", *extra)
        assert done.exit_code == 0, done.output
        result = fricli.predict_file(model, str(log), str(folder / f"{command}-call.parquet"), time_until="80%",
                                     **kwargs)
        cmd, call = (pq.read_table(folder / f"{command}-{how}.parquet") for how in ("cmd", "call"))
        assert call.equals(cmd, check_metadata=True)
        printed = json.loads(done.stdout)
        assert {k: printed[k] for k in result.as_json()} == json.loads(json.dumps(result.as_json()))
    for kwargs, option in (({"lowpass_hz": 5.0}, "lowpass_hz"), ({"precision": "half"}, "precision"),
                           ({"batch_rows": 0}, "batch_rows")):
        with pytest.raises(OptionError) as err:
            fricli.predict_file(model, str(log), str(folder / "refused.parquet"), **kwargs)
        assert err.value.option == option
    assert not (folder / "refused.parquet").exists()


def test_paths_may_be_path_objects_and_anything_else_is_an_option_error_naming_the_argument(folder):
    """A pathlib.Path reads as its text (a Path log was once refused as a damaged Parquet file);
    None, a number or a list where a file goes is OptionError naming the argument, never a
    TypeError from deep inside."""
    import pathlib

    from fricli.fitting.optionspec import OptionError

    log = pathlib.Path(folder / "sample_data" / "joint2_extended_asym.parquet")
    fricli.Linear().fit(folder / "sample_data" / "joint2_base.parquet").save(folder / "linear-paths.npz")
    model = pathlib.Path(folder / "linear-paths.npz")
    assert fricli.predict_file(model, log, folder / "path.parquet").rows == fricli.read_log(log).table.num_rows
    assert fricli.external_torque(model, log).shape == fricli.external_torque(fricli.load_model(model), log).shape
    for call, argument in ((lambda: fricli.read_log(None), "path"), (lambda: fricli.load_model(5), "path"),
                           (lambda: fricli.predict_file(None, log, folder / "x.parquet"), "model"),
                           (lambda: fricli.predict_file(model, [log], folder / "x.parquet"), "log"),
                           (lambda: fricli.external_torque(None, log), "model"),
                           (lambda: fricli.load_model(model).predict(3), "log"),
                           (lambda: fricli.replay_log(model, None), "log"),
                           (lambda: fricli.export_header(None), "model"),
                           (lambda: fricli.write_report(model, log, None), "output"),
                           (lambda: fricli.evaluate([model], [log]), "models"),
                           (lambda: fricli.calibrate_thresholds(model, []), "log_files")):
        with pytest.raises(OptionError) as err:
            call()
        assert err.value.option == argument, (argument, str(err.value))


@pytest.mark.parametrize("call, option", [
    (lambda m, log: fricli.replay_log(m, log, gain=float("nan")), "gain"),
    (lambda m, log: fricli.replay_log(m, log, gain=-1.0), "gain"),
    (lambda m, log: fricli.replay_log(m, log, gain="5"), "gain"),
    (lambda m, log: fricli.replay_log(m, log, time_constant=0), "time_constant"),
    (lambda m, log: fricli.calibrate_thresholds(m, log, margin=float("inf")), "margin"),
    (lambda m, log: fricli.calibrate_thresholds(m, log, release=1.0), "release"),
    (lambda m, log: fricli.calibrate_thresholds(m, log, persistence=1.5), "persistence"),
    (lambda m, log: fricli.calibrate_thresholds(m, log, level_share="no"), "level_share"),
    (lambda m, log: fricli.export_header(m, observer="yes"), "observer"),
    (lambda m, log: fricli.external_torque(m, log, lowpass_hz=0), "lowpass_hz"),
    (lambda m, log: fricli.read_log(log, cutoff=float("inf")), "cutoff"),
])
def test_the_controllers_calls_check_their_options_as_the_commands(folder, call, option):
    from fricli.fitting.optionspec import OptionError

    log = folder / "sample_data" / "joint2_adapt.parquet"
    if not (folder / "linear-options.npz").exists():
        fricli.Linear().fit(log).save(folder / "linear-options.npz")
    with pytest.raises(OptionError) as err:
        call(str(folder / "linear-options.npz"), str(log))
    assert err.value.option == option, str(err.value)
