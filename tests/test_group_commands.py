"""A coupled group's model in every command that applies a model of one joint (docs/drives.md):
evaluate, report, diagnose (--fix), adapt and export take the group's file, through the member of
each joint (kind coupled-member), with the partners' velocities from the same log."""

from __future__ import annotations

import json

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from conftest import invoke as run
from fricli import models
from fricli.core import logs, metrics
from fricli.models import coupled
from fricli.sim.coupled import simulate_coupled

GROUP = [5, 6]
SHIFT = 0.4      # [Nm] added to the wrist joints' motor torque while they move forwards (a direction asymmetry)


def _shifted(table: pa.Table) -> pa.Table:
    """``table`` with SHIFT added to tau_m of the wrist joints where qd > 0: what the group's model
    does not have, for adapt and diagnose --fix to find."""
    joint, qd = table.column("joint").to_numpy(), table.column("qd").to_numpy()
    tau_m = table.column("tau_m").to_numpy() + SHIFT * (np.isin(joint, GROUP) & (qd > 0))
    i = table.schema.get_field_index("tau_m")
    return table.set_column(i, table.schema.field(i), pa.array(tau_m))


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    """Logs of the simulated arm (6 s at 500 Hz): training, held-out, the held-out one shifted,
    and the held-out one without joint 6's rows; and the wrist's model fitted on the training log."""
    folder = tmp_path_factory.mktemp("group")
    out = {}
    for name, seed in (("train", 1), ("test", 2)):
        table = simulate_coupled(duration=6.0, rate_hz=500.0, rng=np.random.default_rng(seed)).table
        out[name] = folder / f"{name}.parquet"
        logs.write_table(table, str(out[name]))
    test = pq.read_table(out["test"])
    out["shifted"] = folder / "shifted.parquet"
    logs.write_table(_shifted(test), str(out["shifted"]))
    out["only5"] = folder / "only5.parquet"
    logs.write_table(test.filter(pa.array(test.column("joint").to_numpy() != 6)), str(out["only5"]))
    out["group"] = folder / "wrist.npz"
    res = run("identify", out["train"], "--coupling", "--joint", 5, "-o", out["group"], "-q")
    assert res.exit_code == 0, res.output
    out["folder"] = folder
    return out


def _group_figures(arm, log: str) -> dict:
    """{joint: friction errors (mae, rmse, max)} of the group's model over every row of ``log``,
    from ``predict_group`` on the group's rows."""
    group = models.load(str(arm["group"]))[0]
    _, datas = coupled.group_rows(pq.read_table(arm[log]), GROUP, log)
    pred = group.predict_group(coupled.stack(datas, "qd"))
    return {j: metrics.errors(logs.friction_target(d.signals), pred[:, c]) for c, (j, d) in enumerate(zip(GROUP, datas))}


def _joint_log(arm, log: str, joint, model) -> logs.Log:
    """The log of ``joint`` with the partners' velocities ``model`` reads."""
    table = pq.read_table(arm[log])
    data = logs.from_table(table, name=log, joint=joint)
    coupled.add_partners(model, data, table)
    return data


def test_a_member_saves_and_loads_to_the_same_predictions(arm, tmp_path):
    group = models.load(str(arm["group"]))[0]
    member = group.member(6)
    data = _joint_log(arm, "test", 6, member)
    assert set(data.signals) >= {"qd@5"}
    models.save_for_log(str(tmp_path / "m6.npz"), member, data, rows_used=len(data))
    loaded, meta = models.load(str(tmp_path / "m6.npz"))
    assert loaded.kind == meta["kind"] == "coupled-member" and meta["joint"] == 6
    assert meta["inputs"] == ["qd", "qd@5", "t"]
    assert loaded.group.kind == "coupled" and loaded.joint == 6
    pred = loaded.predict(data.signals)[0]
    assert np.array_equal(pred, member.predict(data.signals)[0])
    _, datas = coupled.group_rows(pq.read_table(arm["test"]), GROUP, "test")
    assert np.array_equal(pred, group.predict_group(coupled.stack(datas, "qd"))[:, 1])
    # a damaged member (its joint not in its group) is one line, exit 4
    spec, arrays = models.to_parts(loaded)
    spec["params"]["joint"] = 3
    with pytest.raises(models.ModelFileError, match="damaged coupled-member model"):
        models.from_parts(spec, arrays)


def test_evaluate_gives_each_joint_of_the_group_what_the_group_model_gives(arm):
    res = run("evaluate", "--model", f"g={arm['group']}", "--log", f"test={arm['test']}", "--json", "-q")
    assert res.exit_code == 0, res.output
    results = {r["joint"]: r for r in json.loads(res.output)["results"]}
    assert sorted(results) == GROUP
    expected = _group_figures(arm, "test")
    for j in GROUP:
        for key in ("mae", "rmse", "max"):
            assert results[j]["friction"][key] == pytest.approx(expected[j][key], rel=1e-12)
    res = run("evaluate", "--model", f"g={arm['group']}", "--log", f"test={arm['test']}", "--joint", 6, "--json", "-q")
    assert res.exit_code == 0, res.output
    assert [r["joint"] for r in json.loads(res.output)["results"]] == [6]


def test_report_writes_a_report_per_joint_of_the_group(arm, tmp_path):
    res = run("report", arm["group"], arm["test"], "-o", tmp_path / "rep")
    assert res.exit_code == 0, res.output
    assert (tmp_path / "rep" / "joint_5" / "index.html").is_file()
    assert (tmp_path / "rep" / "joint_6" / "index.html").is_file()
    expected = _group_figures(arm, "test")
    assert (f"joint 5 {expected[5]['mae']:.3f} Nm, joint 6 {expected[6]['mae']:.3f} Nm") in res.output


def test_diagnose_each_joint_of_the_group(arm):
    res = run("diagnose", arm["group"], arm["test"], "--json")
    assert res.exit_code == 0, res.output
    found = json.loads(res.output)["joints"]
    assert sorted(found) == ["5", "6"]
    for j in ("5", "6"):      # the group's model has the coupling: nothing is missing on its own log
        assert found[j]["added"] == []
    res = run("diagnose", arm["group"], arm["shifted"], "--joint", 6, "--json")
    assert res.exit_code == 0, res.output
    assert json.loads(res.output)["added"]


def test_diagnose_fix_writes_per_joint_models_over_the_member(arm, tmp_path):
    fixed = tmp_path / "fixed"
    res = run("diagnose", arm["group"], arm["shifted"], "--fix", "-o", fixed, "--json")
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in fixed.iterdir()) == ["joint_5.npz", "joint_6.npz"]
    before = _group_figures(arm, "shifted")
    for j in GROUP:
        model, meta = models.load(str(fixed / f"joint_{j}.npz"))
        assert model.kind == "augmented" and model.base.kind == "coupled-member" and meta["joint"] == j
        assert model.effects
        out = tmp_path / f"p{j}.parquet"
        res = run("predict", fixed, arm["shifted"], "--joint", j, "-o", out, "-q")
        assert res.exit_code == 0, res.output
        pred = pq.read_table(out).column("tau_f_pred").to_numpy()
        data = _joint_log(arm, "shifted", j, model)
        assert np.array_equal(pred, model.predict(data.signals)[0])
        mae = metrics.errors(logs.friction_target(data.signals), pred)["mae"]
        assert mae < 0.8 * before[j]["mae"], (j, mae, before[j]["mae"])
    res = run("evaluate", "--model", f"fixed={fixed}", "--log", arm["shifted"], "--joint", 5, "--json")
    assert res.exit_code == 0, res.output


def test_adapt_puts_a_residual_network_on_each_joint_of_the_group(arm, tmp_path):
    adapted = tmp_path / "adapted"
    res = run("adapt", arm["group"], arm["shifted"], "--max-seconds", 4, "-o", adapted, "--json", "-q")
    assert res.exit_code == 0, res.output
    summary = json.loads(res.output)["joints"]
    assert sorted(summary) == ["5", "6"] and all(summary[j]["adapted"] for j in summary)
    before = _group_figures(arm, "shifted")
    for j in GROUP:
        model, meta = models.load(str(adapted / f"joint_{j}.npz"))
        assert model.kind == "residual" and model.base.kind == "coupled-member" and meta["joint"] == j
        res = run("estimate-ext", adapted, arm["shifted"], "--joint", j, "-o", tmp_path / f"e{j}.parquet", "-q")
        assert res.exit_code == 0, res.output
        pred = pq.read_table(tmp_path / f"e{j}.parquet").column("tau_f_pred").to_numpy()
        data = _joint_log(arm, "shifted", j, model)
        np.testing.assert_allclose(pred, model.predict(data.signals)[0], rtol=0, atol=1e-12)
        assert metrics.errors(logs.friction_target(data.signals), pred)["mae"] < 0.8 * before[j]["mae"]


def test_a_fleet_adapt_job_on_a_group_model_writes_what_the_command_writes(arm, tmp_path):
    from fricli.fleet import manifest, pipelines

    res = run("adapt", arm["group"], arm["shifted"], "--joint", 6, "--max-seconds", 2, "-o", tmp_path / "cmd.npz",
              "-q")
    assert res.exit_code == 0, res.output
    job = manifest.Job(robot="r1", joint="6", log=str(arm["shifted"]), date="2026-01-01", pipeline="adapt",
                       model=str(tmp_path / "fleet" / "a.npz"), options=(("max_seconds", 2.0),), base=str(arm["group"]))
    result = pipelines.run(job)
    assert result["status"] == "ok", result["reason"]
    assert (tmp_path / "fleet" / "a.npz").read_bytes() == (tmp_path / "cmd.npz").read_bytes()


@pytest.mark.parametrize("kind", ["fixed", "adapted"])
def test_export_of_a_model_over_a_member_matches_predict_double(arm, tmp_path, kind):
    import export_check as check

    from fricli.export import c

    if check.compiler() is None:
        pytest.skip("no compiler")
    out = tmp_path / "m.npz"
    if kind == "fixed":
        res = run("diagnose", arm["group"], arm["shifted"], "--joint", 6, "--fix", "-o", out, "-q")
    else:
        res = run("adapt", arm["group"], arm["shifted"], "--joint", 6, "--max-seconds", 4, "-o", out, "-q")
    assert res.exit_code == 0, res.output
    model = models.load(str(out))[0]
    assert model.kind == {"fixed": "augmented", "adapted": "residual"}[kind] and model.base.kind == "coupled-member"
    res = run("export", out, "--prefix", "w6", "-o", tmp_path / "w6.h", "-q")
    assert res.exit_code == 0, res.output
    check.build(str(tmp_path / "w6.h"), "w6", str(tmp_path / "drv"))
    res = run("predict", out, arm["shifted"], "--joint", 6, "--precision", "double", "-o", tmp_path / "p.parquet", "-q")
    assert res.exit_code == 0, res.output
    ref = pq.read_table(tmp_path / "p.parquet").column("tau_f_pred").to_numpy()
    names = c.signals_of(model)
    assert "qd@5" in names
    got = check.run(str(tmp_path / "drv"), check.signal_matrix(_joint_log(arm, "shifted", 6, model).signals, names))
    assert np.max(np.abs(got - ref) / (1e-12 + np.abs(ref))) <= 1e-9


@pytest.mark.parametrize("command", ["evaluate", "report", "diagnose", "adapt", "diagnose --fix", "predict"])
def test_a_log_without_the_partners_rows_is_refused(arm, tmp_path, command):
    log = arm["only5"]
    args = {"evaluate": ["evaluate", "--model", arm["group"], "--log", log],
            "report": ["report", arm["group"], log, "-o", tmp_path / "rep"],
            "diagnose": ["diagnose", arm["group"], log],
            "adapt": ["adapt", arm["group"], log, "-o", tmp_path / "a.npz"],
            "diagnose --fix": ["diagnose", arm["group"], log, "--fix", "-o", tmp_path / "a.npz"],
            "predict": ["predict", arm["group"], log, "-o", tmp_path / "a.npz"]}[command]
    res = run(*args)
    assert res.exit_code == 3, res.output
    assert res.output.strip() == (f"fricli: error: {log}: the friction of joint 5 depends on joint 6 (they share "
                                  "motors), and the log has no usable rows of joint 6")
    assert not (tmp_path / "a.npz").exists() and not (tmp_path / "rep").exists()


def test_diagnose_calibrate_refuses_a_group_model_it_cannot_refit(arm, tmp_path):
    res = run("diagnose", arm["group"], arm["test"], "--fix", "--calibrate", tmp_path / "cal.urdf", "-o",
              tmp_path / "fixed")
    assert res.exit_code == 4, res.output
    assert "joints 5, 6 share the model of their coupled group, which it does not refit" in res.output
    assert not (tmp_path / "fixed").exists() and not (tmp_path / "cal.urdf").exists()
