"""One meaning per name across the commands: --hidden, -o -, --lowpass, the effect names."""

import click
import pytest
from click.testing import CliRunner

from conftest import invoke
from fricli import models, sim
from fricli.cli import COMMANDS, cli
from fricli.fitting.diagnosis import effects as diagnosis_effects
from fricli.sim import effects as sim_effects


@pytest.fixture(scope="module")
def base_log(tmp_path_factory):
    path = tmp_path_factory.mktemp("names") / "base.parquet"
    res = invoke("simulate", "--scenario", "base", "--seed", 1, "-o", path, "-q")
    assert res.exit_code == 0, res.stderr
    return path


def test_hidden_takes_layer_widths_in_train_base_and_adapt(base_log, tmp_path):
    base = tmp_path / "base.npz"
    res = invoke("train-base", base_log, "-o", base, "--hidden", "3,3", "--steps", 5, "--max-samples", 200, "-q")
    assert res.exit_code == 0, res.stderr
    assert models.load(str(base))[0].hidden_sizes == (3, 3)
    adapted = tmp_path / "adapted.npz"
    res = invoke("adapt", base, base_log, "-o", adapted, "--hidden", "4,2", "--epochs", 1, "--val-fraction", 0, "-q")
    assert res.exit_code == 0, res.stderr
    model, meta = models.load(str(adapted))
    assert meta["kind"] == "residual" and model.hidden_sizes == (4, 2)
    for command, args in (("train-base", [base_log]), ("adapt", [base, base_log])):
        res = invoke(command, *args, "-o", tmp_path / "x.npz", "--hidden", "3,x")
        assert res.exit_code == 2 and "layer sizes: positive integers" in res.stderr, (command, res.stderr)


def test_identify_writes_its_model_to_stdout_like_train_base_and_adapt(base_log, tmp_path):
    res = CliRunner().invoke(cli, ["identify", str(base_log), "-o", "-", "-q"])
    assert res.exit_code == 0, res.stderr
    path = tmp_path / "file.npz"
    assert invoke("identify", base_log, "-o", path, "-q").exit_code == 0
    assert res.stdout_bytes == path.read_bytes()   # the same model, written to stdout
    res = invoke("identify", base_log, "-o", "-", "--json")
    assert res.exit_code == 2 and "both write to stdout" in res.stderr


def test_lowpass_defaults_to_none_in_every_command():
    defaults = {}
    for name in COMMANDS:
        command = cli.get_command(click.Context(cli), name)
        defaults.update({name: p.default for p in command.params if p.name == "lowpass"})
    assert set(defaults) >= {"evaluate", "report", "estimate-ext"}
    assert set(defaults.values()) == {None}, defaults


def test_simulate_speaks_diagnose_effect_names_and_keeps_the_old_ones():
    assert set(sim_effects.ALIASES.values()) <= set(diagnosis_effects.NAMES) & set(sim_effects.EFFECTS)
    assert not set(sim_effects.ALIASES) & set(sim_effects.EFFECTS)
    for old, new in sim_effects.ALIASES.items():
        a = sim.simulate("base", joint=2, effects=[old], seed=4)
        b = sim.simulate("base", joint=2, effects=[f"{new}"], seed=4)
        assert a.equals(b)
        assert [e["name"] for e in sim.metadata(a)["effects"]] == [new]
    res = invoke("simulate", "--effect", "asymmetry=0.1", "--effect", "direction", "-o", "-")
    assert res.exit_code == 2 and "given twice" in res.stderr
