"""The import's check of a mapping against the robot model (fricli/robot/sanity.py): motor-side
recordings of the simulated coupled-wrist arm (fricli/sim/coupled.py) with the torques of a six-joint
URDF, imported with a mapping that has one mistake each: a joint's zero a quarter turn off, a joint
turning the other way, a coupling term off by 2 in 32. Each is flagged with its joint and cause,
and the correct mapping is not."""

import math

import numpy as np
import pytest
from click.testing import CliRunner

from fricli.cli import cli
from fricli.core.transmission import Transmission
from fricli.sim import coupled

pytest.importorskip("pinocchio")

RATE = 500.0


def urdf_text() -> str:
    axes = ["0 0 1", "0 1 0", "0 1 0", "0 1 0", "0 0 1", "0 1 0"]
    # the last link carries a tool: its weight, 20 cm off joint 6's axis, loads the coupled wrist (a coupling
    # term off by d shows in motor 5's torque as d tau_6 / (R55 R66), which must stand above the noise)
    masses = [4.0, 8.0, 4.0, 2.0, 1.5, 6.0]
    lengths = [0.1, 0.6, 0.5, 0.15, 0.1, 0.4]
    parts = ['<?xml version="1.0"?>\n<robot name="arm6"><link name="base"/>']
    parent = "base"
    for k in range(6):
        m, L = masses[k], lengths[k]
        parts.append(f'<joint name="j{k + 1}" type="revolute"><parent link="{parent}"/><child link="l{k + 1}"/>'
                     f'<origin xyz="{0.0 if k == 0 else lengths[k - 1]} 0 {0.1 if k == 0 else 0}"/><axis xyz="{axes[k]}"/>'
                     '<limit lower="-6" upper="6" effort="500" velocity="5"/></joint>')
        i = m * L * L / 12 + 0.001
        parts.append(f'<link name="l{k + 1}"><inertial><origin xyz="{L / 2} 0 0.02"/><mass value="{m}"/>'
                     f'<inertia ixx="{0.001 * m}" ixy="0" ixz="0" iyy="{i}" iyz="0" izz="{i}"/></inertial></link>')
        parent = f"l{k + 1}"
    parts.append("</robot>")
    return "\n".join(parts)


def true_transmission() -> Transmission:
    tr = coupled.default_arm().transmission
    ratio = tr.ratio.copy()
    ratio[5, 4] = 32.0
    return Transmission(tr.joints, ratio, offset=tr.offset)


def recording(folder, seed=3, duration=24.0):
    """positions.csv and torques.csv of the arm: motor angles and motor torques."""
    from fricli.robot.dynamics import RobotModel

    tr = true_transmission()
    arm = coupled.CoupledArm(tr, coupled.default_arm().friction, gravity=np.zeros(6), link_inertia=np.zeros(6),
                             noise_sd=np.full(6, 0.002))
    t = np.arange(int(duration * RATE)) / RATE
    rng = np.random.default_rng(seed)
    q, qd, qdd = coupled.trajectories(t, 6, rng)
    q = q + np.array([0.0, -0.6, 0.9, 0.2, 0.0, 0.3])          # about a pose where gravity loads joints 2-4 and 6
    g, d = RobotModel(urdf_text(), "arm6.urdf").terms(q, qd, qdd)
    tau_motor = tr.motor_torques(g + d + arm.joint_friction(qd)) + rng.normal(size=q.shape) * arm.noise_sd
    np.savetxt(folder / "positions.csv", tr.motor_positions(q), delimiter=",", fmt="%.17g")
    np.savetxt(folder / "torques.csv", tau_motor, delimiter=",", fmt="%.17g")
    (folder / "arm6.urdf").write_text(urdf_text())


def import_with(folder, tr: Transmission):
    text = coupled.mapping_text(tr, RATE, 1.0) + '\n[robot]\nmatch = "order"\n'
    (folder / "map.toml").write_text(text)
    res = CliRunner().invoke(cli, ["import", str(folder / "positions.csv"), str(folder / "torques.csv"), "--mapping",
                                   str(folder / "map.toml"), "--urdf", str(folder / "arm6.urdf"), "-o",
                                   str(folder / "log.parquet")])
    assert res.exit_code == 0, res.stderr
    return [line for line in res.stderr.splitlines() if "the mapping disagrees" in line]


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    path = tmp_path_factory.mktemp("arm6")
    recording(path)
    return path


def wrong_zero(tr: Transmission) -> Transmission:
    return Transmission(tr.joints, tr.ratio, offset=tr.offset + tr.ratio[:, 1] * math.pi / 2)


@pytest.fixture(scope="module")
def wrong_zero_folder(folder, tmp_path_factory):
    """The recording imported once with joint 2's offset left out of the mapping (a zero a quarter turn
    off), in a folder of its own: (folder, the import's lines on the mapping)."""
    import shutil

    path = tmp_path_factory.mktemp("wrong_zero")
    for name in ("positions.csv", "torques.csv", "arm6.urdf"):
        shutil.copy(folder / name, path / name)
    return path, import_with(path, wrong_zero(true_transmission()))


def test_the_right_mapping_passes_without_a_word(folder):
    assert import_with(folder, true_transmission()) == []


def test_a_zero_a_quarter_turn_off_is_flagged(wrong_zero_folder):
    tr = true_transmission()
    _, lines = wrong_zero_folder
    assert len(lines) == 1, lines
    assert "joint 2: its zero is +pi/2 away from the URDF's" in lines[0], lines
    new = [float(x) for x in lines[0].split("[transmission] offset = [")[1].split("]")[0].split(",")]
    assert np.allclose(new, tr.offset, atol=1e-4), (new, tr.offset)


def test_a_joint_turning_the_other_way_is_flagged(folder):
    tr = true_transmission()
    ratio = tr.ratio.copy()
    ratio[:, 2] = -ratio[:, 2]
    lines = import_with(folder, Transmission(tr.joints, ratio, offset=tr.offset))
    assert len(lines) == 1, lines
    assert "joint 3: it turns the other way than the URDF's axis (a sign)" in lines[0], lines


def test_a_coupling_term_off_by_two_in_thirty_two_is_flagged(folder):
    tr = true_transmission()
    ratio = tr.ratio.copy()
    ratio[5, 4] = 30.0
    lines = import_with(folder, Transmission(tr.joints, ratio, offset=tr.offset))
    assert len(lines) == 1, lines
    assert "joint 5: the coupling term of motor 6 on joint 5 is 30 in the mapping; " in lines[0], lines
    fitted = float(lines[0].split("in the mapping; ")[1].split(" fits")[0])
    assert abs(fitted - 32.0) < 0.2, lines


def joint_side_import(folder, degrees: list[int], milli: list[int] = (), mapped_deg: list[int] = ()) -> list[str]:
    """A joint-side recording of the six-joint arm (q, qd, tau_m per joint; friction Fv 2 qd +
    Fc 3 sign(qd)) with the joints ``degrees`` (0-based) written in degrees and the torques of the
    joints ``milli`` in mNm, imported with a mapping that says rad and Nm for every joint but deg
    for the joints ``mapped_deg``: the import's lines on the mapping."""
    from fricli.robot.dynamics import RobotModel

    t = np.arange(int(20 * RATE)) / RATE
    rng = np.random.default_rng(4)
    q, qd, qdd = coupled.trajectories(t, 6, rng)
    q = q + np.array([0.0, -0.6, 0.9, 0.2, 0.0, 0.3])
    g, d = RobotModel(urdf_text(), "arm6.urdf").terms(q, qd, qdd)
    tau = g + d + 2.0 * qd + 3.0 * np.tanh(qd / 0.01) + rng.normal(size=q.shape) * 0.05
    scale = np.ones(6)
    scale[degrees] = 180 / np.pi
    milli_scale = np.ones(6)
    milli_scale[list(milli)] = 1000.0
    cols = [t, *(q * scale).T, *(qd * scale).T, *(tau * milli_scale).T]
    names = ["t"] + [f"{s}{k}" for s in ("q", "qd", "tau") for k in range(1, 7)]
    np.savetxt(folder / "rec.csv", np.column_stack(cols), delimiter=",", header=",".join(names), comments="",
               fmt="%.12g")
    (folder / "arm6.urdf").write_text(urdf_text())
    joints = ""
    for k in range(1, 7):
        q_unit, qd_unit = ("deg", "deg/s") if k - 1 in mapped_deg else ("rad", "rad/s")
        joints += (f'[[joints]]\nname = "j{k}"\nq = {{column = "q{k}", unit = "{q_unit}"}}\n'
                   f'qd = {{column = "qd{k}", unit = "{qd_unit}"}}\ntau_m = "tau{k}"\n')
    (folder / "map.toml").write_text('header = true\ntime = "t"\n[robot]\nmatch = "name"\n' + joints)
    res = CliRunner().invoke(cli, ["import", str(folder / "rec.csv"), "--mapping", str(folder / "map.toml"), "--urdf",
                                   str(folder / "arm6.urdf"), "-o", str(folder / "log.parquet")])
    assert res.exit_code == 0, res.stderr
    return [line for line in res.stderr.splitlines() if "the mapping disagrees" in line]


@pytest.mark.parametrize("degrees,mapped_deg,said,unit", [
    ([], [], None, None),
    ([0, 1, 2, 3, 4, 5], [], "joints j1, j2, j3, j4, j5, j6: their position and velocity are in deg, read as rad", "deg"),
    ([2], [], "joint j3: its position and velocity are in deg, read as rad", "deg"),
    ([], [2], "joint j3: its position and velocity are in rad, read as deg", "rad")])
def test_a_joint_side_motion_in_degrees_read_as_radians_is_flagged(tmp_path, degrees, mapped_deg, said, unit):
    """A recorder that writes degrees, mapped with the default unit rad: the robot model's gravity then
    turns with 57 times the angle, and the check names the unit (and only where it is wrong); the
    same for radians mapped as degrees."""
    lines = joint_side_import(tmp_path, degrees, mapped_deg=mapped_deg)
    if said is None:
        assert lines == []
    else:
        assert len(lines) == 1 and said in lines[0], lines
        assert f'q and qd: unit "{unit}" and "{unit}/s" in the mapping' in lines[0]


def test_a_drive_gain_off_on_a_joint_side_mapping_is_flagged(tmp_path):
    """Joint-side torques with a drive gain off (x0.5 and x2.5 in the mapping's scale): each joint is
    named with the factor that explains its torque; the positions are left as they are."""
    joint_side_import(tmp_path, [])
    text = (tmp_path / "map.toml").read_text()
    for k, f in ((2, 0.5), (4, 2.5)):
        text = text.replace(f'tau_m = "tau{k}"', f'tau_m = {{column = "tau{k}", scale = {f}}}')
    (tmp_path / "map.toml").write_text(text)
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.csv"), "--mapping", str(tmp_path / "map.toml"), "--urdf",
                                   str(tmp_path / "arm6.urdf"), "-o", str(tmp_path / "log.parquet")])
    lines = [line for line in res.stderr.splitlines() if "the mapping disagrees" in line]
    assert len(lines) == 2, lines
    for line, joint, f in zip(lines, ("j2", "j4"), (2.0, 0.4)):
        assert f"joint {joint}: its torque is x" in line and "of the robot model's, a drive gain (kt)" in line, line
        scale = float(line.split("its torque is x")[1].split(" ")[0])
        fix = float(line.split("scale multiplied by ")[1])
        assert abs(scale * f - 1) < 0.05 and abs(fix / f - 1) < 0.05, line


def test_a_torque_in_the_wrong_unit_is_flagged_as_one(tmp_path):
    """Torques in mNm mapped as Nm: the joint's torque is 1000 times the robot model's. It is named
    as a unit (without it, the other changes took the motion read 1000 times too small, as a chain
    of gear ratios)."""
    lines = joint_side_import(tmp_path, [], milli=[1, 3])
    assert len(lines) == 2, lines
    for line, joint in zip(lines, ("j2", "j4")):
        assert f"joint {joint}: its torque is x1e+03 of the robot model's, a current in mA mapped as A or a torque in " \
               "mNm mapped as Nm" in line, line
        assert line.endswith(f"with joint {joint}'s tau_m: scale multiplied by 0.001"), line


def test_a_template_from_a_header_and_a_urdf_imports_as_it_is(tmp_path):
    (tmp_path / "arm6.urdf").write_text(urdf_text())
    t = np.arange(600) / 100.0
    rng = np.random.default_rng(0)
    cols = [t] + [0.3 * np.sin(t + k) for k in range(6)] + [rng.normal(size=600) for _ in range(6)]
    header = "time," + ",".join(f"pos_{k}" for k in range(1, 7)) + "," + ",".join(f"effort_{k}" for k in range(1, 7))
    np.savetxt(tmp_path / "rec.csv", np.column_stack(cols), delimiter=",", header=header, comments="", fmt="%.9g")
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.csv"), "--template", "--urdf", str(tmp_path / "arm6.urdf"),
                                   "-o", str(tmp_path / "map.toml")])
    assert res.exit_code == 0, res.stderr
    text = (tmp_path / "map.toml").read_text()
    assert 'name = "j6"' in text and 'tau_m = {column = 13, unit = "Nm"}' in text and "FILL IN" not in text
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.csv"), "--mapping", str(tmp_path / "map.toml"), "-o",
                                   str(tmp_path / "log.parquet")])
    assert res.exit_code == 0, res.stderr
    assert "dropped" not in res.stderr         # the header is read as one: header = true
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.csv"), "--template", "-o", str(tmp_path / "m2.toml")])
    assert res.exit_code == 2 and "--template needs --urdf" in res.stderr


def test_a_template_asks_for_the_drive_gain_of_a_current_and_reads_v_as_a_velocity(tmp_path):
    (tmp_path / "arm6.urdf").write_text(urdf_text())
    names = ["t"] + [f"{s}_{k}" for s in ("q", "v", "cur") for k in range(1, 7)]
    (tmp_path / "rec.csv").write_text(",".join(names) + "\n" + ",".join(["0.5"] * len(names)) + "\n")
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.csv"), "--template", "--urdf", str(tmp_path / "arm6.urdf"),
                                   "-o", "-"])
    assert res.exit_code == 0, res.stderr
    assert 'qd = {column = 8, unit = "rad/s"}' in res.stdout and 'i_m = {column = 14, unit = "A"}' in res.stdout
    assert res.stdout.count("# kt = VALUE") == 6


_ARM3 = """<robot name="a"><link name="b"/><link name="l1"/><link name="l2"/><link name="l3"/>
<joint name="j1" type="revolute"><parent link="b"/><child link="l1"/><axis xyz="0 0 1"/>
<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/><axis xyz="0 1 0"/>
<limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="a3" type="continuous"><parent link="l2"/><child link="l3"/><axis xyz="0 1 0"/></joint></robot>"""


def test_a_template_takes_the_unit_a_column_name_states(tmp_path):
    (tmp_path / "arm3.urdf").write_text(_ARM3)
    names = ["stamp_ms", "q1_deg", "q2 [rad]", "a3_pos", "qd1_deg_s", "i1_mA", "j2_amps", "tau_a3 (Nm)"]
    (tmp_path / "rec.csv").write_text(",".join(names) + "\n" + ",".join(["0.5"] * len(names)) + "\n")
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.csv"), "--template", "--urdf", str(tmp_path / "arm3.urdf"),
                                   "-o", "-"])
    assert res.exit_code == 0, res.stderr
    lines = res.stdout.splitlines()
    stated = ['time = {column = 1, unit = "ms"}', 'q = {column = 2, unit = "deg"}', 'q = {column = 3, unit = "rad"}',
              'qd = {column = 5, unit = "deg/s"}', 'i_m = {column = 6, unit = "mA"}', 'i_m = {column = 7, unit = "A"}',
              'tau_m = {column = 8, unit = "Nm"}']
    for text in stated:   # a unit the name states is no guess to check
        line = next(ln for ln in lines if ln.startswith(text))
        assert "check the unit" not in line, line
    # no unit in the name ('a3_pos'; the joint's own name 'a3' is no ampere): the default, to check
    assert any(ln.startswith('q = {column = 4, unit = "rad"}') and "check the unit" in ln for ln in lines)
    (tmp_path / "ros.csv").write_text("%time,field.position0\n1,2\n")   # rostopic echo -p: %time in ns
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "ros.csv"), "--template", "--urdf", str(tmp_path / "arm3.urdf"),
                                   "-o", "-"])
    assert 'time = {column = 1, unit = "ns"}' in res.stdout


@pytest.mark.parametrize("names,q_columns", [
    # Universal Robots' RTDE recorder: joints counted from 0, the commanded signals beside the measured ones
    ([f"{w}_{s}_{k}" for w in ("target", "actual") for s in ("q", "qd", "current") for k in range(3)], [11, 12, 13]),
    # a ROS JointState flattened to columns (PlotJuggler): position[0] is the first joint
    ([f"/joint_states/{s}[{k}]" for s in ("position", "velocity", "effort") for k in range(3)], [2, 3, 4])])
def test_a_template_counts_joints_from_zero_and_takes_measured_signals_first(tmp_path, names, q_columns):
    (tmp_path / "arm3.urdf").write_text(_ARM3)
    names = ["timestamp"] + names
    (tmp_path / "rec.csv").write_text(",".join(names) + "\n" + ",".join(["0.5"] * len(names)) + "\n")
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.csv"), "--template", "--urdf", str(tmp_path / "arm3.urdf"),
                                   "-o", "-"])
    assert res.exit_code == 0, res.stderr
    got = [int(ln.split("column = ")[1].split(",")[0]) for ln in res.stdout.splitlines() if ln.startswith("q = {")]
    assert got == q_columns, res.stdout
    assert "target" not in res.stdout.split("# The recording has")[1].split("\n", 1)[1]


def test_a_template_of_a_linear_axis_defaults_to_metres_and_newtons(tmp_path):
    (tmp_path / "gantry.urdf").write_text(
        '<robot name="g"><link name="b"/><link name="c"/><joint name="x" type="prismatic"><parent link="b"/>'
        '<child link="c"/><axis xyz="1 0 0"/><limit lower="0" upper="1" effort="1" velocity="1"/></joint></robot>')
    (tmp_path / "rec.csv").write_text("time,x_pos_mm,x_vel,x_force\n0,1,2,3\n")
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.csv"), "--template", "--urdf",
                                   str(tmp_path / "gantry.urdf"), "-o", "-"])
    assert res.exit_code == 0, res.stderr
    assert 'q = {column = 2, unit = "mm"}' in res.stdout and 'qd = {column = 3, unit = "m/s"}' in res.stdout
    assert 'tau_m = {column = 4, unit = "N"}' in res.stdout and 'unit = "rad' not in res.stdout


def test_a_template_reads_names_aligned_with_spaces(tmp_path):
    (tmp_path / "arm6.urdf").write_text(urdf_text())
    names = ["t"] + [f"pos_{k}" for k in range(1, 7)] + [f"effort_{k}" for k in range(1, 7)]
    (tmp_path / "rec.txt").write_text("".join(f"{n:>12}" for n in names) + "\n" + "".join(f"{0.5:12.4f}" for _ in names) + "\n")
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.txt"), "--template", "--urdf", str(tmp_path / "arm6.urdf"),
                                   "-o", "-"])
    assert res.exit_code == 0, res.stderr
    assert 'delimiter = " "' in res.stdout and 'tau_m = {column = 13, unit = "Nm"}' in res.stdout
    assert "FILL IN" not in res.stdout


def test_a_header_read_as_a_row_is_named_with_the_fix(tmp_path):
    t = np.arange(300) / 100.0
    np.savetxt(tmp_path / "rec.csv", np.column_stack([t, np.sin(t), np.cos(t)]), delimiter=",", header="time,pos,torque",
               comments="", fmt="%.9g")
    (tmp_path / "map.toml").write_text('time = {column = 1, unit = "s"}\n[[joints]]\nname = 1\n'
                                       'q = {column = 2, unit = "rad"}\ntau_m = {column = 3, unit = "Nm"}\n')
    res = CliRunner().invoke(cli, ["import", str(tmp_path / "rec.csv"), "--mapping", str(tmp_path / "map.toml"), "-o",
                                   str(tmp_path / "log.parquet")])
    assert res.exit_code == 0, res.stderr
    assert "line 1: 'time' in column 1: the first line names the columns (set header = true in the mapping)" in res.stderr



@pytest.mark.slow
def test_calibrate_checks_the_log_it_is_given(wrong_zero_folder):
    """calibrate's check of a log (no mapping at hand: the log's joint-side signals, its transmission)."""
    import pyarrow.parquet as pq

    from fricli.robot import calibration, sanity
    from fricli.robot.calibration import motion_check_ratio
    from fricli.robot.dynamics import RobotModel

    robot = RobotModel(urdf_text(), "arm6.urdf")
    motion = calibration.read_motion(pq.read_table(wrong_zero_folder[0] / "log.parquet"), "log", robot, match=None)
    found = sanity.check_motion(robot, motion, motion_check_ratio(robot, motion))["findings"]
    assert [(f["joint"], f["cause"]) for f in found] == [("2", "offset")], found
    assert "joint 2's zero moved by +1.5708 rad ([transmission] offset)" in found[0]["message"]


@pytest.mark.slow
def test_calibrate_warns_of_a_wrong_zero(wrong_zero_folder):
    folder, _ = wrong_zero_folder
    res = CliRunner().invoke(cli, ["calibrate", str(folder / "log.parquet"), "--urdf", str(folder / "arm6.urdf"), "-o",
                                   str(folder / "cal.urdf")])
    assert res.exit_code == 0, res.stderr
    assert "warning: the log's mapping disagrees with the URDF: joint 2: its zero is +pi/2 away from the URDF's" \
        in res.stderr


@pytest.mark.slow
def test_mistakes_planted_in_the_ur10e_mapping_are_flagged_on_real_data():
    """The UR10e's own recording (no transmission, currents times drive gains) with the documented
    mapping changed: joint 2's zero a quarter turn off, joint 3 reversed, joint 2's torque sign reversed."""
    import dataclasses

    from conftest import ROOT, shared_data
    from fricli.robot import importing
    from fricli.robot import mapping as mp
    from fricli.robot.dynamics import load_model

    folder = shared_data("ur10e")
    data = (folder / "identification" / "ur-20_02_19_14harm50sec.csv").read_bytes()

    def findings(change):
        m = mp.load_mapping(str(ROOT / "docs" / "ur10e-mapping.toml"))
        model = load_model(str(folder / "ur10e.urdf"), m)
        change(m)
        res = importing.import_recording(data, m, "run", model=model, cutoff_hz=10.0)
        return [(f["joint"], f["cause"]) for f in res.meta["robot"]["mapping_check"]["findings"]]

    def scaled(jm, signals, **kw):
        for s in signals:
            if s in jm.columns:
                c = jm.columns[s]
                jm.columns[s] = dataclasses.replace(c, **{k: v(c) for k, v in kw.items()})

    assert findings(lambda m: None) == []
    assert findings(lambda m: scaled(m.joints[1], ["q"], offset=lambda c: c.offset + math.pi / 2)) == [("2", "offset")]
    assert findings(lambda m: scaled(m.joints[2], ["q", "qd", "i_m", "tau_m"], scale=lambda c: -c.scale)) == \
        [("3", "direction")]
    assert findings(lambda m: scaled(m.joints[1], ["i_m", "tau_m"], scale=lambda c: -c.scale)) == [("2", "torque-sign")]
