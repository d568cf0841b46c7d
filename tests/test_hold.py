"""URDF joints the log does not record (a gripper's fingers, one mimicking the other), held at
their zero position: import/dynamics --hold, robot.hold in a mapping, and calibrate on such a log."""

import json

import numpy as np
import pytest

from conftest import run_in
from fricli.core import errors, logs

pin = pytest.importorskip("pinocchio")

import test_calibrate as arm  # noqa: E402
from fricli.robot.dynamics import RobotModel  # noqa: E402

FINGERS = """
  <joint name="finger_l" type="prismatic"><parent link="flange"/><child link="pad_l"/>
    <origin xyz="0.05 0.02 0"/><axis xyz="0 1 0"/><limit lower="0" upper="0.04" effort="20" velocity="0.2"/></joint>
  <link name="pad_l"><inertial><origin xyz="0.02 0 0"/><mass value="0.4"/>
    <inertia ixx="0.0002" ixy="0" ixz="0" iyy="0.0002" iyz="0" izz="0.0001"/></inertial></link>
  <joint name="finger_r" type="prismatic"><parent link="flange"/><child link="pad_r"/>
    <origin xyz="0.05 -0.02 0"/><axis xyz="0 -1 0"/><limit lower="0" upper="0.04" effort="20" velocity="0.2"/>
    <mimic joint="finger_l"/></joint>
  <link name="pad_r"><inertial><origin xyz="0.02 0 0"/><mass value="0.4"/>
    <inertia ixx="0.0002" ixy="0" ixz="0" iyy="0.0002" iyz="0" izz="0.0001"/></inertial></link>
</robot>"""
GRIPPER = arm.URDF.replace("</robot>", FINGERS)
# what a user would otherwise write by hand: the fingers fixed at their zero position
FIXED = GRIPPER.replace('name="finger_l" type="prismatic"', 'name="finger_l" type="fixed"').replace(
    'name="finger_r" type="prismatic"', 'name="finger_r" type="fixed"').replace('<mimic joint="finger_l"/>', "")


def fricli(*args, cwd):
    return run_in(cwd, *args)


def write_log(path, t, q, qd, qdd, tau):
    """A long-format log of joints j1..j4 (named as the URDF names them)."""
    n = len(t)
    columns = {"t": np.tile(t, 4), "joint": np.repeat([f"j{k}" for k in range(1, 5)], n),
               **{c: v.T.reshape(-1) for c, v in (("q", q), ("qd", qd), ("qdd", qdd), ("tau_m", tau))}}
    table = logs.table_from_arrays(columns, {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm"})
    logs.write_table(table, str(path))
    return str(path)


@pytest.fixture(scope="module")
def gripper_arm(tmp_path_factory):
    """The arm with a two-finger gripper, its masses and centres of mass off the URDF's by up to 20 %
    (fingers held), and a log of the arm's four joints simulated through it."""
    root = tmp_path_factory.mktemp("gripper")
    (root / "gripper.urdf").write_text(GRIPPER)
    (root / "fixed.urdf").write_text(FIXED)
    rng = np.random.default_rng(5)
    model = RobotModel(FIXED, "truth").pin_model.copy()
    model.gravity = pin.Motion(np.array([0.0, 0.0, -9.81]), np.zeros(3))
    for i in range(1, model.njoints):
        old = model.inertias[i]
        model.inertias[i] = pin.Inertia(old.mass * (1 + rng.uniform(-0.2, 0.2)),
                                        old.lever * (1 + rng.uniform(-0.2, 0.2, 3)), old.inertia)
    model.armature = arm.ARMATURE.copy()
    fit = arm.harmonics(rng, 1500, (0.2, 0.45, 0.7, 1.1), 0.25)
    data = model.createData()
    config = RobotModel(FIXED, "truth").configuration(fit[1])
    tau = np.array([pin.rnea(model, data, config[k], fit[2][k], fit[3][k]) for k in range(len(fit[0]))])
    tau += arm.FRICTION[:, 0] * fit[2] + arm.FRICTION[:, 1] * np.sign(fit[2]) + arm.FRICTION[:, 2]
    return root, write_log(root / "raw.parquet", *fit, tau), tau


def test_a_joint_the_log_lacks_is_refused_with_the_way_to_hold_it(gripper_arm):
    root, raw, _ = gripper_arm
    done = fricli("dynamics", raw, "--urdf", "gripper.urdf", "--match", "name", "-o", "x.parquet", cwd=root)
    assert done.returncode == errors.MODEL, done.stderr
    assert "joint 'finger_l' (prismatic, and 1 more) is not in the log" in done.stderr
    assert "--hold JOINT" in done.stderr and not (root / "x.parquet").exists()
    done = fricli("dynamics", raw, "--urdf", "gripper.urdf", "--match", "name", "--hold", "nosuch", "-o", "x.parquet",
                  cwd=root)
    assert done.returncode == errors.MODEL and "no moving joint 'nosuch' to hold" in done.stderr, done.stderr
    done = fricli("dynamics", raw, "--urdf", "gripper.urdf", "--match", "name", "--hold", "finger_l", "--hold", "finger_r", "--hold", "j2",
                  "-o", "x.parquet", cwd=root)
    assert done.returncode == errors.MODEL, done.stderr
    assert "joint 'j2' is held at zero" in done.stderr and "but the log records it" in done.stderr, done.stderr


def test_held_joints_give_the_terms_of_the_urdf_with_them_fixed(gripper_arm):
    root, raw, _ = gripper_arm
    for urdf, extra, out in (("gripper.urdf", ["--hold", "finger_l"], "held.parquet"),
                             ("fixed.urdf", [], "fixed.parquet")):
        done = fricli("dynamics", raw, "--urdf", urdf, "--match", "name", *extra, "-o", out, "-q", cwd=root)
        assert done.returncode == 0, done.stderr
    held, _ = logs.read_table(str(root / "held.parquet"))
    fixed, _ = logs.read_table(str(root / "fixed.parquet"))
    for column in ("tau_g", "tau_dyn"):
        np.testing.assert_array_equal(held.column(column).to_numpy(), fixed.column(column).to_numpy())
    assert np.abs(held.column("tau_g").to_numpy()).max() > 1.0
    # the mimicking finger is held with the finger it follows; the record keeps both
    assert logs.robot_record(held.schema)["held"] == ["finger_l", "finger_r"]
    assert logs.robot_model(held.schema)["held"] == ["finger_l", "finger_r"]


def test_calibrate_holds_the_recorded_joints_and_keeps_the_gripper_in_its_urdf(gripper_arm):
    root, raw, tau = gripper_arm
    done = fricli("dynamics", raw, "--urdf", "gripper.urdf", "--match", "name", "--hold", "finger_l",
                  "-o", "held.parquet", "-q", cwd=root)
    assert done.returncode == 0, done.stderr
    done = fricli("calibrate", "held.parquet", "--urdf", "gripper.urdf", "-o", "cal.urdf", "-q", cwd=root)
    assert done.returncode == 0, done.stderr
    text = (root / "cal.urdf").read_text()
    assert 'name="finger_l" type="prismatic"' in text and '<mimic joint="finger_l"' in text
    # the calibrated URDF, with the fingers held again, gives the simulated torques (noise-free)
    report = json.loads((root / "cal.calibration.json").read_text())
    table, _ = logs.read_table(str(root / "held.parquet"))
    robot = RobotModel(text, "cal", held=("finger_l",))
    n = table.num_rows // 4
    q, qd, qdd = (np.column_stack([table.column(c).to_numpy()[k * n:(k + 1) * n] for k in range(4)])
                  for c in ("q", "qd", "qdd"))
    tau_g, tau_dyn = robot.terms(q, qd, qdd)
    friction = np.column_stack([report["friction"]["joints"][j]["Fv"] * qd[:, k]
                                + report["friction"]["joints"][j]["Fc"] * np.sign(qd[:, k])
                                + report["friction"]["joints"][j]["offset"]
                                for k, j in enumerate(report["friction"]["joints"])])
    np.testing.assert_allclose(tau_g + tau_dyn + friction, tau, rtol=0, atol=1e-6 * np.abs(tau).max())


def test_import_holds_the_joints_its_mapping_names(gripper_arm):
    """robot.hold in the mapping, as --hold on the command line: the same terms."""
    root, raw, _ = gripper_arm
    table, _ = logs.read_table(raw)
    n = table.num_rows // 4
    q, tau = (np.column_stack([table.column(c).to_numpy()[k * n:(k + 1) * n] for k in range(4)]) for c in ("q", "tau_m"))
    np.savetxt(root / "rec.csv", np.column_stack([table.column("t").to_numpy()[:n], q, tau]), delimiter=",")
    joints = "".join(f'[[joints]]\nname = "j{k}"\nq = {k + 1}\ntau_m = {k + 5}\n' for k in range(1, 5))
    (root / "map.toml").write_text(f'time = 1\n[robot]\nmatch = "name"\nhold = ["finger_l"]\n{joints}')
    done = fricli("import", "rec.csv", "--mapping", "map.toml", "--urdf", "gripper.urdf", "-o", "rec.parquet", "-q",
                  cwd=root)
    assert done.returncode == 0, done.stderr
    (root / "map.toml").write_text(f'time = 1\n[robot]\nmatch = "name"\n{joints}')
    done = fricli("import", "rec.csv", "--mapping", "map.toml", "--urdf", "fixed.urdf", "-o", "ref.parquet", "-q",
                  cwd=root)
    assert done.returncode == 0, done.stderr
    held, _ = logs.read_table(str(root / "rec.parquet"))
    fixed, _ = logs.read_table(str(root / "ref.parquet"))
    np.testing.assert_array_equal(held.column("tau_g").to_numpy(), fixed.column("tau_g").to_numpy())
    assert logs.held_of(held.schema) == ("finger_l", "finger_r")
    done = fricli("import", "rec.csv", "--mapping", "map.toml", "--hold", "finger_l", "-o", "x.parquet", cwd=root)
    assert done.returncode == errors.USAGE and "it applies with --urdf" in done.stderr


def test_a_mapping_holds_joints_under_robot():
    from fricli.robot.mapping import parse_mapping

    doc = {"time": 1, "robot": {"match": "name", "hold": ["finger_l"]}, "joints": [{"name": "j1", "q": 2, "tau_m": 3}]}
    assert parse_mapping(doc).held == ("finger_l",)
    with pytest.raises(errors.LogError, match="robot.hold: expected a list of URDF joint names"):
        parse_mapping(dict(doc, robot={"hold": "finger_l"}))
