"""``fricli.estimators.whole_log.fit_joints``: the fitting commands on every joint of a log, as one
call, writing what the command writes."""

import numpy as np
import pyarrow as pa
import pytest

from conftest import invoke, write
from fricli import sim
from fricli import fit_joints
from fricli.fitting.optionspec import OptionError


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    parts = []
    for joint, seed in ((2, 5), (3, 6)):
        part = sim.simulate("base", joint=2, seed=seed)
        parts.append(part.set_column(part.schema.get_field_index("joint"), "joint",
                                     pa.array(np.full(part.num_rows, joint))))
    return write(pa.concat_tables(parts), tmp_path_factory.mktemp("arm") / "arm.parquet")


def _bytes(folder):
    return {p.name: p.read_bytes() for p in sorted(folder.iterdir())}


def test_identify_of_every_joint_writes_the_commands_files(arm, tmp_path):
    run = fit_joints("identify", arm, str(tmp_path / "call"), kind="linear", time_until="80%")
    assert [o.label for o in run.outcomes] == [2, 3] and run.folder == str(tmp_path / "call")
    assert all(o.made.summary["rmse"] > 0 for o in run.outcomes)
    res = invoke("identify", arm, "--kind", "linear", "--until", "80%", "-o", tmp_path / "cmd", "-q")
    assert res.exit_code == 0, res.output
    assert _bytes(tmp_path / "call") == _bytes(tmp_path / "cmd")
    again = fit_joints("identify", arm, str(tmp_path / "call"), kind="linear", time_until="80%", if_changed=True)
    assert again.unchanged


def test_one_joint_of_the_log_is_one_model_file(arm, tmp_path):
    run = fit_joints("identify", arm, str(tmp_path / "j3.npz"), kind="linear", joint=3)
    assert run.folder is None and [o.label for o in run.outcomes] == [3] and (tmp_path / "j3.npz").is_file()


@pytest.mark.parametrize("command, kwargs, option", [
    ("identify", {"kind": "nope"}, "kind"),
    ("identify", {"bogus": 1}, "bogus"),
    ("identify", {"time_from": "soon"}, "time_from"),
    ("predict", {}, "command"),
    ("adapt", {}, "base"),
    ("identify", {"base": "m.npz"}, "base"),
])
def test_a_wrong_option_is_named(arm, tmp_path, command, kwargs, option):
    with pytest.raises(OptionError) as err:
        fit_joints(command, arm, str(tmp_path / "out"), **kwargs)
    assert err.value.option == option
    assert not (tmp_path / "out").exists()
