"""The UR10e case study script (studies/ur10e/run_case_study.py) on a small part of the data.

Skips when ../shared/data/ur10e is absent, and when the robot extra (Pinocchio) or
``fricli import`` is not there: the script imports the CSV recordings with ``fricli import --urdf``.
"""

from __future__ import annotations

import importlib.util
import json
import math
import sys

import pytest
from conftest import ROOT, shared_data

SCRIPT = ROOT / "studies" / "ur10e" / "run_case_study.py"


@pytest.mark.slow
@pytest.mark.skipif(importlib.util.find_spec("pinocchio") is None, reason="needs the robot extra (pin)")
@pytest.mark.skipif(importlib.util.find_spec("fricli.robot") is None, reason="needs fricli import (fricli/robot)")
def test_case_study_script_runs_on_one_joint_and_one_validation_run(tmp_path, monkeypatch, fricli_in_process):
    data = shared_data("ur10e")
    # the script's main in this process, as ``python SCRIPT ...`` runs it (its folder first on sys.path)
    monkeypatch.syspath_prepend(str(SCRIPT.parent))
    spec = importlib.util.spec_from_file_location("run_case_study", SCRIPT)
    script = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(script)
    script.main(["--data", str(data), "--joints", "3", "--runs", "1", "--out", str(tmp_path)])
    text = (tmp_path / "docs" / "studies" / "case-study-ur10e.md").read_text()
    results = json.loads((tmp_path / "docs" / "studies" / "ur10e-results.json").read_text())
    row = results["joints"]["3"]
    for key in ("linear", "published", "lugre", "fixed_cad", "idim", "lugre_cal", "fixed"):
        assert math.isfinite(row[key]["moving"]) and row[key]["moving"] > 0
    # each run's own friction level, fitted on that run, can only lower the error it is added to
    assert 0 < row["fixed"]["own_friction_moving"] <= row["fixed"]["moving"]
    (level,) = row["fixed"]["run_levels"]       # one validation run: its level and its clock
    assert set(level) == {"start", "Fv", "Fc", "offset"} and all(math.isfinite(v) for v in level.values())
    fv, fc, _offset = row["linear_coef"]
    assert fv > 0 and fc > 0, "friction must oppose the motion: a sign or gain error in the import"
    # the payload's torque on the elbow is tens of Nm; the linear model's estimate must see most of it
    assert row["payload"]["reference_rms"] > 5.0
    assert row["payload"]["linear"] < row["payload"]["reference_rms"]
    # the elbow carries a large mass: the calibrated robot model lowers its error on the fitting run
    fit = results["calibration"]["fit"]["3"]
    assert fit["rms_after"] < fit["rms_before"]
    assert row["payload"]["fixed"] > 0 and row["payload"]["idim"] > 0
    assert "fricli import" in text and "--calibrate" in text and "ur10e-cal.urdf" in text
    assert (tmp_path / "docs" / "studies" / "img" / "ur10e-friction-ratio.png").stat().st_size > 0


def test_level_table_orders_a_days_runs_by_the_controller_clock():
    sys.path.insert(0, str(ROOT / "studies" / "ur10e"))
    import case_study_text

    def level(start, fv):
        return {"start": start, "Fv": fv, "Fc": 0.0, "offset": 0.0}

    # three runs of one day listed out of clock order, one run of another day
    runs = ["ur-20_02_05-b", "ur-20_02_05-a", "ur-20_02_05-c", "ur-20_02_06-a"]
    levels = [level(500.0, 0.1), level(100.0, 0.3), level(900.0, 0.22), level(50.0, -0.1)]
    res = {"validation_runs": runs,
           "joints": {6: {"fixed": {"run_levels": levels}, "linear_coef": [2.0, 1.0, 0.0]}}}
    text = "\n".join(case_study_text._level_lines(res, [6]))
    # by the clock the day runs 0.3 -> 0.1 -> 0.22: one of its two consecutive pairs is lower
    assert "lower in 1 of 2 pairs" in text
    assert "above zero on 3 of 4 runs" in text
    assert "+8 % of the fitting run's linear Fv" in text      # median 0.16 of Fv 2.0
    assert case_study_text._level_lines(res, []) == []
