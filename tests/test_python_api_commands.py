"""The calls of report, inspect, simulate, fleet, trend and demo: each writes what its command writes,
gives what it prints, and refuses a wrong option with OptionError naming it."""

import importlib.util
import json
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

import fricli
from conftest import ROOT, SAMPLE, run_in
from fricli import OptionError
from fricli.core import errors

ENV = {**os.environ, "PYTHONPATH": str(ROOT) + os.pathsep + os.environ.get("PYTHONPATH", "")}


def files_of(folder) -> dict:
    """{relative path: bytes} of every file under ``folder``."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture(scope="module")
def linear(tmp_path_factory):
    path = tmp_path_factory.mktemp("calls") / "linear.npz"
    fricli.Linear().fit(SAMPLE / "joint2_base.parquet").save(path)
    return path


def test_write_report_is_the_command(linear, tmp_path):
    log = SAMPLE / "joint2_extended_asym.parquet"
    done = run_in(tmp_path, "report", linear, log, "-o", "cmd", "--lowpass", "4", "--until", "30%")
    assert done.returncode == 0, done.stderr
    summary = fricli.write_report(linear, log, tmp_path / "call", lowpass_hz=4, time_until="30%")
    assert files_of(tmp_path / "call") == files_of(tmp_path / "cmd")
    assert set(summary) == {"2"} and f"friction MAE {summary['2']['friction']['mae']:.3f}" in done.stderr
    for wrong in ({"lowpass_hz": 0}, {"time_until": "150%"}, {"cutoff": -1}):
        with pytest.raises(OptionError) as err:
            fricli.write_report(linear, log, tmp_path / "refused", **wrong)
        assert err.value.option == next(iter(wrong))
    assert not (tmp_path / "refused").exists()


def test_inspect_models_is_the_command(linear, tmp_path):
    folder = tmp_path / "arm"
    folder.mkdir()
    shutil.copy(linear, folder / "joint_2.npz")
    for model in (linear, folder):
        done = run_in(tmp_path, "inspect", model)
        assert done.returncode == 0, done.stderr
        assert json.loads(json.dumps(fricli.inspect_models(model))) == json.loads(done.stdout)
    assert list(fricli.inspect_models(folder)["joints"]) == ["2"]
    with pytest.raises(fricli.FricliError) as missing:
        fricli.inspect_models(tmp_path / "nope.npz")
    assert missing.value.exit_code == run_in(tmp_path, "inspect", tmp_path / "nope.npz").returncode


def test_simulate_log_is_the_command(tmp_path):
    args = ("--scenario", "adapt", "--joint", "4", "--seed", "5", "--effect", "drift=0.5", "--contact", "10,3,1")
    done = run_in(tmp_path, "simulate", *args, "-o", "cmd.parquet")
    assert done.returncode == 0, done.stderr
    table = fricli.simulate_log(tmp_path / "call.parquet", scenario="adapt", joint=4, seed=5, effects=["drift=0.5"],
                                contacts=[(10, 3, 1)])
    assert (tmp_path / "call.parquet").read_bytes() == (tmp_path / "cmd.parquet").read_bytes()
    assert f"{table.num_rows} rows" in done.stderr
    assert np.ptp(table.column("tau_ext").to_numpy()) >= 3.0   # the contact is in the log
    for wrong, option in (({"scenario": "walk"}, "scenario"), ({"joint": 3}, "joint"), ({"rate": 0.5}, "rate"),
                          ({"effects": ["nonsense"]}, "effects"), ({"duration": 60}, "duration"),
                          ({"thin": True, "scenario": "adapt"}, "thin"), ({"wearing": 1}, "wearing"),
                          ({"fleet": "2x0x1"}, "fleet"), ({"fleet": "1x1x1", "load": "sym"}, "load"),
                          ({"contacts": [(1000, 3, 1)]}, "contacts")):
        with pytest.raises(OptionError) as err:
            fricli.simulate_log(tmp_path / "refused.parquet", **wrong)
        assert err.value.option == option, wrong
    assert not (tmp_path / "refused.parquet").exists()


def test_simulate_log_writes_the_commands_fleet(tmp_path):
    done = run_in(tmp_path, "simulate", "--fleet", "1x2x1", "--wearing", "1", "--seed", "2", "-o", "cmd")
    assert done.returncode == 0, done.stderr
    joints = fricli.simulate_log(tmp_path / "call", fleet=(1, 2, 1), wearing=1, seed=2, map_fn=map)
    assert files_of(tmp_path / "call") == files_of(tmp_path / "cmd")
    assert f"wearing: {joints[0].robot}/" in done.stderr and sum(j.wears for j in joints) == 1


@pytest.fixture(scope="module")
def small_fleet(tmp_path_factory):
    """1 robot x 2 joints x 1 day, as the command simulates it."""
    folder = tmp_path_factory.mktemp("fleet") / "plant"
    fricli.simulate_log(folder, fleet="1x2x1", seed=3, map_fn=map)
    return folder


def test_run_fleet_lists_the_jobs_as_the_command(small_fleet):
    done = run_in(small_fleet, "fleet", "fleet.toml", "--list")
    assert done.returncode == 0, done.stderr
    listed = fricli.run_fleet(small_fleet / "fleet.toml", list_only=True)
    assert listed.listing() + "\n" == done.stdout and len(listed.jobs) == 2 and listed.outcome is None
    for wrong in ({"workers": 0}, {"connect_timeout": 0}):
        with pytest.raises(OptionError) as err:
            fricli.run_fleet(small_fleet / "fleet.toml", **wrong)
        assert err.value.option == next(iter(wrong))


@pytest.mark.skipif(importlib.util.find_spec("distributed") is None,
                    reason="fricli fleet runs on Dask: the fleet extra (dask[distributed]) is not installed")
def test_run_fleet_runs_the_jobs_as_the_command(small_fleet, tmp_path):
    call, cmd = tmp_path / "call", tmp_path / "cmd"
    shutil.copytree(small_fleet, call)
    shutil.copytree(small_fleet, cmd)
    code = ("import json, fricli; r = fricli.run_fleet('fleet.toml', workers=1); "
            "print(json.dumps({'json': r.as_json(), 'table': r.table(), 'exit': r.exit_code}))")
    ran = subprocess.run([sys.executable, "-c", code], cwd=call, env=ENV, capture_output=True, text=True, timeout=300)
    assert ran.returncode == 0, ran.stderr
    done = subprocess.run([sys.executable, "-m", "fricli", "fleet", "fleet.toml", "--workers", "1", "--json"],
                          cwd=cmd, env=ENV, capture_output=True, text=True, timeout=300)
    assert done.returncode == errors.OK, done.stderr
    got, printed = json.loads(ran.stdout), json.loads(done.stdout)
    assert got["exit"] == printed["exit_code"] == errors.OK

    def jobs(printed, folder):
        return [{k: os.path.relpath(j[k], folder) if k in ("log", "model") else j[k]
                 for k in ("robot", "joint", "date", "log", "model", "status", "reason")} for j in printed["jobs"]]

    assert jobs(got["json"], call) == jobs(printed, cmd) and len(printed["jobs"]) == 2
    assert "2 jobs: 2 ok, 0 unchanged, 0 failed" in got["table"]
    for name in ("models/robot001/joint1/2026-01-01.npz", "models/robot001/joint2/2026-01-01.npz"):
        assert fricli.load_model(call / name).meta["fit"] == fricli.load_model(cmd / name).meta["fit"]


def test_fleet_trend_is_the_command(tmp_path):
    from test_fleet import synthetic_history

    synthetic_history(tmp_path / "h", np.random.default_rng(7))
    done = run_in(tmp_path, "trend", "h", "--json", "--figures", "fig-cmd", "--param", "fc", "--max-level", "0.2")
    assert done.returncode == errors.WEAR, done.stderr
    result = fricli.fleet_trend(tmp_path / "h", params=["fc"], max_level=0.2, figures=tmp_path / "fig-call")
    assert json.loads(json.dumps(result.as_json())) == json.loads(done.stdout)
    assert result.flagged == ["r1/2"] and result.exit_code == errors.WEAR
    assert files_of(tmp_path / "fig-call").keys() == files_of(tmp_path / "fig-cmd").keys() == {"r1-joint2.png"}
    table = run_in(tmp_path, "trend", "h", "--param", "fc", "--max-level", "0.2")
    assert table.stdout == result.table() + "\n"
    for wrong, option in (({"params": ["wear"]}, "params"), ({"baseline_days": 0}, "baseline_days"),
                          ({"window_days": 1}, "window_days"), ({"max_growth": 0}, "max_growth")):
        with pytest.raises(OptionError) as err:
            fricli.fleet_trend(tmp_path / "h", **wrong)
        assert err.value.option == option
    bad = run_in(tmp_path, "trend", "h", "--param", "wear")
    assert bad.returncode == 2 and "unknown parameter 'wear'" in bad.stderr


def test_run_demo_refuses_a_wrong_option(tmp_path):
    for wrong, option in (({"joint": 3}, "joint"), ({"steps": 0}, "steps"), ({"seed": 1.5}, "seed")):
        with pytest.raises(OptionError) as err:
            fricli.run_demo(tmp_path / "demo", **wrong)
        assert err.value.option == option
    assert not (tmp_path / "demo").exists()


@pytest.mark.slow
def test_run_demo_is_the_command(tmp_path):
    """Two short demos (about 5 s each): the call writes the command's files and gives its table."""
    done = run_in(tmp_path, "demo", "--steps", "3", "--data", SAMPLE, "-o", "cmd")
    assert done.returncode == 0, done.stderr
    result = fricli.run_demo(tmp_path / "call", data=SAMPLE, steps=3)
    assert result.table() + "\n" == done.stdout
    assert files_of(tmp_path / "call") == files_of(tmp_path / "cmd")
