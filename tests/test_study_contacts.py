"""The simulated-contacts study (studies/contacts/run_simulated_contacts.py): where it puts its
contacts and how it scores one replay, on small arrays."""

import importlib.util

import numpy as np

from conftest import ROOT

SCRIPT = ROOT / "studies" / "contacts" / "run_simulated_contacts.py"


def script():
    spec = importlib.util.spec_from_file_location("run_simulated_contacts", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_onsets_fall_where_the_joint_moves_one_per_window():
    study = script()
    t = np.arange(0, 40, 0.01)
    qd = np.where((t % 4) < 1, 0.0, 0.3)          # at rest for the first second of every 4 s
    picked = study.onsets(t, qd, 0.02, np.random.default_rng(0))
    assert picked and all(abs(qd[i]) > 0.02 for i in picked)
    starts = t[picked]
    assert starts[0] >= study.FIRST and starts[-1] + study.LENGTH + 1.0 < t[-1]
    assert np.all(np.diff(starts) > study.WINDOW / 2)       # each contact in a window of its own
    assert len(picked) == len(np.arange(t[0] + study.FIRST, t[-1] - study.WINDOW / 2 - study.LENGTH - 1.0, study.WINDOW))


def test_the_late_contacts_text_says_how_many_and_why():
    study = script()
    results = [{"rate": 1000.0, "delays": [0.012, 0.026, None], "against": [0.0, 0.4, 0.5]},
               {"rate": 100.0, "delays": [0.03], "against": [0.9]}]
    text = study.late_text(results)
    assert text.startswith("At 500 Hz and 1 kHz, 2 of 3 contacts")
    assert "by 0.45 x the threshold in force (median; 0.00 for the others)" in text
    assert study.late_text([{"rate": 1000.0, "delays": [0.01], "against": [0.0]}]) == ""
