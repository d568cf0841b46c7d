"""evaluate, report and demo."""

import json

import numpy as np
import pytest
from click.testing import CliRunner

import test_report
from conftest import SAMPLE
from fricli.core import metrics
from fricli.cli import cli

ASYM = str(SAMPLE / "joint2_extended_asym.parquet")
NONE = str(SAMPLE / "joint2_extended_none.parquet")


@pytest.fixture(scope="module")
def fitted(tmp_path_factory):
    folder = tmp_path_factory.mktemp("models")
    runner = CliRunner()
    lugre, nn = str(folder / "lugre.npz"), str(folder / "nn.npz")
    assert runner.invoke(cli, ["identify", str(SAMPLE / "joint2_base.parquet"), "-o", lugre, "-q"]).exit_code == 0
    assert runner.invoke(cli, ["train-base", str(SAMPLE / "joint2_base.parquet"), "-o", nn, "--steps", "300",
                               "-q"]).exit_code == 0
    return {"lugre": lugre, "nn": nn, "folder": folder}


def test_evaluate_json_is_stable_and_complete(fitted):
    args = ["evaluate", "--model", f"lugre={fitted['lugre']}", "--model", fitted["nn"],
            "--log", f"asym={ASYM}", "--log", f"none={NONE}", "--lowpass", "5", "--json"]
    first, second = CliRunner().invoke(cli, args), CliRunner().invoke(cli, args)
    assert first.exit_code == 0, first.stderr
    assert first.stdout == second.stdout
    out = json.loads(first.stdout)
    assert [(r["model"], r["log"]) for r in out["results"]] == [
        ("lugre", "asym"), ("lugre", "none"), ("nn", "asym"), ("nn", "none")]
    for r in out["results"]:
        assert r["external"] is not None and r["friction_moving"]["n"] < r["friction"]["n"]
    # the identified LuGre model misses the extended logs' new friction state by well over the noise
    assert out["results"][0]["friction"]["mae"] > 1.0


def test_evaluate_markdown_table(fitted):
    res = CliRunner().invoke(cli, ["evaluate", "--model", f"lugre={fitted['lugre']}", "--log", f"asym={ASYM}"])
    assert res.exit_code == 0
    lines = res.stdout.splitlines()
    assert any(line.startswith("| lugre |") for line in lines)
    assert "asym ext. torque MAE" in res.stdout


def test_a_log_without_joints_and_a_log_without_motion_read_as_such():
    """Rows of a log without a joint column next to a joint's: named as such, not "(joint None)";
    no row in motion: a dash in brackets, as the JSON's null, not "(nan)"."""
    from fricli.applying.evaluation import Result, markdown_table

    err = {"mae": 0.5, "rmse": 0.6}
    rows = [Result("a", "d", err, None, err, None, joint=None),
            Result("a", "e", err, None, {"mae": None, "rmse": float("nan")}, None, joint=2)]
    text = markdown_table(rows, ["a"], ["d", "e"])
    assert "| a (log without joints) | 0.500 (0.500) | 0.600 (0.600) | – | – |" in text
    assert "| a (joint 2) | – | – | 0.500 (–) | 0.600 (–) |" in text and "None" not in text and "nan" not in text


def test_evaluate_refuses_a_name_used_twice(fitted):
    res = CliRunner().invoke(cli, ["evaluate", "--model", f"a={fitted['lugre']}", "--model", f"a={fitted['nn']}",
                                   "--log", ASYM])
    assert res.exit_code == 2 and "used twice" in res.stderr


def test_report_writes_figures_and_index(fitted, tmp_path):
    out = tmp_path / "report"
    res = CliRunner().invoke(cli, ["report", fitted["nn"], ASYM, "-o", str(out)])
    assert res.exit_code == 0, res.stderr
    names = sorted(p.name for p in out.iterdir())
    assert names == ["external_torque.png", "friction_time.png", "friction_velocity.png", "heatmap.png",
                     "index.html", "loss.png", "quadrants.png"]
    html = (out / "index.html").read_text()
    for name in (n for n in names if n.endswith(".png")):
        assert name in html
        assert (out / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_in_motion():
    qd = np.array([0.0, 0.001, 0.05, -0.5, 1.0])
    np.testing.assert_array_equal(metrics.in_motion(qd), [False, False, True, True, True])
    assert not metrics.in_motion(np.zeros(3)).any()


def test_demo_end_to_end_with_few_steps(tmp_path):
    res = CliRunner().invoke(cli, ["demo", "-o", str(tmp_path / "d"), "--data", str(SAMPLE), "--steps", "200", "-q"])
    assert res.exit_code == 0, res.stderr
    for label in ("LuGre", "NN_base", "Selmic", "NNACM", "NN_base + NN_add", "LuGre + NN_add"):
        assert f"| {label} |" in res.stdout
    summary = json.loads((tmp_path / "d" / "results.json").read_text())
    assert summary["steps"] == {"nn_base": 200, "baselines": 200}
    test_report.check_demo_page(tmp_path / "d")
    # adaptation is model-agnostic: adapting the LuGre model must beat the LuGre model itself
    for load in ("extended_asym", "extended_sym"):
        r = summary["results"]
        assert r["lugre_adapted"][load]["all"]["friction_mae"] < r["lugre"][load]["all"]["friction_mae"]


def test_evaluate_reports_rms_beside_mae(fitted, tmp_path):
    """The table's RMS cells are the JSON's rmse, which is the root mean square of predict's error."""
    import pyarrow.parquet as pq

    from fricli.core import logs

    runner = CliRunner()
    args = ["evaluate", "--model", f"lugre={fitted['lugre']}", "--log", f"asym={ASYM}"]
    table, out = runner.invoke(cli, args), json.loads(runner.invoke(cli, args + ["--json"]).stdout)
    r = out["results"][0]
    assert r["unit"] == "Nm"
    head, _, row = [line for line in table.stdout.splitlines() if line.startswith("|")]
    cells = dict(zip([c.strip() for c in head.split("|")[1:-1]], [c.strip() for c in row.split("|")[1:-1]]))
    assert cells["asym friction RMS [Nm]"] == f"{r['friction']['rmse']:.3f} ({r['friction_moving']['rmse']:.3f})"
    assert cells["asym friction MAE [Nm]"] == f"{r['friction']['mae']:.3f} ({r['friction_moving']['mae']:.3f})"
    assert cells["asym ext. torque RMS [Nm]"] == f"{r['external']['rmse']:.3f} ({r['external_moving']['rmse']:.3f})"
    pred = tmp_path / "p.parquet"
    assert runner.invoke(cli, ["predict", fitted["lugre"], ASYM, "-o", str(pred), "-q"]).exit_code == 0
    err = pq.read_table(pred).column("tau_f_pred").to_numpy() - logs.friction_target(logs.load_log(ASYM).signals)
    assert r["friction"]["rmse"] == pytest.approx(np.sqrt(np.mean(err ** 2)), rel=1e-6)
    assert r["friction"]["rmse"] > r["friction"]["mae"]


def test_a_log_without_acceleration_is_evaluated_without_deriving_one(tmp_path, monkeypatch):
    """A model that reads no acceleration is scored on a log without one as it is: the zero-phase
    filter over the velocity (which derives it) does not run, and the figures are those of the
    model on the log's own signals."""
    import pyarrow.parquet as pq

    from conftest import make_table
    from fricli import evaluate, models
    from fricli.core import logs, logs_motion
    from fricli.models.lugre import LuGreModel

    path = tmp_path / "no_qdd.parquet"
    pq.write_table(make_table(n=1500), path)
    model = LuGreModel(fc=5.0, fs=6.0, vs=0.05, delta=1.0, fv=10.0, sigma0=1e4, sigma1=5.0)
    models.save(str(tmp_path / "m.npz"), model, joint=None, axis="rotary", units={}, provenance={})
    filtered = []
    lowpass = logs_motion.lowpass
    monkeypatch.setattr(logs_motion, "lowpass", lambda *a, **k: filtered.append(1) or lowpass(*a, **k))
    (result,) = evaluate({"m": str(tmp_path / "m.npz")}, {"log": str(path)}).results
    assert filtered == []
    sig = logs.load_log(str(path)).signals
    assert result.friction["rmse"] == pytest.approx(metrics.errors(logs.friction_target(sig),
                                                                   model.predict(sig)[0])["rmse"], rel=1e-12)
