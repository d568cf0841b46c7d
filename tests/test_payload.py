"""fricli payload: a point payload identified from a whole-arm log simulated through Pinocchio
(the four-joint arm of test_calibrate.py, linear friction, the payload added as import adds it)."""

import json

import numpy as np
import pytest

from fricli.core import errors

pin = pytest.importorskip("pinocchio")

from fricli.robot import calibration as cb  # noqa: E402
from fricli.robot import payload  # noqa: E402
from fricli.robot.dynamics import RobotModel  # noqa: E402
from fricli.robot.mapping import Payload  # noqa: E402
from test_calibrate import FRICTION, URDF, fricli, harmonics, write_log  # noqa: E402

TRUE = Payload(mass=1.7, com=(0.05, -0.03, 0.12), frame="flange")


def simulate(rng, carried: Payload | None, n=1500, held=()):
    """q, qd, qdd, tau_m of the arm (URDF's own inertias) carrying ``carried``, plus linear friction;
    the joints ``held`` (indices) stay at 0.3 rad."""
    t, q, qd, qdd = harmonics(rng, n, (0.2, 0.45, 0.7, 1.1), 0.25)
    for j in held:
        q[:, j], qd[:, j], qdd[:, j] = 0.3, 0.0, 0.0
    robot = RobotModel(URDF, "true", payload=carried)
    tau_g, tau_dyn = robot.terms(q, qd, qdd)
    tau = tau_g + tau_dyn + FRICTION[:, 0] * qd + FRICTION[:, 1] * np.sign(qd) + FRICTION[:, 2]
    return t, q, qd, qdd, tau


def motion(t, q, qd, qdd, tau):
    return cb.Motion(t=t, q=q, qd=qd, qdd=qdd, tau=tau, names=[1, 2, 3, 4], rotor_inertia=np.full(4, np.nan))


def test_recovers_the_payload_mass_and_centre_of_mass():
    found = payload.identify(RobotModel(URDF, "cad"), motion(*simulate(np.random.default_rng(3), TRUE)), "flange")
    assert found.detected
    assert found.mass == pytest.approx(TRUE.mass, rel=1e-6)
    np.testing.assert_allclose(found.com, TRUE.com, atol=1e-6)
    np.testing.assert_allclose(found.friction, FRICTION, rtol=1e-6, atol=1e-6)
    assert np.all(found.rms_with < 1e-6 * found.rms_without)


def test_no_payload_is_reported_as_none():
    rng = np.random.default_rng(4)
    t, q, qd, qdd, tau = simulate(rng, None)
    tau = tau + rng.normal(0.0, 0.05, tau.shape)
    found = payload.identify(RobotModel(URDF, "cad"), motion(t, q, qd, qdd, tau), "flange")
    assert not found.detected
    assert abs(found.mass) < 0.05
    assert found.verdict in ("none", "negative")


def test_a_negative_mass_is_a_robot_model_error_and_a_loose_one_is_not_declared():
    """A robot model heavier at the flange than the arm (its payload declared but absent) gives a
    negative mass; a payload whose torques drown in noise is detected but not determined."""
    from fricli.cli.payload import summary

    t, q, qd, qdd, tau = simulate(np.random.default_rng(6), None)
    heavy = RobotModel(URDF, "cad", payload=TRUE)      # the model carries what the arm does not
    found = payload.identify(heavy, motion(t, q, qd, qdd, tau), "flange")
    assert found.verdict == "negative" and found.mass == pytest.approx(-TRUE.mass, rel=1e-6)
    lines = summary(found)
    assert "below zero: a negative mass is no payload but a robot-model error" in lines[0]
    assert not any(line.startswith("declare it") for line in lines)
    rng = np.random.default_rng(7)
    t, q, qd, qdd, tau = simulate(rng, TRUE)
    found = payload.identify(RobotModel(URDF, "cad"), motion(t, q, qd, qdd, tau + rng.normal(0.0, 40.0, tau.shape)),
                             "flange")
    assert found.detected and found.verdict == "undetermined", found.report()   # 1.46 +- 0.26 kg here
    lines = summary(found)
    assert lines[1].startswith("not determined:") and not any(line.startswith("declare it") for line in lines)


def test_a_negative_mass_whose_centre_of_mass_is_loose_is_undetermined_not_a_robot_model_error():
    """One joint moving, the others held (a UR10e jointwise run): a mass far below zero, many standard
    errors, traded against a centre of mass the log leaves loose. No robot-model error of that size
    is shown; the verdict is undetermined, and nothing is declared or blamed on the robot model."""
    from fricli.cli.payload import summary

    def found(mass, stderr):
        return payload.IdentifiedPayload(frame="tool0", mass=mass, com=np.array([0.0, 1.30, 0.16]),
                                         stderr=np.array(stderr), rows=5934, joints=[1, 2], rms_without=np.ones(2),
                                         rms_with=np.ones(2), friction=np.zeros((2, 3)), held=[1])

    loose = found(-4935.0, [120.0, 5e-6, 7e-6, 0.26])
    assert loose.verdict == "undetermined"
    lines = summary(loose)
    assert lines[1].startswith("not determined:") and not any("robot-model error" in line for line in lines)
    assert found(-0.7, [0.05, 0.01, 0.01, 0.01]).verdict == "negative"
    assert found(-0.1, [0.05, 0.01, 0.01, 0.01]).verdict == "none"
    assert found(2.5, [0.05, 0.01, 0.01, 0.01]).verdict == "payload"


def test_the_printed_declaration_reproduces_the_torques(tmp_path):
    """fricli dynamics -> fricli payload (the URDF recorded in the log) -> the printed import options:
    the log's robot model with that payload gives the true torques."""
    t, q, qd, qdd, tau = simulate(np.random.default_rng(5), TRUE, n=800)
    (tmp_path / "arm.urdf").write_text(URDF)
    write_log(tmp_path / "rec.parquet", t, q, qd, qdd, tau)
    done = fricli("dynamics", "rec.parquet", "--urdf", "arm.urdf", "--match", "order", "-o", "dyn.parquet", "-q",
                  cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    done = fricli("payload", "dyn.parquet", "--frame", "flange", "--json", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    report = json.loads(done.stdout)
    assert report["detected"] and report["mass"] == pytest.approx(TRUE.mass, rel=1e-6)
    declare = next(line for line in done.stderr.splitlines() if line.startswith("declare it: "))
    words = declare.split()
    mass = float(words[words.index("--payload-mass") + 1])
    com = [float(w) for w in words[words.index("--payload-com") + 1:][:3]]
    assert words[words.index("--payload-frame") + 1] == "flange"
    robot = RobotModel(URDF, "declared", payload=Payload(mass, tuple(com), "flange"))
    truth = RobotModel(URDF, "true", payload=TRUE)
    rb = lambda r: np.add(*r.terms(q, qd, qdd))  # noqa: E731
    # printed with 4 significant digits: the torques agree to that
    assert np.max(np.abs(rb(robot) - rb(truth))) < 1e-3 * np.max(np.abs(rb(truth)))
    window = fricli("payload", "dyn.parquet", "--frame", "flange", "--until", "50%", "--json", "-q", cwd=tmp_path)
    assert window.returncode == 0 and json.loads(window.stdout)["rows"] < report["rows"]
    # the same from Python: fricli.identify_payload is the command (docs/python-api.md)
    import fricli as library

    found = library.identify_payload(tmp_path / "dyn.parquet", "flange", time_until="50%")
    assert json.loads(json.dumps({"log": "dyn.parquet", **found.report()})) == json.loads(window.stdout)
    with pytest.raises(library.OptionError) as err:
        library.identify_payload(tmp_path / "dyn.parquet", "flange", edge=-1)
    assert err.value.option == "edge"


def test_bad_input_is_one_line(tmp_path):
    t, q, qd, qdd, tau = simulate(np.random.default_rng(6), TRUE, n=300)
    (tmp_path / "arm.urdf").write_text(URDF)
    write_log(tmp_path / "rec.parquet", t, q, qd, qdd, tau)
    bare = fricli("payload", "rec.parquet", "--frame", "flange", cwd=tmp_path)
    assert bare.returncode == errors.INPUT and "import it with --urdf" in bare.stderr
    assert len(bare.stderr.strip().splitlines()) == 1
    fricli("dynamics", "rec.parquet", "--urdf", "arm.urdf", "--match", "order", "-o", "dyn.parquet", "-q", cwd=tmp_path)
    frame = fricli("payload", "dyn.parquet", "--frame", "tool9", cwd=tmp_path)
    assert frame.returncode == errors.MODEL and "the frames are: " in frame.stderr
    assert len(frame.stderr.strip().splitlines()) == 1


def test_joints_held_still_are_left_out():
    """A held joint holds any torque up to its breakaway: its rows say nothing of the payload."""
    t, q, qd, qdd, tau = simulate(np.random.default_rng(8), TRUE, held=(0, 2))
    tau[:, [0, 2]] += 3.0                      # whatever its last motion left it holding
    found = payload.identify(RobotModel(URDF, "cad"), motion(t, q, qd, qdd, tau), "flange")
    assert found.held == [1, 3] and set(found.report()["joints"]) == {"2", "4"}
    assert found.verdict == "payload" and found.mass == pytest.approx(TRUE.mass, rel=1e-6)
    t, q, qd, qdd, tau = simulate(np.random.default_rng(8), TRUE, held=(0, 1, 2, 3))
    with pytest.raises(errors.DataError, match="every joint is held still"):
        payload.identify(RobotModel(URDF, "cad"), motion(t, q, qd, qdd, tau), "flange")


def test_friction_with_a_stribeck_bump_needs_the_stribeck_columns():
    """A joint whose friction rises towards rest (the LuGre static curve's bump) biased the payload
    fitted beside linear friction; ``friction="stribeck"`` fits the bump beside it (vs on a grid)."""
    t, q, qd, qdd, tau = simulate(np.random.default_rng(3), TRUE)
    vs = np.array([0.2, 0.3, 0.25, 0.4])                          # rad/s
    bump = np.array([2.0, 3.0, 1.5, 0.8]) * np.sign(qd) * np.exp(-np.square(qd / vs))   # (Fs - Fc) [Nm]
    data = motion(t, q, qd, qdd, tau + bump)
    errors_of = {}
    for friction in ("linear", "stribeck"):
        found = payload.identify(RobotModel(URDF, "cad"), data, "flange", friction=friction)
        errors_of[friction] = (abs(found.mass / TRUE.mass - 1), float(np.abs(found.com - TRUE.com).max()))
    assert errors_of["stribeck"][0] < 0.01 and errors_of["stribeck"][1] < 0.005, errors_of
    assert errors_of["linear"][0] > 5 * errors_of["stribeck"][0], errors_of
    assert set(found.report()["joints"]["1"]) >= {"Fs-Fc", "vs"} and found.vs.shape == (4,)
    with pytest.raises(ValueError, match="unknown friction kind"):
        payload.identify(RobotModel(URDF, "cad"), data, "flange", friction="tanh")
