"""--from/--until: a time window on every command that reads a log (fricli.core.timewindow)."""

from __future__ import annotations

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import SAMPLE, invoke, make_table, write
from fricli import models
from fricli.core import errors, logs, timewindow

BASE = str(SAMPLE / "joint2_base.parquet")


def test_fit_on_the_first_60_percent_and_evaluate_on_the_rest(tmp_path):
    """With fricli's options alone: identify on the first 60 % of a log, then evaluate and predict
    on the other 40 %; the rows split the log exactly and the window is in the model's provenance."""
    model = tmp_path / "m.npz"
    res = invoke("identify", BASE, "-o", model, "--kind", "linear", "--until", "60%", "--json", "-q")
    assert res.exit_code == 0, res.output
    fitted = json.loads(res.stdout)
    t = logs.load_log(BASE).signals["t"]
    split = t[0] + 0.6 * (t[-1] - t[0])
    first, rest = t < split, t >= split
    assert fitted["fit"]["n"] == first.sum()
    _, meta = models.load(str(model))
    assert meta["provenance"]["job"]["options"]["window"] == {"from": None, "until": "60%"}
    assert meta["provenance"]["log_rows"] == first.sum()

    res = invoke("evaluate", "--model", model, "--log", BASE, "--from", "60%", "--json")
    assert res.exit_code == 0, res.output
    held_out = json.loads(res.stdout)["results"][0]["friction"]
    assert held_out["n"] == rest.sum() and first.sum() + rest.sum() == len(t)
    pred = tmp_path / "p.parquet"
    assert invoke("predict", model, BASE, "--from", "60%", "-o", pred, "-q").exit_code == 0
    out = pq.read_table(pred)
    np.testing.assert_array_equal(out.column("t").to_numpy(), t[rest])
    # the same numbers as the model on those rows, computed here without the window options
    sig = logs.load_log(BASE).signals
    model_, _ = models.load(str(model))
    err = model_.predict({k: v[rest] for k, v in sig.items()})[0] - logs.friction_target(sig)[rest]
    assert held_out["mae"] == pytest.approx(np.mean(np.abs(err)), rel=1e-12)
    np.testing.assert_allclose(out.column("tau_f_pred").to_numpy(), model_.predict(sig)[0][rest], rtol=0, atol=1e-12)


def test_seconds_bound_and_an_empty_window(tmp_path):
    res = invoke("evaluate", "--model", _lugre(tmp_path), "--log", BASE, "--from", 100, "--until", 150.5, "--json")
    assert res.exit_code == 0, res.output
    t = logs.load_log(BASE).signals["t"]
    assert json.loads(res.stdout)["results"][0]["friction"]["n"] == ((t >= 100) & (t < 150.5)).sum()
    res = invoke("identify", BASE, "-o", tmp_path / "x.npz", "--from", 1e6)
    assert res.exit_code == errors.DATA and "no rows from 1000000 s until the end" in res.stderr
    assert not (tmp_path / "x.npz").exists()
    res = invoke("predict", _lugre(tmp_path), BASE, "-o", tmp_path / "p.parquet", "--until", "-5")
    assert res.exit_code == errors.DATA and not (tmp_path / "p.parquet").exists()
    for bad in ("abc", "101%", "-3%", "nan"):
        res = invoke("identify", BASE, "-o", tmp_path / "x.npz", "--from", bad)
        assert res.exit_code == errors.USAGE and "--from" in res.stderr, bad


def test_a_bound_outside_an_epoch_clock_is_named_and_times_keep_their_seconds(tmp_path):
    """A controller's clock counts from 1970 (t = 1.714e9 s): --from 10, meant from the start, lies
    before the log and cuts nothing, which the command says; an empty window names the log's span
    to the millisecond, not as 1.714e+09 to 1.714e+09."""
    table = make_table(3000)
    t = table.column("t").to_numpy() + 1714000000.0
    table = table.set_column(table.schema.get_field_index("t"), table.schema.field("t"), [t])
    log = write(table, tmp_path / "epoch.parquet")
    model = tmp_path / "m.npz"
    res = invoke("identify", log, "-o", model, "--kind", "linear", "--from", 10, "-q")
    assert res.exit_code == 0, res.output
    assert "note: --from 10 s lies before the log's first time, t = 1714000000 s, and cuts nothing" in res.stderr
    res = invoke("predict", model, log, "-o", tmp_path / "p.parquet", "--until", "60%", "-q")
    assert res.exit_code == 0 and "cuts nothing" not in res.stderr, res.output
    res = invoke("predict", model, log, "-o", tmp_path / "p.parquet", "--until", 1e10, "-q")
    assert res.exit_code == 0 and "--until 10000000000 s lies after the log's last time" in res.stderr, res.output
    res = invoke("identify", log, "-o", model, "--until", 30)
    last = timewindow.seconds_text(float(t[-1]))
    assert res.exit_code == errors.DATA and f"(the log's t runs 1714000000 to {last} s)" in res.stderr, res.stderr
    assert "." in last and "e+" not in last
    assert timewindow.seconds_text(59.9) == "59.9" and timewindow.seconds_text(1714000059.9) == "1714000059.9"


def _lugre(tmp_path) -> str:
    from fricli.models.lugre import LuGreModel

    path = str(tmp_path / "lugre.npz")
    models.save(path, LuGreModel(7.0, 9.0, 0.04, 1.2, 12.0), joint=2, axis="rotary", units=logs.CANONICAL["rotary"],
                provenance={})
    return path


def test_every_log_reading_command_takes_the_window(tmp_path):
    lugre = _lugre(tmp_path)
    t = logs.load_log(BASE).signals["t"]
    cut = 250.0
    runs = {"train-base": ("train-base", BASE, "-o", tmp_path / "nn.npz", "--steps", 5),
            "adapt": ("adapt", lugre, BASE, "-o", tmp_path / "ad.npz", "--epochs", 1),
            "diagnose": ("diagnose", lugre, BASE, "--fix", "-o", tmp_path / "fix.npz", "--folds", 3,
                         "--effects", "offset")}
    for name, args in runs.items():
        res = invoke(*args, "--until", cut, "-q")
        assert res.exit_code == 0, (name, res.output)
        _, meta = models.load(str(args[args.index("-o") + 1]))
        assert meta["provenance"]["job"]["options"]["window"] == {"from": None, "until": f"{cut:g} s"}, name
        assert meta["provenance"]["log_rows"] == (t < cut).sum(), name
    ext = tmp_path / "e.parquet"
    assert invoke("estimate-ext", lugre, BASE, "-o", ext, "--from", cut, "-q").exit_code == 0
    assert pq.read_metadata(ext).num_rows == (t >= cut).sum()
    res = invoke("report", lugre, BASE, "-o", tmp_path / "rep", "--from", "90%")
    assert res.exit_code == 0, res.output


def test_the_window_reads_t_in_its_unit_and_keeps_rows_without_a_time(tmp_path):
    table = make_table(n=400, units={"t": "ms"})
    table = table.set_column(0, table.schema.field("t"), [np.arange(400) * 10.0])   # 0..3990 ms
    win = timewindow.Window(timewindow.Bound.parse("1"), timewindow.Bound.parse("2"))
    got = timewindow.slice_table(table, win)
    assert got.num_rows == 100 and got.column("t").to_numpy()[0] == 1000.0
    t = np.arange(10.0)
    t[4] = np.nan
    keep = timewindow.rows(t, *timewindow.Window(timewindow.Bound.parse("50%")).limits(t))
    assert keep.tolist() == [False] * 4 + [True] * 6                 # NaN kept: the log check reports it
    log = write(make_table(n=300), tmp_path / "l.parquet")
    res = invoke("predict", _lugre(tmp_path), log, "-o", tmp_path / "p.parquet", "--until", "100%", "-q")
    assert res.exit_code == 0 and pq.read_metadata(tmp_path / "p.parquet").num_rows == 300   # the last row too
