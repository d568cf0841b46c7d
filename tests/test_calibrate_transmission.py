"""fricli calibrate through a transmission: the four-joint arm of test_calibrate.py driven by four
motors, joints j3 and j4 coupled (motor 4 turns with joint 3 as well as joint 4), each motor with a
rotor inertia and linear friction in its own velocity (fricli.core.transmission), simulated through
Pinocchio (RNEA of the rigid body) plus R^T diag(J_m) R qdd plus R^T f(R qd)."""

import json

import numpy as np
import pyarrow.parquet as pq
import pytest

from fricli.core import errors, logs
from fricli.core.transmission import META_KEY, Transmission

pin = pytest.importorskip("pinocchio")

from fricli.robot import calibration as cb  # noqa: E402
from fricli.robot.dynamics import RobotModel  # noqa: E402
from test_calibrate import (ARMATURE, FRICTION, URDF, fricli, harmonics, motion, simulate,  # noqa: E402
                            true_model, write_log)

JOINTS = ["j1", "j2", "j3", "j4"]
RATIO = np.array([[-60.0, 0, 0, 0], [0, 80.0, 0, 0], [0, 0, 50.0, 0], [0, 0, 25.0, 40.0]])   # rows: motors
ROTOR = np.array([2.5e-4, 2.5e-4, 1.8e-4, 3e-5])                                        # J_m [kg m^2]
PRIOR = ROTOR * np.array([1.2, 1.2, 1.2, 2.0])      # a datasheet's J_m: motor 4's twice the truth
MOTOR_FRICTION = np.array([[2.2e-3, 0.08, 0.005], [1.9e-3, 0.09, -0.006], [2e-3, 0.05, 0.004],
                           [6e-4, 0.015, 0.001]])   # per motor: Fv [Nm s/rad], Fc [Nm], offset [Nm]
TRUE = Transmission(JOINTS, RATIO, rotor_inertia=ROTOR)


class _Bodies:
    def __init__(self, model):
        self.pin_model = model


def friction_at_joints(qd, coef, ratio=RATIO):
    """Joint torques (n, 4) of each motor's linear friction ``coef`` (4, 3) in w = R qd: R^T f(w)."""
    w = qd @ ratio.T
    return (coef[:, 0] * w + coef[:, 1] * np.sign(w) + coef[:, 2]) @ ratio


def reported(report) -> np.ndarray:
    """(4, 3): Fv, Fc, offset of the report's friction per log joint 1..4 (per motor with a transmission)."""
    return np.array([[report["friction"]["joints"][j][f] for f in cb.FRICTION] for j in "1234"])


@pytest.fixture(scope="module")
def arm():
    """The rigid body's true model, the true parameters (motor units), a fitting and a held-out run,
    and the torque of a run: (torque(t, q, qd, qdd) -> (n, 4), rigid body and rotors without friction)."""
    rng = np.random.default_rng(7)
    model, _ = true_model(rng)
    model.armature = np.zeros(4)
    x_true = np.concatenate([cb.cad_parameters(_Bodies(model)), ROTOR, MOTOR_FRICTION.reshape(-1)])

    def inertial(t, q, qd, qdd):
        joint_friction = FRICTION[:, 0] * qd + FRICTION[:, 1] * np.sign(qd) + FRICTION[:, 2]
        return simulate(model, t, q, qd, qdd) - joint_friction + qdd @ TRUE.reflected_inertia().T

    fit = harmonics(rng, 1000, (0.2, 0.45, 0.7, 1.1), 0.25)
    held = harmonics(rng, 600, (0.3, 0.6, 0.9), 0.3)
    return x_true, fit, held, inertial


def torque(inertial, t, q, qd, qdd):
    return inertial(t, q, qd, qdd) + friction_at_joints(qd, MOTOR_FRICTION)


@pytest.fixture(scope="module")
def coupled(arm):
    _, fit, _, inertial = arm
    m = motion(*fit, torque(inertial, *fit))
    m.transmission = Transmission(JOINTS, RATIO, rotor_inertia=PRIOR)
    return cb.calibrate(RobotModel(URDF, "cad"), m)


def test_the_motor_inertias_and_friction_are_found(arm, coupled, tmp_path):
    x_true, _, held, inertial = arm
    cal, robot = coupled, RobotModel(URDF, "cad")
    assert cal.motors == [0, 1, 2, 3]
    base, names = cb.base_parameters(robot, cal.x, ratio=cal.ratio, motors=cal.motors)
    base_true, _ = cb.base_parameters(robot, x_true, ratio=cal.ratio, motors=cal.motors)
    np.testing.assert_allclose(base, base_true, rtol=1e-6, atol=1e-6 * np.abs(base_true).max())
    # the coupled motors' rotor inertias are base parameters of their own (no link inertia shares their columns)
    assert {"motor@j3.rotor_inertia", "motor@j4.rotor_inertia"} <= set(names)
    np.testing.assert_allclose(cal.x[42:44], ROTOR[2:], rtol=1e-6)
    np.testing.assert_allclose(reported(cal.report), MOTOR_FRICTION, rtol=1e-6)
    assert all(row["motor"] for row in cal.report["friction"]["joints"].values())

    motor = cal.report["motors"]["j4"]
    assert motor["log_joint"] == "4" and motor["ratio"] == {"j3": 25.0, "j4": 40.0}
    assert motor["prior"] == PRIOR[3] and motor["identified"] == pytest.approx(ROTOR[3], rel=1e-6)
    reflected = cal.report["reflected_inertia"]
    assert reflected["joints"] == JOINTS
    np.testing.assert_allclose(reflected["identified"][2][3], 25 * 40 * ROTOR[3], rtol=1e-6)
    np.testing.assert_allclose([cal.report["armature"][j]["identified"] for j in ("j3", "j4")],
                               TRUE.armature()[2:], rtol=1e-6)
    # motor 4's datasheet value was twice the truth: flagged as today's armature is; motor 3's 20 % is not
    flagged = [line for line in cal.report["suspicious"] if line.startswith("motor of joint")]
    assert len(flagged) == 1 and flagged[0].startswith("motor of joint j4: rotor inertia 6e-05 -> 3e-05 kg m^2 (-50 %)")

    # the written URDF: armature in rotor_params, J_m and R in fricli_transmission; fricli's model adds the
    # cross-term, and with the reported motor friction predicts the held-out run
    text = cb.calibrated_urdf(URDF, "cad", cal)
    calibrated = RobotModel(text, "cal")
    np.testing.assert_allclose(calibrated.transmission.rotor_inertia, cal.x[40:44])
    np.testing.assert_allclose(calibrated.cross_inertia[2, 3], 25 * 40 * ROTOR[3], rtol=1e-6)
    t, q, qd, qdd = held
    tau_g, tau_dyn = calibrated.terms(q, qd, qdd)
    truth = torque(inertial, *held)
    error = tau_g + tau_dyn + friction_at_joints(qd, reported(cal.report)) - truth
    assert np.linalg.norm(error) < 1e-6 * np.linalg.norm(truth)
    # Pinocchio loads the file as a URDF (ignoring fricli_transmission) and reads its rotor_params
    path = tmp_path / "cal.srdf"
    path.write_text(text)
    loaded = pin.buildModelFromUrdf(str(path))
    pin.loadRotorParameters(loaded, str(path), False)
    np.testing.assert_allclose(loaded.armature, calibrated.armature)


def test_a_calibration_that_ignores_the_coupling_is_worse_on_the_coupled_joints(arm, coupled):
    _, fit, held, inertial = arm
    robot = RobotModel(URDF, "cad")
    m = motion(*fit, torque(inertial, *fit))
    m.rotor_inertia = Transmission(JOINTS, RATIO, rotor_inertia=PRIOR).armature()   # what import records per joint
    per_joint = cb.calibrate(robot, m)
    assert per_joint.motors is None
    t, q, qd, qdd = held
    truth = torque(inertial, *held)
    errors_ = {}
    for name, cal in (("coupled", coupled), ("per joint", per_joint)):
        tau_g, tau_dyn = RobotModel(cb.calibrated_urdf(URDF, "cad", cal), name).terms(q, qd, qdd)
        ratio = RATIO if cal.motors else np.eye(4)
        model = tau_g + tau_dyn + friction_at_joints(qd, reported(cal.report), ratio)
        errors_[name] = np.sqrt(np.mean((model - truth) ** 2, axis=0))
    scale = np.sqrt(np.mean(truth ** 2, axis=0))
    assert np.all(errors_["coupled"] < 1e-6 * scale)
    # joints 3 and 4: neither the cross-inertia nor motor 4's friction at joint 3 fits a per-joint model
    assert np.all(errors_["per joint"][2:] > 0.01 * scale[2:])
    fit_rms = {name: [cal.report["fit"][j]["rms_after"] for j in "34"] for name, cal in
               (("coupled", coupled), ("per joint", per_joint))}
    assert min(fit_rms["per joint"]) > 1e3 * max(fit_rms["coupled"])


@pytest.mark.parametrize("friction", ["linear", "stribeck"])
def test_a_diagonal_transmission_is_the_per_joint_calibration(friction):
    """Gear ratios alone: the same fit as one rotor per joint (armature r^2 J_m, joint friction Fv = r^2 Fv_m,
    Fc = |r| Fc_m, offset = r offset_m, vs = vs_m / |r|); a unit transmission gives the same bytes. With
    noise, so that the prior and the consistency step take part. The prior's strength is fixed: the
    physically consistent fit that follows an inconsistent estimate stops at a tolerance, where a
    difference in the last bit (of memory layout, not of the layout of the parameters) can move
    weakly determined parameters; with --prior auto the chosen strengths are compared instead."""
    rng = np.random.default_rng(5)
    model, _ = true_model(rng)
    fit = harmonics(rng, 800, (0.2, 0.45, 0.7, 1.1), 0.25)
    tau = simulate(model, *fit, rng=rng, noise=0.05)
    robot = RobotModel(URDF, "cad")
    r = np.diag(RATIO)
    per_joint = motion(*fit, tau)
    per_joint.rotor_inertia = 1.2 * ARMATURE
    geared = motion(*fit, tau)
    geared.transmission = Transmission.diagonal(JOINTS, r, rotor_inertia=1.2 * ARMATURE / r ** 2)
    auto = [cb.calibrate(robot, m, friction=friction).report["prior_choice"] for m in (per_joint, geared)]
    assert auto[0]["held_out_rms"] == pytest.approx(auto[1]["held_out_rms"], rel=1e-12)
    assert list(auto[0]["per_group"].values()) == list(auto[1]["per_group"].values())
    a, b = (cb.calibrate(robot, m, friction=friction, prior=0.5) for m in (per_joint, geared))
    assert b.motors == [0, 1, 2, 3] and a.motors is None
    if friction == "linear":
        unit = motion(*fit, tau)
        unit.rotor_inertia = 1.2 * ARMATURE
        unit.transmission = Transmission.diagonal(JOINTS, np.ones(4))
        assert np.array_equal(cb.calibrate(robot, unit, prior=0.5).x, a.x)
    np.testing.assert_allclose(b.x[:40], a.x[:40], rtol=1e-12, atol=1e-12 * np.abs(a.x[:40]).max())
    np.testing.assert_allclose(b.armature(), a.x[40:44], rtol=1e-12)
    np.testing.assert_allclose(b.armature(b.x0), a.x0[40:44], rtol=1e-12)
    np.testing.assert_allclose(reported(b.report) * np.column_stack([r ** 2, np.abs(r), r]), reported(a.report),
                               rtol=1e-12)
    for j, g in zip("1234", r):
        fit_a, fit_b = a.report["fit"][j], b.report["fit"][j]
        assert fit_b["rms_after"] == pytest.approx(fit_a["rms_after"], rel=1e-12)
        assert fit_b["rms_before"] == pytest.approx(fit_a["rms_before"], rel=1e-12)
        if friction == "stribeck":
            fa, fb = a.report["friction"]["joints"][j], b.report["friction"]["joints"][j]
            assert fb["vs"] / abs(g) == pytest.approx(fa["vs"], rel=1e-12)
            assert (fb["Fs"] - fb["Fc"]) * abs(g) == pytest.approx(fa["Fs"] - fa["Fc"], rel=1e-12)
    assert a.report["excitation"]["base_parameters"] == b.report["excitation"]["base_parameters"]


def _transmission_log(path, run, tau, tr):
    write_log(path, *run, tau)
    table = pq.read_table(path)
    logs.write_table(table.replace_schema_metadata({**(table.schema.metadata or {}), META_KEY: tr.to_json().encode()}),
                     str(path))
    return str(path)


@pytest.mark.slow
def test_cli_writes_the_motors_that_dynamics_import_and_diagnose_calibrate_use(arm, tmp_path):
    _, fit, held, inertial = arm
    (tmp_path / "cad.urdf").write_text(URDF)
    log = _transmission_log(tmp_path / "fit.parquet", fit, torque(inertial, *fit),
                            Transmission([1, 2, 3, 4], RATIO, rotor_inertia=PRIOR))
    res = fricli("calibrate", log, "--urdf", "cad.urdf", "--match", "order", "-o", "cal.urdf", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "joint 4: " in res.stderr and "(motor: Fv " in res.stderr
    assert "warning: motor of joint j4: rotor inertia" in res.stderr
    report = json.loads((tmp_path / "cal.calibration.json").read_text())
    assert report["motors"]["j4"]["identified"] == pytest.approx(ROTOR[3], rel=1e-6)
    text = (tmp_path / "cal.urdf").read_text()
    assert text.count("<motor ") == 4 and '<ratio joint="j3" value="25.0" />' in text

    # dynamics: the rigid body and every rotor inertia, the cross-term included
    t, q, qd, qdd = held
    held_log = write_log(tmp_path / "held.parquet", *held, torque(inertial, *held))
    res = fricli("dynamics", held_log, "--urdf", "cal.urdf", "--match", "order", "-o", "terms.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    terms = logs.read_table(str(tmp_path / "terms.parquet"))[0]
    got = (logs.float64_values(terms.column("tau_g")) + logs.float64_values(terms.column("tau_dyn"))).reshape(4, -1).T
    truth = inertial(*held)
    assert np.linalg.norm(got - truth) < 1e-6 * np.linalg.norm(truth)

    # import of a motor-side recording with the datasheet's rotor inertias in its mapping: with the calibrated
    # URDF the URDF's rotor inertias replace the mapping's, the cross-term too (counted once)
    tau_motor = Transmission(JOINTS, RATIO).motor_torques(torque(inertial, *held))
    np.savetxt(tmp_path / "motor.csv", np.column_stack([t, q @ RATIO.T, tau_motor]), delimiter=",", fmt="%.17g")
    mapping = ('time = 1\n[robot]\nmatch = "order"\n[transmission]\nratio = '
               + json.dumps(RATIO.tolist()) + f"\nrotor_inertia = {json.dumps(PRIOR.tolist())}\n"
               + "".join(f"[[joints]]\nname = {k + 1}\ntheta = {k + 2}\ntau_motor = {k + 6}\n" for k in range(4)))
    (tmp_path / "motor.toml").write_text(mapping)
    tables = {}
    for urdf in ("cad", "cal"):
        res = fricli("import", "motor.csv", "--mapping", "motor.toml", "--urdf", f"{urdf}.urdf", "-o",
                     f"{urdf}.parquet", cwd=tmp_path)
        assert res.returncode == 0, res.stderr
        tables[urdf] = logs.read_table(str(tmp_path / f"{urdf}.parquet"))[0]
    per_joint = {c: logs.float64_values(tables["cal"].column(c)).reshape(4, -1).T
                 for c in ("q", "qd", "qdd", "tau_dyn")}
    _, expected = RobotModel(text, "cal").terms(per_joint["q"], per_joint["qd"], per_joint["qdd"])
    np.testing.assert_allclose(per_joint["tau_dyn"], expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())
    record = json.loads(tables["cal"].schema.metadata[b"fricli.import"])["robot"]
    assert "cross_inertia" not in record
    assert "cross_inertia" in json.loads(tables["cad"].schema.metadata[b"fricli.import"])["robot"]

    # diagnose --fix --calibrate's step: the log imported with the CAD URDF calibrated through its recorded
    # transmission, its tau_dyn recomputed with the identified cross-term
    cal, text2, new = cb.recalibrate(tables["cad"], "cad.parquet", str(tmp_path / "cad.urdf"))
    assert cal.motors == [0, 1, 2, 3] and "<fricli_transmission>" in text2
    model = RobotModel(text2, "recal")
    assert model.cross_inertia[2, 3] > 0
    _, expected = model.terms(per_joint["q"], per_joint["qd"], per_joint["qdd"])
    got = logs.float64_values(new.column("tau_dyn")).reshape(4, -1).T
    np.testing.assert_allclose(got, expected, rtol=1e-9, atol=1e-9 * np.abs(expected).max())


@pytest.mark.parametrize("element, message", [
    ('<motor joint="j3" rotor_inertia="1e-4"><ratio joint="j3" value="50"/></motor>',
     "rotor_params of joint 'j3' (0.45 kg m^2) differs from the diagonal of its fricli_transmission (0.25 kg m^2)"),
    ('<motor joint="j9" rotor_inertia="1e-4"/>', "the motor of joint 'j9' is listed twice or names no moving joint"),
    ('<motor joint="j3" rotor_inertia="1e-4"><ratio joint="j4" value="5"/></motor>',
     "has a ratio to joint 'j4', whose motor is not listed"),
    ('<motor joint="j3" rotor_inertia="heavy"><ratio joint="j3" value="50"/></motor>', "is 'heavy', not a number"),
    ('<motor joint="j3" rotor_inertia="1e-4"/>', "the ratio matrix is singular"),
])
def test_a_bad_fricli_transmission_is_refused(element, message):
    text = URDF.replace("</robot>", '<rotor_params><joint name="j3" mass="0.45" gear_ratio="1"/></rotor_params>'
                        f"<fricli_transmission>{element}</fricli_transmission></robot>")
    with pytest.raises(errors.ModelFileError, match="fricli_transmission") as exc:
        RobotModel(text, "bad.urdf")
    assert message in str(exc.value)
