"""The simulator, `fricli simulate` and the sample data."""

import functools
import io
import shlex

import numpy as np
import pyarrow.parquet as pq
import pytest
from click.testing import CliRunner

from conftest import ROOT, SAMPLE
from fricli.core import logs
from fricli.numerics import physics
from fricli.cli import cli
from fricli.sim import EFFECTS, JOINTS, metadata, simulate, true_params
from fricli.sim import effects as fx
from fricli.sim import trajectories

EXT_S = 60.0   # extended logs in these tests are shortened to keep the file fast


@functools.lru_cache(maxsize=None)
def sim(scenario, joint=2, load="none", effects=(), seed=1, rate=100.0, friction_state=None):
    duration = EXT_S if scenario == "extended" else None
    return simulate(scenario, joint, load=load, effects=effects, seed=seed, rate=rate, duration=duration,
                    friction_state=friction_state)


def signals(table):
    return logs.from_table(table, name="sim").signals


def noise(sig):
    return logs.friction_target(sig) - sig["tau_f_true"]


# ------------------------------------------------------------------ determinism


def test_same_seed_same_table_different_seed_different_noise():
    a = sim("extended", 2, "sym", seed=7)
    b = simulate("extended", 2, load="sym", seed=7, duration=EXT_S)
    assert a.equals(b, check_metadata=True)
    c = simulate("extended", 2, load="sym", seed=8, duration=EXT_S)
    assert not np.array_equal(a.column("tau_m").to_numpy(), c.column("tau_m").to_numpy())
    na, nc = noise(signals(a)), noise(signals(c))
    assert not np.allclose(na[:100], nc[:100])


def test_cli_output_is_byte_identical(tmp_path):
    runner = CliRunner()
    paths = [tmp_path / "a.parquet", tmp_path / "b.parquet"]
    for p in paths:
        res = runner.invoke(cli, ["simulate", "--scenario", "adapt", "--joint", "4", "--seed", "3",
                                  "--effect", "ripple", "-o", str(p)])
        assert res.exit_code == 0, res.stderr
    assert paths[0].read_bytes() == paths[1].read_bytes()


def test_effects_and_loads_leave_motion_and_noise_unchanged():
    clean = signals(sim("extended", 2))
    for spec in ("ripple", "level", "temperature", "column"):
        sig = signals(sim("extended", 2, effects=(spec,)))
        np.testing.assert_array_equal(sig["q"], clean["q"])
        np.testing.assert_allclose(noise(sig), noise(clean), rtol=0, atol=1e-9)
    loaded = signals(sim("extended", 2, "asym"))
    np.testing.assert_array_equal(loaded["q"], clean["q"])
    np.testing.assert_array_equal(loaded["tau_g"], clean["tau_g"])   # the payload is not in tau_g


# ------------------------------------------------------- sign convention, columns


@pytest.mark.parametrize("scenario,joint,load", [("base", 2, "none"), ("base", 4, "none"),
                                                 ("extended", 2, "none"), ("extended", 2, "asym"),
                                                 ("extended", 4, "sym"), ("adapt", 2, "none")])
def test_friction_target_minus_true_friction_is_the_noise(scenario, joint, load):
    j = JOINTS[joint]
    e = noise(signals(sim(scenario, joint, load)))
    sd = np.hypot(j.noise_sd, j.ext_noise_sd) if load != "none" else j.noise_sd
    assert abs(e.mean()) < 4 * sd / np.sqrt(len(e))
    assert abs(e.std() / sd - 1) < 5 / np.sqrt(len(e))


def test_columns_units_and_metadata():
    table = sim("extended", 2, "sym")
    units = {f.name: logs.field_unit(f) for f in table.schema}
    assert units == {"t": "s", "joint": None, "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm",
                     "tau_g": "Nm", "tau_dyn": "Nm", "tau_ext": "Nm", "temp": "degC", "tau_f_true": "Nm"}
    assert set(table.column("joint").to_pylist()) == {2}
    log = logs.from_table(table, name="sim")
    assert log.axis == "rotary" and log.derived == {}
    meta = metadata(table)
    assert (meta["scenario"], meta["joint"], meta["seed"], meta["load"]) == ("extended", 2, 1, "sym")
    assert meta["rows"] == table.num_rows and meta["effects"] == []
    for name, value in true_params(2, "extended").items():
        assert meta["parameters"][name] == value
        assert name in meta["units"]


def test_true_params_base_and_shifted_state():
    base, ext = true_params(2, "base"), true_params(2, "extended")
    for name in ("fc", "fs", "vs", "delta", "fv", "kc", "ks", "sigma0", "sigma1"):
        assert base[name] == ext[name] == getattr(JOINTS[2], name)
    assert base["temperature"] == base["t_ref"] and base["kq"] == 0
    assert ext["temperature"] < ext["t_ref"] and ext["kq"] > 0
    assert true_params(2, "extended", "base") == base
    # the logged temperature is the state's
    assert np.all(signals(sim("base", 2))["temp"] == base["temperature"])
    assert np.all(signals(sim("adapt", 2))["temp"] == ext["temperature"])


@pytest.mark.parametrize("joint", [2, 4])
def test_base_friction_is_exactly_an_extended_lugre_model(joint):
    """At the internal rate (1 kHz) the logged friction is the LuGre model of true_params."""
    sig = signals(sim("base", joint, rate=1000.0))
    p = true_params(joint, "base")
    load = np.abs(sig["tau_g"])
    g = physics.stribeck(sig["qd"], p["fc"] + p["kc"] * load, p["fs"] + p["ks"] * load, p["vs"], p["delta"])
    tau, _ = physics.lugre_friction(sig["qd"], g, p["fv"], p["sigma0"], p["sigma1"],
                                    physics.intervals(sig["t"]), z0=0.0)
    np.testing.assert_allclose(sig["tau_f_true"], tau, rtol=1e-9, atol=1e-9)


def test_output_rate_decimates_the_same_simulation():
    fast, slow = signals(sim("adapt", 2, rate=1000.0)), signals(sim("adapt", 2))
    for name in ("t", "q", "qd", "tau_f_true", "tau_g"):
        np.testing.assert_allclose(slow[name], fast[name][::10], rtol=0, atol=1e-12)
    assert len(signals(sim("adapt", 2, rate=200.0))["t"]) == 2 * len(slow["t"]) - 1


# ------------------------------------------------------------------ scenarios


def _plateaus(sig):
    """Velocities held constant (qdd == 0) while moving."""
    held = (sig["qdd"] == 0) & (sig["qd"] != 0)
    return set(np.round(sig["qd"][held], 9))


@pytest.mark.parametrize("joint", [2, 4])
def test_base_scenario(joint):
    j = JOINTS[joint]
    sig = signals(sim("base", joint))
    assert 30_000 <= len(sig["t"]) <= 60_000
    levels = _plateaus(sig)
    for v in trajectories.BASE_LEVELS:
        assert v in levels and -v in levels
    assert min(abs(v) for v in levels) <= 0.005 and np.abs(sig["qd"]).max() == pytest.approx(0.7)
    assert sig["tau_g"].min() < -0.95 * j.gravity_amplitude and sig["tau_g"].max() > 0.95 * j.gravity_amplitude
    assert j.q_min - 1e-9 <= sig["q"].min() and sig["q"].max() <= j.q_max + 1e-9
    np.testing.assert_allclose(sig["tau_g"], j.gravity_amplitude * np.sin(sig["q"]))  # single joint
    assert np.all(sig["tau_ext"] == 0)
    assert np.abs(sig["qdd"]).max() <= trajectories.A_MAX + 1e-9


def test_base_slow_levels_meet_different_gravity_loads():
    sig = signals(sim("base", 2))
    for v in (0.005, 0.01, 0.02):
        tau_g = sig["tau_g"][np.isclose(sig["qd"], v) & (sig["qdd"] == 0)]
        assert np.ptp(tau_g) > 5.0     # two stretches at different positions


@pytest.mark.parametrize("joint", [2, 4])
def test_extended_scenario(joint):
    j = JOINTS[joint]
    sig = signals(simulate("extended", joint, seed=3))
    assert sig["t"][-1] == pytest.approx(120.0, abs=1.0)
    assert np.abs(sig["qd"]).max() <= 0.7 + 1e-9
    moving = sig["qd"][np.abs(sig["qd"]) > 0.01]
    assert np.count_nonzero(np.diff(np.sign(moving))) >= 5                       # reversals
    assert len(_plateaus(sig)) >= 10                                            # many levels
    assert sig["tau_g"].min() < -0.9 * j.gravity_amplitude and sig["tau_g"].max() > 0.9 * j.gravity_amplitude
    # other joints move: tau_g is not a function of this joint's position
    assert np.std(sig["tau_g"] - j.gravity_amplitude * np.sin(sig["q"])) > 0.1 * j.gravity_amplitude
    assert j.q_min <= sig["q"].min() and sig["q"].max() <= j.q_max


@pytest.mark.parametrize("joint", [2, 4])
def test_adapt_scenario(joint):
    j = JOINTS[joint]
    sig = signals(sim("adapt", joint))
    assert sig["t"][-1] < 60.0
    assert _plateaus(sig) == {trajectories.ADAPT_VELOCITY, -trajectories.ADAPT_VELOCITY}
    assert sig["tau_g"].min() < -0.95 * j.gravity_amplitude and sig["tau_g"].max() > 0.95 * j.gravity_amplitude
    assert np.all(sig["tau_ext"] == 0)


def test_loads():
    j = JOINTS[2]
    sym = signals(sim("extended", 2, "sym"))["tau_ext"]
    asym = signals(sim("extended", 2, "asym"))["tau_ext"]
    assert sym.min() < -0.5 * j.load_amplitude and sym.max() > 0.5 * j.load_amplitude
    assert abs(sym.mean()) < 0.5 * j.load_amplitude
    assert asym.min() > -5 * j.ext_noise_sd and asym.max() > 0.7 * j.load_amplitude


def test_the_shifted_state_differs_from_base_by_tau_g_and_direction():
    """Extended in the shifted state vs the same motion in the base state: the change in
    friction is mostly a function of (tau_g, sign(qd))."""
    shifted, base = signals(sim("extended", 2)), signals(sim("extended", 2, friction_state="base"))
    diff = shifted["tau_f_true"] - base["tau_f_true"]
    moving = np.abs(shifted["qd"]) > 0.02
    X = np.column_stack([np.sign(shifted["qd"]), np.ones_like(diff), shifted["tau_g"],
                         shifted["tau_g"] * np.sign(shifted["qd"])])[moving]
    coef, *_ = np.linalg.lstsq(X, diff[moving], rcond=None)
    explained = 1 - np.var(diff[moving] - X @ coef) / np.var(diff[moving])
    assert np.abs(diff[moving]).mean() > 5 * JOINTS[2].noise_sd
    assert explained > 0.8


# -------------------------------------------------------------------- effects

FRICTION_EFFECTS = sorted(set(EFFECTS) - {"acceleration", "offset", "payload", "gravity", "disturbance"})


@pytest.mark.parametrize("scenario", ["extended", "base"])
@pytest.mark.parametrize("name", FRICTION_EFFECTS)
def test_each_friction_effect_changes_the_target_clearly(scenario, name):
    clean = signals(sim(scenario, 2))
    sig = signals(sim(scenario, 2, effects=(name,)))
    change = np.abs(logs.friction_target(sig) - logs.friction_target(clean)).mean()
    assert change > 2 * np.abs(noise(clean)).mean()
    np.testing.assert_allclose(noise(sig), noise(clean), rtol=0, atol=1e-9)   # the effect is in the friction
    assert metadata(sim(scenario, 2, effects=(name,)))["effects"][0]["name"] == name


def test_offset_is_a_bias_on_tau_m():
    clean, sig = signals(sim("extended", 2)), signals(sim("extended", 2, effects=("offset=1.5",)))
    np.testing.assert_allclose(logs.friction_target(sig) - logs.friction_target(clean), 1.5)
    np.testing.assert_array_equal(sig["tau_f_true"], clean["tau_f_true"])


def test_gravity_error_is_in_the_logged_tau_g():
    clean, sig = signals(sim("extended", 2)), signals(sim("extended", 2, effects=("gravity",)))
    np.testing.assert_allclose(sig["tau_g"], 0.93 * clean["tau_g"], rtol=1e-12)
    np.testing.assert_allclose(logs.friction_target(sig) - logs.friction_target(clean), 0.07 * clean["tau_g"],
                               atol=1e-9)
    np.testing.assert_array_equal(sig["tau_f_true"], clean["tau_f_true"])


def test_disturbance_is_a_periodic_torque_in_tau_m():
    clean, sig = signals(sim("extended", 2)), signals(sim("extended", 2, effects=("disturbance",)))
    change = sig["tau_m"] - clean["tau_m"]
    np.testing.assert_array_equal(sig["tau_f_true"], clean["tau_f_true"])
    assert np.abs(change).max() == pytest.approx(1.0, rel=0.01)
    power = np.abs(np.fft.rfft(change)) ** 2
    freq = np.fft.rfftfreq(len(change), 0.01)
    assert freq[np.argmax(power)] == pytest.approx(fx.DISTURBANCE_HZ, abs=0.02)


def test_inertia_error_is_in_the_logged_tau_dyn():
    j = JOINTS[2]
    clean, sig = signals(sim("extended", 2)), signals(sim("extended", 2, effects=("acceleration",)))
    missing = fx.EFFECTS["acceleration"].default(j) * j.inertia
    change = logs.friction_target(sig) - logs.friction_target(clean)
    np.testing.assert_allclose(change, missing * sig["qdd"], atol=1e-9)
    accelerating = np.abs(sig["qdd"]) > 0.5
    assert np.abs(change[accelerating]).mean() > 2 * np.abs(noise(clean)).mean()


def test_payload_goes_through_tau_ext_and_loads_the_gear():
    j = JOINTS[2]
    clean, sig = signals(sim("base", 2)), signals(sim("base", 2, effects=("payload",)))
    assert sig["tau_ext"].max() > 0.5 * j.load_amplitude      # 0..P over the configurations met
    np.testing.assert_array_equal(sig["tau_g"], clean["tau_g"])
    assert np.abs(sig["tau_m"] - clean["tau_m"]).mean() > 2 * np.abs(noise(clean)).mean()
    # the gear load changes the friction: kc*(|tau_g - tau_ext| - |tau_g|), measurably
    assert np.abs(sig["tau_f_true"] - clean["tau_f_true"]).mean() > 0.02


def test_temperature_and_column_effects_log_their_signals():
    sig = signals(sim("extended", 2, effects=("temperature", "column")))
    assert sig["temp"][0] == pytest.approx(fx.WARM_START)
    assert sig["temp"][-1] == pytest.approx(fx.WARM_START + fx.EFFECTS["temperature"].default(JOINTS[2]))
    assert np.all(np.diff(sig["temp"]) > 0)
    h = sig["humidity"]
    assert np.ptp(h) > fx.HUMIDITY_SWING and abs(h.mean() - fx.HUMIDITY_REF) < fx.HUMIDITY_SWING
    table = sim("extended", 2, effects=("temperature", "column"))
    assert logs.field_unit(table.schema.field("humidity")) == "%"


def test_all_effects_together_on_every_scenario_and_joint():
    specs = tuple(sorted(EFFECTS))
    for scenario in ("base", "extended", "adapt"):
        for joint in (2, 4):
            table = sim(scenario, joint, effects=specs)
            sig = signals(table)
            assert all(np.isfinite(v).all() for v in sig.values())
            assert [e["name"] for e in metadata(table)["effects"]] == list(EFFECTS)


def test_effect_strength_changes_the_size():
    clean = signals(sim("extended", 2))
    sizes = [np.abs(signals(sim("extended", 2, effects=(f"ripple={a}",)))["tau_f_true"] - clean["tau_f_true"]).mean()
             for a in (0.5, 1.0)]
    assert sizes[1] == pytest.approx(2 * sizes[0], rel=1e-9)


@pytest.mark.parametrize("kwargs,message", [
    ({"scenario": "nope"}, "unknown scenario"),
    ({"load": "heavy"}, "unknown load"),
    ({"effects": ("sparkle",)}, "unknown effect"),
    ({"effects": ("level=0",)}, "level must be positive"),
    ({"effects": ("ripple", "ripple=2")}, "given twice"),
    ({"effects": ("drift=x",)}, "not a number"),
    ({"scenario": "base", "duration": 30.0}, "only be given for the extended scenario"),
])
def test_bad_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        simulate(**kwargs)


# ------------------------------------------------------------------------- CLI


def test_cli_writes_a_file(tmp_path):
    out = tmp_path / "log.parquet"
    res = CliRunner().invoke(cli, ["simulate", "--scenario", "extended", "--joint", "4", "--load", "asym",
                                   "--duration", "30", "--effect", "drift=0.5", "--seed", "2", "-o", str(out)])
    assert res.exit_code == 0, res.stderr
    assert res.stdout == ""
    assert "3001 rows" in res.stderr and "30.0 s" in res.stderr
    log = logs.load_log(str(out))
    assert log.joint == 4 and len(log) == 3001
    expected = simulate("extended", 4, load="asym", effects=("drift=0.5",), seed=2, duration=30.0)
    assert pq.read_table(out).equals(expected, check_metadata=True)


def test_cli_writes_parquet_to_stdout():
    res = CliRunner().invoke(cli, ["simulate", "--scenario", "adapt", "-q", "-o", "-"])
    assert res.exit_code == 0, res.stderr
    assert res.stderr == ""
    table = pq.read_table(io.BytesIO(res.stdout_bytes))
    assert table.equals(simulate("adapt", 2, seed=0), check_metadata=True)


@pytest.mark.parametrize("args,message", [
    (["--effect", "sparkle"], "unknown effect"),
    (["--effect", "inertia=1.5"], "inertia must be below 1"),
    (["--effect", "temperature=-500"], "the joint would end at -480 degC; a gear runs between -40 and 120 degC"),
    (["--effect", "column=5"], "|k| must be below 0.0833 1/%"),
    (["--duration", "30"], "duration applies to the extended scenario only"),
    (["--joint", "3"], "'3' is not one of"),
])
def test_cli_usage_errors(tmp_path, args, message):
    res = CliRunner().invoke(cli, ["simulate", *args, "-o", str(tmp_path / "x.parquet")])
    assert res.exit_code == 2
    assert message in res.stderr and res.stdout == ""
    assert not (tmp_path / "x.parquet").exists()


def test_cli_help_has_an_example():
    res = CliRunner().invoke(cli, ["simulate", "--help"])
    assert res.exit_code == 0 and "Example:" in res.stdout and "--effect" in res.stdout


# ----------------------------------------------------------------- sample data


def _sample_commands():
    text = (SAMPLE / "README.md").read_text()
    return [shlex.split(line)[1:] for line in text.splitlines() if line.startswith("fricli simulate ")]


def test_sample_data_readme_lists_every_file():
    outputs = sorted(args[args.index("-o") + 1] for args in _sample_commands())
    files = sorted(f"sample_data/{p.name}" for p in SAMPLE.glob("*.parquet"))
    assert outputs == files and len(files) == 10


def test_sample_data_regenerates_identically(tmp_path):
    runner = CliRunner()
    for args in _sample_commands():
        i = args.index("-o")
        name = args[i + 1].split("/")[-1]
        out = tmp_path / name
        res = runner.invoke(cli, args[:i] + ["-o", str(out)] + args[i + 2:] + ["-q"])
        assert res.exit_code == 0, res.stderr
        new, stored = pq.read_table(out), pq.read_table(SAMPLE / name)
        # the same schema and metadata (units, how the log was made); the same numbers up to the
        # last bits that numpy and libm builds may round differently (seen: 3e-14 Nm in tau_m)
        assert new.schema.equals(stored.schema, check_metadata=True), name
        for column in new.column_names:
            a, b = new.column(column).to_numpy(), stored.column(column).to_numpy()
            if a.dtype.kind == "f":
                np.testing.assert_allclose(a, b, rtol=1e-12, atol=1e-12, err_msg=f"{name}: {column}")
            else:
                assert (a == b).all(), f"{name}: {column}"


def test_the_sample_figures_in_the_docs_are_current():
    """docs/simulator.md's table and figures of sample_data/ are what tools/docs/make_sample_figures.py writes."""
    import importlib.util

    spec = importlib.util.spec_from_file_location("make_sample_figures", ROOT / "tools" / "docs" / "make_sample_figures.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.section() in (ROOT / "docs" / "simulator.md").read_text()


@pytest.mark.parametrize("args", [["--effect", "drift=1e30"], ["--effect", "offset=1e12"], ["--contact", "5,1e30,1"]])
def test_strengths_that_would_write_an_unreadable_log_are_refused(tmp_path, args):
    """Values beyond the limit every command refuses as absurd (logs.MAGNITUDE_LIMIT): exit 2
    naming the option, and no file written."""
    out = tmp_path / "s.parquet"
    res = CliRunner().invoke(cli, ["simulate", "--scenario", "adapt", *args, "-o", str(out), "-q"])
    assert res.exit_code == 2 and f"Invalid value for {args[0]}" in res.output and "every command refuses" in res.output
    assert not out.exists()
