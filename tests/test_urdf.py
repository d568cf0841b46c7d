"""Rigid-body terms from a URDF (fricli import --urdf) against a two-link planar arm's analytic
gravity, mass matrix and Coriolis terms."""

import json
import re
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import ROOT, run_in, shared_data
from fricli.core import errors, logs
from fricli.robot.mapping import Payload, parse_mapping

# two-link planar arm, both axes along z: masses [kg], lengths [m], centre-of-mass distances
# [m], inertias about the centre of mass [kg m^2]
M1, M2, L1, L2, LC1, LC2, I1, I2 = 3.0, 2.0, 0.7, 0.5, 0.3, 0.2, 0.11, 0.05
URDF = f"""<?xml version="1.0"?>
<robot name="two_link">
  <link name="base"/>
  <joint name="shoulder" type="revolute">
    <parent link="base"/><child link="link1"/>
    <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-10" upper="10" effort="100" velocity="10"/>
  </joint>
  <link name="link1">
    <inertial><origin xyz="{LC1} 0 0" rpy="0 0 0"/><mass value="{M1}"/>
      <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="{I1}"/></inertial>
  </link>
  <joint name="elbow" type="revolute">
    <parent link="link1"/><child link="link2"/>
    <origin xyz="{L1} 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/>
    <limit lower="-10" upper="10" effort="100" velocity="10"/>
  </joint>
  <link name="link2">
    <inertial><origin xyz="{LC2} 0 0" rpy="0 0 0"/><mass value="{M2}"/>
      <inertia ixx="0.003" ixy="0" ixz="0" iyy="0.004" iyz="0" izz="{I2}"/></inertial>
  </link>
  <joint name="flange_joint" type="fixed">
    <parent link="link2"/><child link="flange"/>
    <origin xyz="{L2} 0 0" rpy="0 0 1.5707963267948966"/>
  </joint>
  <link name="flange"/>
</robot>
"""


def analytic(q, qd, qdd, gravity, payload_mass=0.0, payload_reach=0.0, rotor=(0.0, 0.0)):
    """tau_g and tau_dyn of the two-link arm, shapes (n, 2); the payload is a point mass on
    link 2's x axis at ``payload_reach`` from the elbow."""
    c1, s1, c2, s2 = np.cos(q[:, 0]), np.sin(q[:, 0]), np.cos(q[:, 1]), np.sin(q[:, 1])
    c12, s12 = np.cos(q[:, 0] + q[:, 1]), np.sin(q[:, 0] + q[:, 1])
    mass2 = M2 + payload_mass                                        # link 2 with the payload
    first2 = M2 * LC2 + payload_mass * payload_reach                 # its first moment about the elbow
    j1 = I1 + M1 * LC1 ** 2                                          # inertia about the axis
    j2 = I2 + M2 * LC2 ** 2 + payload_mass * payload_reach ** 2
    m11 = j1 + j2 + mass2 * L1 ** 2 + 2 * L1 * first2 * c2
    m12 = j2 + L1 * first2 * c2
    h = L1 * first2 * s2
    tau_dyn = np.column_stack([
        m11 * qdd[:, 0] + m12 * qdd[:, 1] - h * (2 * qd[:, 0] * qd[:, 1] + qd[:, 1] ** 2) + rotor[0] * qdd[:, 0],
        m12 * qdd[:, 0] + j2 * qdd[:, 1] + h * qd[:, 0] ** 2 + rotor[1] * qdd[:, 1],
    ])
    gx, gy, _ = gravity
    # potential V = -g . (sum of m p): tau_g = dV/dq
    d1 = (M1 * LC1 + mass2 * L1) * np.column_stack([-s1, c1]) + first2 * np.column_stack([-s12, c12])
    d2 = first2 * np.column_stack([-s12, c12])
    tau_g = -np.column_stack([gx * d1[:, 0] + gy * d1[:, 1], gx * d2[:, 0] + gy * d2[:, 1]])
    return tau_g, tau_dyn


def close(actual, expected, rtol=1e-9):
    """Relative to each column's scale."""
    scale = np.abs(expected).max(axis=0)
    assert np.all(np.abs(actual - expected) <= rtol * scale), np.abs(actual - expected).max(axis=0) / scale


def motion(rng, n=200):
    return rng.uniform(-np.pi, np.pi, (n, 2)), rng.normal(0, 2, (n, 2)), rng.normal(0, 5, (n, 2))


def test_gravity_and_dynamics_match_the_analytic_two_link_arm(rng):
    pytest.importorskip("pinocchio")
    from fricli.robot.dynamics import RobotModel

    gravity = (1.3, -9.81, 4.0)   # the z part acts along the axes: no torque
    model = RobotModel(URDF, "two_link.urdf", gravity=gravity)
    assert model.joints == ["shoulder", "elbow"] and model.kinds == ["rotary", "rotary"]
    q, qd, qdd = motion(rng)
    tau_g, tau_dyn = model.terms(q, qd, qdd)
    g_ref, dyn_ref = analytic(q, qd, qdd, gravity)
    close(tau_g, g_ref)
    close(tau_dyn, dyn_ref)


def test_a_robot_of_one_moving_joint(rng):
    """The elbow held: a model of one joint, for which pinocchio returns vectors, not (1, n)
    matrices; the terms are the two-link arm's with the elbow at 0, shape (n, 1), and the payload's
    regressor reads too."""
    pytest.importorskip("pinocchio")
    from fricli.robot import payload
    from fricli.robot.dynamics import RobotModel

    model = RobotModel(URDF, "two_link.urdf", gravity=(0.0, -9.81, 0.0), held=("elbow",))
    assert model.joints == ["shoulder"]
    q, qd, qdd = motion(rng)
    still = np.zeros_like(q[:, 1])
    tau_g, tau_dyn = model.terms(q[:, :1], qd[:, :1], qdd[:, :1])
    assert tau_g.shape == tau_dyn.shape == (len(q), 1)
    g_ref, dyn_ref = analytic(np.column_stack([q[:, 0], still]), np.column_stack([qd[:, 0], still]),
                              np.column_stack([qdd[:, 0], still]), (0.0, -9.81, 0.0))
    close(tau_g, g_ref[:, :1])
    close(tau_dyn, dyn_ref[:, :1])
    y, _ = payload.body_regressor(model, "flange", q[:, :1], qd[:, :1], qdd[:, :1])
    assert y.shape == (len(q), 1, 10)


def test_rotor_inertia_and_payload_in_a_rotated_frame(rng):
    pytest.importorskip("pinocchio")
    from fricli.robot.dynamics import RobotModel

    gravity = (0.0, -9.81, 0.0)
    # the flange frame is turned 90 degrees about z: its -y axis points along link 2
    payload = Payload(mass=1.7, com=(0.0, -0.08, 0.0), frame="flange")
    model = RobotModel(URDF, "two_link.urdf", gravity=gravity, payload=payload)
    q, qd, qdd = motion(rng)
    tau_g, tau_dyn = model.terms(q, qd, qdd, rotor_inertia=np.array([0.9, 0.25]))
    g_ref, dyn_ref = analytic(q, qd, qdd, gravity, payload_mass=1.7, payload_reach=L2 + 0.08, rotor=(0.9, 0.25))
    close(tau_g, g_ref)
    close(tau_dyn, dyn_ref)
    with pytest.raises(errors.ModelFileError, match="no frame 'tool0'"):
        RobotModel(URDF, "two_link.urdf", payload=Payload(1.0, (0, 0, 0), "tool0"))


def test_row_by_row_path_gives_the_same_terms(rng, monkeypatch):
    pin = pytest.importorskip("pinocchio")
    from fricli.robot import dynamics

    model = dynamics.RobotModel(URDF, "two_link.urdf", gravity=(0, -9.81, 0))
    q, qd, qdd = motion(rng, 50)
    batched = model.terms(q, qd, qdd)
    monkeypatch.delattr(pin, "rneaInParallel", raising=False)
    rows = model.terms(q, qd, qdd)
    for a, b in zip(batched, rows):
        np.testing.assert_allclose(a, b, rtol=0, atol=1e-12)


def test_joint_matching_is_explicit_and_checked():
    pytest.importorskip("pinocchio")
    from fricli.robot.dynamics import RobotModel

    model = RobotModel(URDF, "two_link.urdf")
    assert model.match([None, None], "order") == [0, 1]
    assert model.match(["elbow", "shoulder"], "name") == [1, 0]
    with pytest.raises(errors.ModelFileError, match="3 moving joints|2 moving joints, but the log has 3"):
        model.match([None, None, None], "order")
    with pytest.raises(errors.ModelFileError, match="no joint 'wrist'"):
        model.match(["shoulder", "wrist"], "name")
    with pytest.raises(errors.ModelFileError, match="'elbow' .revolute. is not in the log: .* --hold JOINT"):
        model.match(["shoulder"], "name")
    with pytest.raises(errors.ModelFileError, match="matched by two"):
        model.match(["shoulder", "shoulder"], "name")


def test_not_a_urdf_is_a_model_error():
    pytest.importorskip("pinocchio")
    from fricli.robot.dynamics import RobotModel

    with pytest.raises(errors.ModelFileError, match="not a usable URDF"):
        RobotModel("<robot name='x'><link", "bad.urdf")


@pytest.mark.parametrize("xyz, why", [("0 0 0", "joint 'elbow' has the axis '0 0 0'"),
                                      ("0.0 -0 0", "joint 'elbow' has the axis '0.0 -0 0'"),
                                      ("0 nan 1", "Malformed axis element for joint"), ("0 0", "Malformed axis")])
def test_a_joint_axis_that_is_no_direction_is_a_model_error(xyz, why):
    """Pinocchio builds a joint of axis 0 0 0 without complaint, and its torques come out zero."""
    pytest.importorskip("pinocchio")
    from fricli.robot.dynamics import RobotModel

    with pytest.raises(errors.ModelFileError, match=why):
        RobotModel(URDF.replace('<axis xyz="0 0 1"/>\n    <limit lower="-10" upper="10" effort="100" velocity="10"/>\n'
                                '  </joint>\n  <link name="link2">',
                                f'<axis xyz="{xyz}"/>\n    <limit lower="-10" upper="10" effort="100" velocity="10"/>\n'
                                '  </joint>\n  <link name="link2">'), "arm.urdf")
    RobotModel(URDF.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 2"/>'), "arm.urdf")   # any length


def test_a_xacro_file_is_named_as_one():
    """ROS descriptions ship as .urdf.xacro macros; the URDF parser would only say it found no links."""
    pytest.importorskip("pinocchio")
    from fricli.robot.dynamics import RobotModel

    xacro = ('<robot xmlns:xacro="http://www.ros.org/wiki/xacro" name="ur">'
             '<xacro:include filename="$(find ur_description)/urdf/ur_macro.xacro"/><xacro:ur_robot name="ur"/></robot>')
    with pytest.raises(errors.ModelFileError, match=re.escape("arm.urdf.xacro: a xacro file, not a URDF: expand it "
                                                              "first (xacro arm.urdf.xacro > robot.urdf")):
        RobotModel(xacro, "arm.urdf.xacro")


@pytest.mark.parametrize("text, why", [
    ("<robot name='x'><link name='a'><bad", "Error=XML_ERROR_PARSING_ELEMENT ErrorID=6 (0x6) Line number=1: "
                                            "XMLElement name=bad"),
    ("<robot name='x'><link name='a'/><joint name='j' type='revolute'><parent link='a'/><child link='b'/>"
     "</joint></robot>", "Joint [j] is of type REVOLUTE but it does not specify limits")])
def test_the_urdf_parsers_complaint_is_the_one_error_line(tmp_path, text, why):
    """The URDF parser writes to the process's stderr itself: its complaint becomes the reason of
    fricli's one line, and nothing else reaches stderr."""
    pytest.importorskip("pinocchio")
    (tmp_path / "bad.urdf").write_text(text)
    pq.write_table(logs.table_from_arrays({"t": np.arange(5.0), "q": np.zeros(5), "tau_m": np.zeros(5)}, {}),
                   tmp_path / "x.parquet")
    done = subprocess.run([sys.executable, "-m", "fricli", "dynamics", "x.parquet", "--urdf", "bad.urdf", "--match",
                           "name", "-o", "y.parquet"], cwd=tmp_path, capture_output=True, text=True,
                          env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert done.returncode == errors.MODEL
    assert done.stderr.splitlines() == [f"fricli: error: bad.urdf: not a usable URDF ({why})"], done.stderr


# ---------------------------------------------------------------------- the command


def mapping_text(match="order", qdd=True):
    joints = ""
    for k, (name, urdf) in enumerate([("a", "shoulder"), ("b", "elbow")]):
        joints += f"""
[[joints]]
name = "{name}"
urdf = "{urdf}"
q = {2 + k}
qd = {4 + k}
{f"qdd = {6 + k}" if qdd else ""}
tau_m = {8 + k}
rotor_inertia = {0.5 * (k + 1)}
"""
    return f"""time = 1
[robot]
match = "{match}"
gravity = [0.0, -9.81, 0.0]
{joints}"""


def write_case(tmp_path, rng, n=300, match="order", qdd=True):
    q, qd, acc = motion(rng, n)
    t = np.arange(n) * 0.01
    data = np.column_stack([t, q, qd, acc, rng.normal(size=(n, 2))])
    np.savetxt(tmp_path / "rec.csv", data, delimiter=",", fmt="%.17g")
    (tmp_path / "two_link.urdf").write_text(URDF)
    (tmp_path / "map.toml").write_text(mapping_text(match, qdd))
    return t, q, qd, acc


def run(*args, cwd):
    return run_in(cwd, *args)


def test_import_with_urdf_writes_the_analytic_terms(tmp_path, rng):
    pytest.importorskip("pinocchio")
    t, q, qd, qdd = write_case(tmp_path, rng)
    res = run("import", "rec.csv", "--mapping", "map.toml", "--urdf", "two_link.urdf",
              "--payload-mass", "1.2", "--payload-com", "0", "-0.05", "0", "--payload-frame", "flange",
              "--rotor-inertia", "b=0.3", "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    table = pq.read_table(tmp_path / "out.parquet")
    assert table.column("joint").to_pylist() == ["a"] * len(t) + ["b"] * len(t)
    n = len(t)
    tau_g = np.column_stack([table.column("tau_g").to_numpy()[:n], table.column("tau_g").to_numpy()[n:]])
    tau_dyn = np.column_stack([table.column("tau_dyn").to_numpy()[:n], table.column("tau_dyn").to_numpy()[n:]])
    g_ref, dyn_ref = analytic(q, qd, qdd, (0, -9.81, 0), payload_mass=1.2, payload_reach=L2 + 0.05, rotor=(0.5, 0.3))
    close(tau_g, g_ref)
    close(tau_dyn, dyn_ref)
    assert table.schema.field("tau_dyn").metadata[b"unit"] == b"Nm"
    meta = json.loads(table.schema.metadata[b"fricli.import"])
    robot = meta["robot"]
    assert robot["joints"] == {"a": "shoulder", "b": "elbow"} and robot["match"] == "order"
    assert robot["rotor_inertia"] == {"a": 0.5, "b": 0.3}
    assert robot["payload"] == {"mass": 1.2, "com": [0.0, -0.05, 0.0], "frame": "flange"}
    assert robot["derived"] == {}


def test_derived_acceleration_is_recorded_and_follows_the_log_contract(tmp_path, rng):
    pytest.importorskip("pinocchio")
    from fricli.core.logs import derive_motion

    t, q, qd, _ = write_case(tmp_path, rng, qdd=False)
    res = run("import", "rec.csv", "--mapping", "map.toml", "--urdf", "two_link.urdf", "--cutoff", "10",
              "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "derived qdd (low-pass 10 Hz" in res.stderr
    table = pq.read_table(tmp_path / "out.parquet")
    meta = json.loads(table.schema.metadata[b"fricli.import"])
    assert meta["robot"]["derived"] == {"columns": {"qdd": ["a", "b"]}, "cutoff_hz": 10.0, "filtered": True}
    sig = {"t": t, "q": q[:, 1], "qd": qd[:, 1]}
    derive_motion(sig, 10.0)
    np.testing.assert_allclose(table.column("qdd").to_numpy()[len(t):], sig["qdd"], rtol=1e-12, atol=1e-12)


def test_import_refuses_unmatched_joints_and_a_missing_choice(tmp_path, rng):
    pytest.importorskip("pinocchio")
    write_case(tmp_path, rng, n=50, match="name")
    text = (tmp_path / "map.toml").read_text().replace('urdf = "elbow"', 'urdf = "knee"')
    (tmp_path / "bad.toml").write_text(text)
    res = run("import", "rec.csv", "--mapping", "bad.toml", "--urdf", "two_link.urdf", "-o", "out.parquet",
              cwd=tmp_path)
    assert res.returncode == errors.MODEL and "no joint 'knee'" in res.stderr
    assert len(res.stderr.strip().splitlines()) == 1
    (tmp_path / "nomatch.toml").write_text(text.replace('match = "name"\n', ""))
    res = run("import", "rec.csv", "--mapping", "nomatch.toml", "--urdf", "two_link.urdf", "-o", "out.parquet",
              cwd=tmp_path)
    assert res.returncode == errors.INPUT and "--match name|order" in res.stderr
    res = run("import", "rec.csv", "--mapping", "nomatch.toml", "--urdf", "two_link.urdf", "--match", "order",
              "-o", "out.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert not (tmp_path / "bad.parquet").exists()


def test_without_pinocchio_one_line_says_how_to_install(tmp_path, rng):
    write_case(tmp_path, rng, n=50)
    code = ("import sys; sys.modules['pinocchio'] = None; from fricli.cli import main; "
            "sys.argv = ['fricli', 'import', 'rec.csv', '--mapping', 'map.toml', '--urdf', 'two_link.urdf', "
            "'-o', 'out.parquet']; main()")
    res = subprocess.run([sys.executable, "-c", code], cwd=tmp_path, capture_output=True, text=True,
                         env={"PYTHONPATH": str(ROOT), "PATH": "/usr/bin:/bin"})
    assert res.returncode == errors.DEPENDENCY
    assert res.stderr == "fricli: error: --urdf needs Pinocchio: pip install 'fricli[robot]'\n"
    assert not (tmp_path / "out.parquet").exists()


def test_mapping_options_parse_robot_section():
    doc = {"time": 1, "robot": {"match": "name", "gravity": [0, 0, -9.8],
                                "payload": {"mass": 2.0, "com": [0, 0, 0.1], "frame": "tool0"}},
           "joints": [{"name": 1, "q": 2, "tau_m": 3}]}
    mapping = parse_mapping(doc)
    assert mapping.match == "name" and mapping.gravity == (0.0, 0.0, -9.8)
    assert mapping.payload == Payload(2.0, (0.0, 0.0, 0.1), "tool0")
    doc["robot"]["match"] = "index"
    with pytest.raises(errors.LogError, match="robot.match"):
        parse_mapping(doc)


def doc_example():
    """The UR10e command and its output as docs/robot-import.md shows them."""
    text = (ROOT / "docs" / "robot-import.md").read_text()
    block = text.split("```console\n$ fricli ", 1)[1].split("```", 1)[0]
    command, output = block.split("\n", 1)
    return command.split(), output


def test_ur10e_import_with_urdf_as_documented(tmp_path):
    pytest.importorskip("pinocchio")
    folder = shared_data("ur10e")
    args, expected = doc_example()
    out = str(tmp_path / "run.parquet")
    args[args.index("run.parquet")] = out
    res = run(*args, cwd=ROOT)
    assert res.returncode == 0, res.stderr
    assert res.stderr == expected.replace("-> run.parquet", f"-> {out}")
    table = pq.read_table(out)
    assert sorted(set(table.column("joint").to_pylist())) == [1, 2, 3, 4, 5, 6]
    # the gravity model explains most of the shoulder-lift motor torque
    rows = np.asarray(table.column("joint")) == 2
    tau_m, tau_g = table.column("tau_m").to_numpy()[rows], table.column("tau_g").to_numpy()[rows]
    assert np.corrcoef(tau_m, tau_g)[0, 1] > 0.9
    check = json.loads(table.schema.metadata[b"fricli.import"])["robot"]["mapping_check"]
    assert check["findings"] == []            # the documented mapping agrees with the URDF: no warning
    assert check["joints"]["2"]["correlation"] > 0.9 and 0.8 < check["joints"]["2"]["scale"] < 1.25
    # joint 1's axis is vertical: no gravity torque
    assert np.abs(table.column("tau_g").to_numpy()[np.asarray(table.column("joint")) == 1]).max() < 1e-9
    assert (folder / "ur10e.urdf").exists()


def test_dynamics_adds_the_same_terms_to_an_existing_log(tmp_path, rng, monkeypatch):
    pytest.importorskip("pinocchio")
    t, q, qd, qdd = write_case(tmp_path, rng)
    assert run("import", "rec.csv", "--mapping", "map.toml", "-o", "plain.parquet", cwd=tmp_path).returncode == 0
    res = run("dynamics", "plain.parquet", "--urdf", "two_link.urdf", "--match", "name", "--urdf-joint", "a=shoulder",
              "--urdf-joint", "b=elbow", "--gravity", "0", "-9.81", "0", "--rotor-inertia", "a=0.5",
              "--rotor-inertia", "b=1.0", "-o", "dyn.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    table = pq.read_table(tmp_path / "dyn.parquet")
    n = len(t)
    g_ref, dyn_ref = analytic(q, qd, qdd, (0, -9.81, 0), rotor=(0.5, 1.0))
    for column, ref in (("tau_g", g_ref), ("tau_dyn", dyn_ref)):
        values = table.column(column).to_numpy()
        close(np.column_stack([values[:n], values[n:]]), ref)
    assert json.loads(table.schema.metadata[b"fricli.dynamics"])["joints"] == {"a": "shoulder", "b": "elbow"}
    # the Python call writes the command's file
    import fricli
    from fricli.fitting.optionspec import OptionError

    monkeypatch.chdir(tmp_path)
    made, record = fricli.add_dynamics("plain.parquet", "two_link.urdf", "call.parquet", match="name",
                                       urdf_joints={"a": "shoulder", "b": "elbow"}, gravity=(0, -9.81, 0),
                                       rotor_inertia={"a": 0.5, "b": 1.0})
    assert pq.read_table(tmp_path / "call.parquet").equals(table, check_metadata=True)
    assert made.equals(table, check_metadata=True)
    assert record == json.loads(table.schema.metadata[b"fricli.dynamics"])
    for kwargs, option in (({}, "match"), ({"match": "order", "payload_mass": 1.0}, "payload_frame")):
        with pytest.raises(OptionError) as err:
            fricli.add_dynamics("plain.parquet", "two_link.urdf", **kwargs)
        assert err.value.option == option
    # joints sampled at different times cannot share one robot model
    shifted = table.set_column(0, table.schema.field("t"), [np.concatenate([t, t + 0.001])])
    pq.write_table(shifted, tmp_path / "shifted.parquet")
    res = run("dynamics", "shifted.parquet", "--urdf", "two_link.urdf", "--match", "order", "-o", "x.parquet",
              cwd=tmp_path)
    assert res.returncode == errors.INPUT and "not sampled at the same times" in res.stderr
    assert not (tmp_path / "x.parquet").exists()
    # a log without rows (it was an internal error)
    pq.write_table(table.slice(0, 0), tmp_path / "empty.parquet")
    res = run("dynamics", "empty.parquet", "--urdf", "two_link.urdf", "--match", "order", "-o", "x.parquet",
              cwd=tmp_path)
    assert res.returncode == errors.INPUT and res.stderr == "fricli: error: empty.parquet: the log is empty\n", res.stderr
    assert not (tmp_path / "x.parquet").exists()


@pytest.mark.slow
def test_the_cutoff_of_derived_accelerations_is_chosen_from_the_torque(tmp_path):
    """A four-joint arm at 1 kHz whose recording gives positions in encoder steps (2^16 per turn) and
    motor torques, no velocity: differentiating the steps twice swamps tau_dyn unless the low-pass
    cuts them. By default the cut-off is chosen from how well the robot model explains tau_m, with
    no knowledge of the true acceleration; its tau_dyn must be within 10 % of the best the grid's
    cut-offs give against the true one, and the log contract's 50 Hz at least twice as far off."""
    pytest.importorskip("pinocchio")
    import test_calibrate as arm
    from fricli.robot.dynamics import RobotModel
    from fricli.robot.importing import CUTOFF_GRID

    rng = np.random.default_rng(11)
    model, _ = arm.true_model(rng)
    n, rate = 20_000, 1000.0
    t = np.arange(n) / rate
    q, qd, qdd = (np.zeros((n, 4)) for _ in range(3))
    for j in range(4):
        for f in (0.2, 0.45, 0.7, 1.1):
            w, a, ph = 2 * np.pi * f * rng.uniform(0.8, 1.2), 0.25 * rng.uniform(0.3, 1.0) / f, rng.uniform(0, 6.3)
            q[:, j] += a * np.sin(w * t + ph)
            qd[:, j] += a * w * np.cos(w * t + ph)
            qdd[:, j] -= a * w * w * np.sin(w * t + ph)
    tau = arm.simulate(model, t, q, qd, qdd, rng=rng, noise=0.05)
    step = 2 * np.pi / 2 ** 16
    np.savetxt(tmp_path / "rec.csv", np.column_stack([t, np.round(q / step) * step, tau]), delimiter=",", fmt="%.17g")
    (tmp_path / "arm.urdf").write_text(arm.URDF)
    (tmp_path / "map.toml").write_text('time = 1\n[robot]\nmatch = "order"\n' + "".join(
        f"[[joints]]\nname = {k}\nq = {k + 1}\ntau_m = {k + 5}\n" for k in range(1, 5)))
    cad = RobotModel(arm.URDF, "cad")
    true_dyn = cad.terms(q, qd, qdd)[1]

    def error(path):
        table = pq.read_table(path)
        return np.linalg.norm(table.column("tau_dyn").to_numpy().reshape(4, n).T - true_dyn)

    res = run("import", "rec.csv", "--mapping", "map.toml", "--urdf", "arm.urdf", "-o", "auto.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    derived = json.loads(pq.read_table(tmp_path / "auto.parquet").schema.metadata[b"fricli.import"])["robot"]["derived"]
    chosen = derived["cutoff_hz"]
    grid = derived["cutoff_choice"]["candidates_hz"]    # below the Nyquist frequency, then none (at it)
    assert grid[:-1] == [c for c in CUTOFF_GRID if c < 499] and grid[-1] == pytest.approx(500.0)
    assert f"cut-off of the derived columns: {chosen:g} Hz, chosen of 2 Hz to no low-pass" in res.stderr
    assert re.search(r"leave the least of tau_m - tau_g in motion, [0-9.]+ Nm RMS \(geometric mean", res.stderr)
    assert f"derived qd and qdd (low-pass {chosen:g} Hz chosen from the data" in res.stderr
    errors_by_cutoff = {}
    for c in grid[:-1]:                       # what import derives with each cut-off (the log contract's way)
        motions = [{"t": t, "q": np.round(q[:, k] / step) * step} for k in range(4)]
        for m in motions:
            logs.derive_motion(m, c)
        derived_dyn = cad.terms(*(np.column_stack([m[x] for m in motions]) for x in ("q", "qd", "qdd")))[1]
        errors_by_cutoff[c] = np.linalg.norm(derived_dyn - true_dyn)
    assert error(tmp_path / "auto.parquet") == pytest.approx(errors_by_cutoff[chosen], rel=1e-12)
    assert errors_by_cutoff[chosen] <= 1.1 * min(errors_by_cutoff.values())
    assert errors_by_cutoff[50.0] >= 2 * errors_by_cutoff[chosen]
    # without torques (a library call: the log contract requires tau_m) auto cannot choose; the default
    # then keeps the contract's 50 Hz
    from fricli.robot.importing import robot_terms
    from fricli.robot.mapping import JointMap, Mapping

    mapping = Mapping(time=None, joints=[JointMap(name=k, columns={}) for k in range(1, 5)], match="order")
    positions = [{"q": np.round(q[:, k] / step) * step} for k in range(4)]
    with pytest.raises(errors.LogError, match="--cutoff auto chooses the cut-off"):
        robot_terms(cad, mapping, t, [dict(p) for p in positions], "rotary", "auto")
    assert robot_terms(cad, mapping, t, [dict(p) for p in positions], "rotary")["derived"]["cutoff_hz"] == 50.0
    # an arm held still gives nothing to choose by: the contract's 50 Hz, no choice recorded
    still = [{"q": np.full(n, 0.3), "tau_m": tau[:, k]} for k in range(4)]
    assert robot_terms(cad, mapping, t, still, "rotary")["derived"] == {
        "columns": {"qd": [1, 2, 3, 4], "qdd": [1, 2, 3, 4]}, "cutoff_hz": 50.0, "filtered": True}
    # a recording too short for any low-pass (fewer than 16 rows): every cut-off derives the same,
    # so none is chosen, and the log says no low-pass applied
    short = [{"q": q[:5, k], "tau_m": tau[:5, k]} for k in range(4)]
    assert robot_terms(cad, mapping, t[:5], short, "rotary")["derived"] == {
        "columns": {"qd": [1, 2, 3, 4], "qdd": [1, 2, 3, 4]}, "cutoff_hz": 50.0, "filtered": False}


def test_a_continuous_joint_recorded_wrapped_is_derived_unwrapped(rng):
    """A continuous joint recorded within one turn (as controllers and ROS report it) jumps by 2 pi
    where it wraps: differentiated as it is, qd peaks at 2 pi / dt there and tau_dyn with it. The
    import derives from the unwrapped position, keeps q as recorded and says so."""
    pytest.importorskip("pinocchio")
    import test_calibrate as arm
    from fricli.robot.dynamics import RobotModel
    from fricli.robot.importing import robot_terms
    from fricli.robot.mapping import JointMap, Mapping

    t = np.arange(3000) / 100.0
    q = np.column_stack([0.3 * np.sin(0.5 * t), 0.4 * np.sin(0.7 * t), 0.3 * np.sin(0.9 * t), 2.0 * t])  # j4 turns
    wrapped = q.copy()
    wrapped[:, 3] = np.angle(np.exp(1j * q[:, 3]))                  # in (-pi, pi]
    model = RobotModel(arm.URDF, "four")
    assert model.continuous == [False, False, False, True]
    mapping = Mapping(time=None, joints=[JointMap(name=k, columns={}) for k in range(1, 5)], match="order")

    def imported(positions):
        sigs = [{"q": positions[:, k].copy()} for k in range(4)]
        return sigs, robot_terms(model, mapping, t, sigs, "rotary", 20.0)

    sigs, record = imported(wrapped)
    truth, clean = imported(q)
    assert record["unwrapped"] == ["4"] and clean["unwrapped"] == []
    np.testing.assert_array_equal(sigs[3]["q"], wrapped[:, 3])        # the log keeps q as recorded
    inner = slice(100, -100)
    for k in range(4):
        np.testing.assert_allclose(sigs[k]["qd"][inner], truth[k]["qd"][inner], atol=1e-9)
        np.testing.assert_allclose(sigs[k]["tau_dyn"][inner], truth[k]["tau_dyn"][inner], atol=1e-9)
    assert np.abs(sigs[3]["qd"]).max() < 2.5


def test_a_revolute_joint_recorded_wrapped_is_derived_unwrapped_too(rng):
    """A revolute joint whose limits pass +-pi (the UR's +-2 pi), reported within one turn by its
    driver, jumps by 2 pi as a continuous one does: derived from its unwrapped position."""
    pytest.importorskip("pinocchio")
    import test_calibrate as arm
    from fricli.robot.dynamics import RobotModel
    from fricli.robot.importing import robot_terms
    from fricli.robot.mapping import JointMap, Mapping

    t = np.arange(3000) / 100.0
    q = np.column_stack([3.0 + 0.5 * np.sin(0.5 * t), 0.4 * np.sin(0.7 * t), 0.3 * np.sin(0.9 * t), 0.2 * t])
    wrapped = q.copy()
    wrapped[:, 0] = np.angle(np.exp(1j * q[:, 0]))                  # j1 (revolute) crosses pi
    model = RobotModel(arm.URDF, "four")
    assert model.continuous[0] is False
    mapping = Mapping(time=None, joints=[JointMap(name=k, columns={}) for k in range(1, 5)], match="order")
    sigs = [{"q": wrapped[:, k].copy()} for k in range(4)]
    record = robot_terms(model, mapping, t, sigs, "rotary", 20.0)
    truth = [{"q": q[:, k].copy()} for k in range(4)]
    robot_terms(model, mapping, t, truth, "rotary", 20.0)
    assert record["unwrapped"] == ["1"]
    inner = slice(100, -100)
    for k in range(4):
        np.testing.assert_allclose(sigs[k]["qd"][inner], truth[k]["qd"][inner], atol=1e-9)
        np.testing.assert_allclose(sigs[k]["tau_g"], truth[k]["tau_g"], atol=1e-9)


def test_import_derives_an_acceleration_column_of_zeros_for_the_robot_terms(tmp_path, rng):
    """A recorder that fills the acceleration column with zeros (the Franka friction files: ddq2 is 0 on
    every row): with --urdf, import reports it and derives qdd for tau_dyn, as when no qdd is mapped;
    without, it reports it and keeps the column as recorded, which every command reads as missing."""
    pytest.importorskip("pinocchio")
    t, q, qd, qdd = write_case(tmp_path, rng)
    data = np.loadtxt(tmp_path / "rec.csv", delimiter=",")
    data[:, 5:7] = 0.0
    np.savetxt(tmp_path / "rec.csv", data, delimiter=",", fmt="%.17g")
    res = run("import", "rec.csv", "--mapping", "map.toml", "--urdf", "two_link.urdf", "--cutoff", "20",
              "-o", "zeros.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    notes = [line for line in res.stderr.splitlines() if "qdd is constant (0)" in line]
    assert [n.split(":")[1] for n in notes] == [" rec.csv, joint a", " rec.csv, joint b"]
    assert all(n.endswith("not a measurement, derived from the velocity instead") for n in notes)
    (tmp_path / "map.toml").write_text(mapping_text("order", qdd=False))
    res = run("import", "rec.csv", "--mapping", "map.toml", "--urdf", "two_link.urdf", "--cutoff", "20",
              "-o", "none.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    zeros, none = pq.read_table(tmp_path / "zeros.parquet"), pq.read_table(tmp_path / "none.parquet")
    for column in ("qdd", "tau_dyn", "tau_g"):
        np.testing.assert_array_equal(zeros.column(column).to_numpy(), none.column(column).to_numpy())
    assert np.abs(zeros.column("qdd").to_numpy()).max() > 0.1
    (tmp_path / "map.toml").write_text(mapping_text("order", qdd=True))
    res = run("import", "rec.csv", "--mapping", "map.toml", "-o", "kept.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "joint a: the acceleration column qdd is constant (0) while the velocity varies otherwise: not a " \
           "measurement; the log keeps it as recorded and every command reads it as missing" in res.stderr
    kept = pq.read_table(tmp_path / "kept.parquet")
    assert not kept.column("qdd").to_numpy().any()
    assert set(json.loads(kept.schema.metadata[b"fricli.import"])["not_measured"]) == {"a", "b"}
