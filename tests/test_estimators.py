"""The estimator contract, checked on every estimator (as scikit-learn's parametrize_with_checks):
parameters stored as given and checked against the option spec, fit returns self, fitted
attributes end in _ and appear only with fit, unfitted use refused, the same seed gives the same
model, a saved model loads and predicts the same, and save writes the bytes of the command's
model file with the same options on the same log."""

import hashlib
import json
import shutil

import numpy as np
import pytest
from click.testing import CliRunner

import fricli
from conftest import SAMPLE
from fricli import GMS, Diagnosis, Linear, LuGre, Network, NotFittedError, OptionError, Residual
from fricli.cli import cli

BASE, ADAPT, EXTENDED = "joint2_base.parquet", "joint2_adapt.parquet", "joint2_extended_asym.parquet"
UNTIL = "40%"   # a part of the long logs: the contract, not the fit, is under test


def command(*args):
    res = CliRunner().invoke(cli, [str(a) for a in args])
    assert res.exit_code == 0, res.output
    return res


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    out = tmp_path_factory.mktemp("estimators")
    for name in (BASE, ADAPT, EXTENDED):
        shutil.copy(SAMPLE / name, out / name)
    command("identify", out / BASE, "--until", UNTIL, "-o", out / "lugre.npz", "-q")
    return out


# (id, estimator factory (folder -> estimator), the log and its reading keywords, the command's arguments
# before -o; "{}" is the folder)
CASES = [
    ("lugre", lambda f: LuGre(hold=0.3), BASE, dict(time_until=UNTIL),
     ["identify", "{}/" + BASE, "--hold", "0.3", "--until", UNTIL]),
    ("linear", lambda f: Linear(asymmetric=True), BASE, dict(cutoff=40.0),
     ["identify", "{}/" + BASE, "--kind", "linear-asymmetric", "--cutoff", "40"]),
    ("gms", lambda f: GMS(), BASE, dict(time_until=UNTIL),
     ["identify", "{}/" + BASE, "--kind", "gms", "--until", UNTIL]),
    ("network", lambda f: Network(steps=30, seed=3, hidden="8,8"), BASE, dict(time_until=UNTIL),
     ["train-base", "{}/" + BASE, "--steps", "30", "--seed", "3", "--hidden", "8,8", "--until", UNTIL]),
    ("residual", lambda f: Residual(str(f / "lugre.npz"), epochs=2, seed=1), ADAPT, {},
     ["adapt", "{}/lugre.npz", "{}/" + ADAPT, "--epochs", "2", "--seed", "1"]),
    ("diagnosis", lambda f: Diagnosis(str(f / "lugre.npz"), folds=5), EXTENDED, dict(time_until=UNTIL),
     ["diagnose", "{}/lugre.npz", "{}/" + EXTENDED, "--fix", "--folds", "5", "--until", UNTIL]),
]
IDS = [c[0] for c in CASES]


@pytest.fixture(scope="module", params=CASES, ids=IDS)
def case(request, folder):
    """(estimator unfitted, the same fitted, the log read, the command's model file)."""
    _, make, log_name, reading, args = request.param
    log = fricli.read_log(folder / log_name, **reading)
    unfitted, fitted = make(folder), make(folder)
    attributes_before = set(vars(fitted))
    returned = fitted.fit(log)
    out = folder / f"{request.param[0]}-command.npz"
    command(*[a.replace("{}", str(folder)) for a in args], "-o", out, "-q")
    return dict(unfitted=unfitted, fitted=fitted, returned=returned, before=attributes_before, log=log,
                command_file=out, make=lambda: make(folder), folder=folder)


def test_fit_returns_self(case):
    assert case["returned"] is case["fitted"]


def test_the_constructor_stores_the_parameters_unchanged(case):
    est = case["unfitted"]
    params = est.get_params()
    again = type(est)(**params)
    for name, value in params.items():
        assert getattr(again, name) is value
    # the values given, not checked or converted copies: "8,8" stays a text, 0.3 a float
    if isinstance(est, Network):
        assert params["hidden"] == "8,8" and params["steps"] == 30
    if isinstance(est, LuGre):
        assert params == {"hold": 0.3, "travel": 0.002, "samples": "auto", "settle": 0.01, "refine": False}


def test_fitting_leaves_the_parameters_as_given(case):
    assert case["fitted"].get_params() == case["unfitted"].get_params()


def test_an_unknown_parameter_is_refused_by_name(case):
    with pytest.raises(OptionError, match=r"unknown \w+ option 'sigma'") as err:
        type(case["unfitted"])(**case["unfitted"].get_params(), sigma=1.0)
    assert err.value.option == "sigma"


def wrong(option):
    """A value ``option`` must refuse."""
    return {"flag": "yes", "choice": "no-such-choice", "int": 1.5, "float": "fast", "sizes": "0,x",
            "text": object()}[option.type]


def test_every_wrong_value_is_refused_naming_its_option(case):
    est = case["unfitted"]
    assert est._spec or isinstance(est, GMS)
    for name, option in est._spec.items():
        with pytest.raises(OptionError) as err:
            type(est)(**{**est.get_params(), name: wrong(option)})
        assert err.value.option == name and name in str(err.value), name


def test_every_number_refuses_infinity_and_a_seed_a_negative_value(case):
    """inf is no option value (the command line says "not a finite number"); a negative seed
    would fail inside numpy once the fit had started."""
    est = case["unfitted"]
    for name, option in est._spec.items():
        if option.type == "float":
            with pytest.raises(OptionError) as err:
                type(est)(**{**est.get_params(), name: float("inf")})
            assert err.value.option == name
    if "seed" in est._spec:
        with pytest.raises(OptionError, match="seed = -1: expected an integer >= 0"):
            type(est)(**{**est.get_params(), "seed": -1})
        assert type(est)(**{**est.get_params(), "seed": np.int64(2)}).get_params()["seed"] == 2


def test_a_model_of_one_joint_refuses_the_log_of_another(case):
    """As the commands refuse it (exit 4): a model fitted on joint 2 predicts no rows of joint 4."""
    from fricli.core.errors import ModelFileError

    with pytest.raises(ModelFileError, match="fitted on joint 2, not on joint 4"):
        case["fitted"].predict(SAMPLE / "joint4_adapt.parquet")


def test_options_that_do_not_go_together_are_refused():
    with pytest.raises(OptionError, match="velocity_input") as err:
        Network(velocity_input="linear")
    assert err.value.option == "velocity_input"
    Network(arch="mlp", velocity_input="linear")


def test_fitted_attributes_end_in_an_underscore_and_come_with_fit(case):
    fitted, unfitted = case["fitted"], case["unfitted"]
    added = set(vars(fitted)) - case["before"]
    assert {"model_", "summary_", "meta_"} <= added
    assert all(name.endswith("_") and not name.startswith("_") for name in added), added
    assert not any(name.endswith("_") for name in vars(unfitted))
    assert hasattr(fitted.model_, "predict") and isinstance(fitted.summary_, dict)


def test_unfitted_use_is_refused(case, tmp_path):
    est = case["unfitted"]
    with pytest.raises(NotFittedError, match="not fitted"):
        est.predict(case["log"])
    with pytest.raises(NotFittedError):
        est.save(tmp_path / "m.npz")
    assert isinstance(NotFittedError("x"), fricli.FricliError)


def test_predict_gives_the_friction_of_every_row(case):
    pred = case["fitted"].predict(case["log"])
    assert pred.shape == (len(case["log"]),) and pred.dtype == np.float64 and np.isfinite(pred).all()


def test_the_same_seed_gives_the_same_predictions(case):
    again = case["make"]().fit(case["log"])
    np.testing.assert_array_equal(again.predict(case["log"]), case["fitted"].predict(case["log"]))


def test_a_saved_model_loads_and_predicts_the_same(case, tmp_path):
    path = tmp_path / "model.npz"
    case["fitted"].save(path)
    loaded = fricli.load_model(path)
    np.testing.assert_array_equal(loaded.predict(case["log"]), case["fitted"].predict(case["log"]))
    copy = tmp_path / "copy.npz"
    loaded.save(copy)
    assert copy.read_bytes() == path.read_bytes()


def test_save_writes_the_commands_model_file(case, tmp_path):
    path = tmp_path / "model.npz"
    case["fitted"].save(path)
    assert path.read_bytes() == case["command_file"].read_bytes()


def test_a_log_path_is_read_as_the_command_reads_it(folder, tmp_path):
    LuGre().fit(folder / BASE).save(tmp_path / "a.npz")
    command("identify", folder / BASE, "-o", tmp_path / "b.npz", "-q")
    assert (tmp_path / "a.npz").read_bytes() == (tmp_path / "b.npz").read_bytes()


def test_another_seed_gives_another_network(folder):
    log = fricli.read_log(folder / BASE, time_until=UNTIL)
    a, b = (Network(steps=30, seed=s, hidden="8,8").fit(log).predict(log) for s in (0, 1))
    assert not np.array_equal(a, b)


def test_the_base_of_a_residual_may_be_a_path_a_loaded_model_or_a_fitted_estimator(folder):
    log = fricli.read_log(folder / ADAPT)
    path = folder / "lugre.npz"
    by_path = Residual(str(path), epochs=2, seed=1).fit(log)
    loaded = Residual(fricli.load_model(path), epochs=2, seed=1).fit(log)
    assert loaded._model_bytes() == by_path._model_bytes()
    estimator = LuGre().fit(fricli.read_log(folder / BASE, time_until=UNTIL))
    in_memory = Residual(estimator, epochs=2, seed=1).fit(log)
    np.testing.assert_array_equal(in_memory.predict(log), by_path.predict(log))
    # the input model is recorded by the sha256 of its bytes, which are the file's
    job = in_memory.meta_["provenance"]["job"]
    assert job == by_path.meta_["provenance"]["job"]
    assert job["inputs"]["base"] == hashlib.sha256(path.read_bytes()).hexdigest()
    with pytest.raises(NotFittedError):
        Residual(LuGre()).fit(log)


def test_a_diagnosis_says_what_diagnose_says(folder):
    log = fricli.read_log(folder / EXTENDED, time_until=UNTIL)
    est = Diagnosis(str(folder / "lugre.npz"), effects="offset,level", max_effects=1).fit(log)
    res = CliRunner().invoke(cli, ["diagnose", str(folder / "lugre.npz"), str(folder / EXTENDED), "--until", UNTIL,
                                   "--effects", "offset,level", "--max-effects", "1", "--json"])
    assert res.exit_code == 0, res.output
    import json

    printed = json.loads(res.stdout)
    assert printed["added"] == est.added_ == est.diagnosis_.to_json()["added"]
    assert len(est.added_) <= 1
    with pytest.raises(OptionError, match="effects") as err:
        Diagnosis("m.npz", effects="gear")
    assert err.value.option == "effects"


def test_the_diagnosis_options_are_the_commands():
    """Diagnosis's defaults and bounds are those of fricli diagnose's options."""
    import click

    diagnose = cli.get_command(click.Context(cli), "diagnose")
    ctx = click.Context(diagnose)
    command_params = {p.name: p for p in diagnose.params}
    for name, option in Diagnosis._spec.items():
        param = command_params["only" if name == "effects" else name]
        default = param.get_default(ctx)
        assert (bool(default) if option.type == "flag" else default) == option.default, name
        low = getattr(param.type, "min", None)
        high = getattr(param.type, "max", None)
        assert (low, high) == (option.low, option.high), name


def arm_files(folder):
    """arm.urdf and arm.parquet in ``folder``: a four-joint arm's URDF and a whole-arm log of it,
    simulated from masses off the URDF's (tests/test_calibrate.py)."""
    pytest.importorskip("pinocchio")
    from test_calibrate import URDF, harmonics, simulate, true_model, write_log

    rng = np.random.default_rng(7)
    model, _ = true_model(rng)
    fit = harmonics(rng, 1500, (0.2, 0.45, 0.7, 1.1), 0.25)
    (folder / "arm.urdf").write_text(URDF)
    write_log(folder / "arm.parquet", *fit, simulate(model, *fit))
    return folder / "arm.urdf", folder / "arm.parquet"


def cad_arm_files(folder, urdf: str = "cad.urdf", raw: str = "raw.parquet", log: str = "arm.parquet"):
    """A four-joint arm simulated with masses and centres of mass up to 30 % off the URDF's and
    noise (``raw``), the URDF (``urdf``) and the log with tau_g and tau_dyn computed from it
    (``log``, ``fricli dynamics``), in ``folder``: (URDF, log)."""
    pytest.importorskip("pinocchio")
    import test_calibrate as sim_arm

    rng = np.random.default_rng(11)
    model, _ = sim_arm.true_model(rng, scale=0.3)
    t, q, qd, qdd = sim_arm.harmonics(rng, 2000, (0.2, 0.45, 0.7, 1.1), 0.25)
    sim_arm.write_log(folder / raw, t, q, qd, qdd, sim_arm.simulate(model, t, q, qd, qdd, rng, noise=0.05))
    (folder / urdf).write_text(sim_arm.URDF)
    command("dynamics", folder / raw, "--urdf", folder / urdf, "--match", "order", "-o", folder / log, "-q")
    return folder / urdf, folder / log


def test_calibration_writes_the_commands_urdf(tmp_path):
    from fricli import Calibration

    urdf, log = arm_files(tmp_path)
    est = Calibration(str(urdf), match="order", friction="stribeck", edge=0.2, time_from="10%")
    assert est.get_params()["urdf"] == str(urdf) and est.get_params()["edge"] == 0.2
    with pytest.raises(NotFittedError):
        est.save(tmp_path / "x.urdf")
    assert est.fit(log) is est
    assert not [name for name in vars(Calibration(str(urdf))) if name.endswith("_")]
    est.save(tmp_path / "estimator.urdf")
    command("calibrate", log, "--urdf", urdf, "--match", "order", "--friction", "stribeck", "--edge", "0.2",
            "--from", "10%", "-o",
            tmp_path / "command.urdf", "-q")
    assert (tmp_path / "estimator.urdf").read_bytes() == (tmp_path / "command.urdf").read_bytes()
    reports = [json.loads((tmp_path / f"{name}.calibration.json").read_text()) for name in ("estimator", "command")]
    for report, name in zip(reports, ("estimator", "command")):      # the report beside the URDF, as the command's
        assert report.pop("output") == str(tmp_path / f"{name}.urdf")
        assert report.pop("report") == str(tmp_path / f"{name}.calibration.json")
    assert reports[0] == reports[1]
    assert set(est.friction_) == {"1", "2", "3", "4"} and est.report_["consistency"]["ok"]
    for name, value in (("friction", "coulomb"), ("prior", "strong"), ("gravity", (0, 0)), ("edge", -1.0),
                        ("urdf_joints", ["j1"]), ("time_until", "120%")):
        with pytest.raises(OptionError) as err:
            Calibration(str(urdf), **{name: value})
        assert err.value.option == name


def test_external_torque_is_estimate_exts(folder, tmp_path):
    import pyarrow.parquet as pq

    log = folder / EXTENDED
    out = tmp_path / "ext.parquet"
    command("estimate-ext", folder / "lugre.npz", log, "--lowpass", "5", "-o", out, "-q")
    written = pq.read_table(out)
    model = fricli.load_model(folder / "lugre.npz")
    np.testing.assert_allclose(fricli.external_torque(model, log, lowpass_hz=5.0),
                               written.column("tau_ext_pred").to_numpy(), rtol=1e-12, atol=1e-9)
    np.testing.assert_allclose(model.predict(log), written.column("tau_f_pred").to_numpy(), rtol=1e-12, atol=1e-9)
    with pytest.raises(NotFittedError):
        fricli.external_torque(LuGre(), log)


def test_read_log_refuses_a_wrong_reading_option_by_name(folder):
    for name, value in (("cutoff", -1.0), ("drop_invalid", "no"), ("time_until", "150%"), ("time_from", "soon")):
        with pytest.raises(OptionError) as err:
            fricli.read_log(folder / BASE, **{name: value})
        assert err.value.option == name and name in str(err.value)
    log = fricli.read_log(folder / BASE, cutoff=30, time_from=12.5)
    assert log.reading["cutoff"] == 30.0 and log.window == {"from": "12.5 s", "until": None}
    assert log.signals["t"][0] >= 12.5


def test_a_coupled_groups_model_reads_the_other_joints_of_the_log(tmp_path):
    """A model of a coupled group (identify --coupling) predicts and is adapted on one joint of a
    whole-arm log as the commands do it: with the velocities of the group's other joints."""
    import pyarrow.compute as pc
    import pyarrow.parquet as pq

    from fricli.core import logs
    from fricli.core.errors import DataError
    from fricli.sim.coupled import simulate_coupled

    arm = tmp_path / "arm.parquet"
    logs.write_table(simulate_coupled(duration=8.0, rate_hz=500.0, rng=np.random.default_rng(11)).table, str(arm))
    group = tmp_path / "group.npz"
    command("identify", arm, "--coupling", "--joint", 5, "-o", group, "-q")
    command("predict", group, arm, "--joint", 5, "-o", tmp_path / "pred.parquet", "-q")
    command("adapt", group, arm, "--joint", 5, "--epochs", 2, "-o", tmp_path / "adapted.npz", "-q")
    log = fricli.read_log(arm, joint=5)
    written = pq.read_table(tmp_path / "pred.parquet")
    expected = written.filter(pc.equal(written.column("joint"), 5)).column("tau_f_pred").to_numpy()
    np.testing.assert_array_equal(fricli.load_model(group).predict(log), expected)
    Residual(str(group), epochs=2).fit(log).save(tmp_path / "estimator.npz")
    assert (tmp_path / "estimator.npz").read_bytes() == (tmp_path / "adapted.npz").read_bytes()
    table, digest = logs.read_table(str(arm))
    alone = logs.from_table(table, name=str(arm), sha256=digest, joint=5)   # no other joint's rows kept
    with pytest.raises(DataError, match="coupled group"):
        fricli.load_model(group).predict(alone)


def test_set_params_checks_as_the_constructor_does():
    est = Network(steps=5)
    assert est.set_params(seed=2) is est and est.seed == 2 and est.steps == 5
    with pytest.raises(OptionError) as err:
        est.set_params(steps=0)
    assert err.value.option == "steps" and est.steps == 5
    assert repr(est) == "Network(steps=5, seed=2)"
    assert repr(Residual("base.npz", epochs=3)) == "Residual(base='base.npz', epochs=3)"
