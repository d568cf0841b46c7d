"""Drives: transmissions, the simulated coupled-wrist arm, the coupled friction model (docs/drives.md)."""

from __future__ import annotations

import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import invoke as run
from fricli import models
from fricli.core import logs
from fricli.models.coupled import CoupledModel, fit_group, group_rows
from fricli.core.transmission import Transmission, of_schema
from fricli.sim.coupled import default_arm, simulate_coupled

WRIST = [4, 5]   # indices of joints 5 and 6


@pytest.fixture(scope="module")
def arm_logs(coupled_arm_logs):
    """Two runs of the simulated arm (different trajectories): training and held-out (conftest)."""
    return coupled_arm_logs


# --------------------------------------------------------------------------- transmission


def test_transmission_maps_motor_and_joint_sides_both_ways(rng):
    ratio = np.diag([-120.0, 80.0, -50.0, 40.0])
    ratio[3, 2] = 30.0
    tr = Transmission([1, 2, 5, 6], ratio, offset=[0.1, 0.2, -0.3, 1.0], rotor_inertia=[1e-4, 2e-4, 3e-5, 4e-5])
    q, qd, tau_motor = rng.normal(size=(3, 50, 4))
    np.testing.assert_allclose(tr.joint_positions(tr.motor_positions(q)), q, rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(tr.joint_velocities(tr.motor_velocities(qd)), qd, rtol=1e-12, atol=1e-13)
    tau = tr.joint_torques(tau_motor)
    np.testing.assert_allclose(tr.motor_torques(tau), tau_motor, rtol=1e-12, atol=1e-13)
    # power is the same on both sides of the gearing
    np.testing.assert_allclose((tau_motor * tr.motor_velocities(qd)).sum(1), (tau * qd).sum(1), rtol=1e-12)
    # motor 6 turns with joint 5: theta_6 = 30 q5 + 40 q6 + theta0
    np.testing.assert_allclose(tr.motor_positions(q)[:, 3], 30 * q[:, 2] + 40 * q[:, 3] + 1.0)
    m = tr.reflected_inertia()
    np.testing.assert_allclose(m, ratio.T @ np.diag(tr.rotor_inertia) @ ratio)
    np.testing.assert_allclose(tr.armature(), [1e-4 * 120 ** 2, 2e-4 * 80 ** 2, 3e-5 * 50 ** 2 + 4e-5 * 30 ** 2,
                                               4e-5 * 40 ** 2])
    assert tr.cross_inertia()[2, 3] == pytest.approx(4e-5 * 30 * 40)
    assert np.count_nonzero(tr.cross_inertia()) == 2
    assert tr.groups() == [[0], [1], [2, 3]] and tr.coupled_groups() == [[2, 3]]
    assert Transmission.from_meta(tr.to_meta()).to_meta() == tr.to_meta()


def test_groups_are_connected_components():
    ratio = np.eye(5)
    ratio[0, 3] = ratio[3, 4] = 2.0        # 0-3-4 a chain, 1 and 2 alone
    assert Transmission("abcde", ratio).groups() == [[0, 3, 4], [1], [2]]
    assert Transmission.diagonal([1, 2], [-3.0, 4.0]).is_diagonal


@pytest.mark.parametrize("ratio, message", [(np.zeros((2, 2)), "singular"), (np.ones((2, 3)), "2 x 2"),
                                            ([[1.0, np.nan], [0.0, 1.0]], "non-finite")])
def test_bad_transmissions_are_refused(ratio, message):
    with pytest.raises(ValueError, match=message):
        Transmission([5, 6], ratio)


# --------------------------------------------------------------------------- simulated arm


def test_simulated_arm_noise_is_the_stated_floor(arm_logs):
    _, runs = arm_logs
    r = runs["train"]
    noise = r.tau_m - r.tau_g - r.tau_dyn - r.tau_f
    floor = default_arm().noise_floor()
    np.testing.assert_allclose(noise.std(axis=0), floor, rtol=0.03)
    table = r.table
    assert of_schema(table.schema.metadata).to_meta() == default_arm().transmission.to_meta()
    # joint 6's friction depends on joint 5's velocity: the wrist is coupled
    tr = default_arm().transmission
    assert tr.coupled_groups() == [WRIST]


# --------------------------------------------------------------------------- coupled model


def _target(r):
    return r.tau_m - r.tau_g - r.tau_dyn


def test_coupled_model_reaches_the_noise_floor_on_held_out_data(arm_logs):
    folder, runs = arm_logs
    tr = default_arm().transmission.sub(WRIST)
    table = pq.read_table(folder / "train.parquet")
    _, datas = group_rows(table, [5, 6], "train")
    model, fit = fit_group(datas, tr)
    test = runs["test"]
    err = model.predict_group(test.qd[:, WRIST]) - _target(test)[:, WRIST]
    rmse = np.sqrt(np.mean(err ** 2, axis=0))
    floor = default_arm().noise_floor()[WRIST]
    assert np.all(rmse <= 1.3 * floor), (rmse, floor)
    np.testing.assert_allclose(model.fc, [0.03, 0.025], rtol=0.02)
    assert set(fit["joints"]) == {"5", "6"}


def test_coupled_model_file_round_trip(tmp_path, arm_logs):
    folder, runs = arm_logs
    table = pq.read_table(folder / "train.parquet")
    _, datas = group_rows(table, [5, 6], "train")
    model, _ = fit_group(datas, default_arm().transmission.sub(WRIST))
    spec, arrays = models.to_parts(model)
    again = models.from_parts(spec, arrays)
    qd = runs["test"].qd[:, WRIST]
    np.testing.assert_array_equal(again.predict_group(qd), model.predict_group(qd))
    member = again.member(6)
    assert member.required_inputs() == {"t", "qd", "qd@5"}
    got, _ = member.predict({"t": runs["test"].t, "qd": qd[:, 1], "qd@5": qd[:, 0]})
    np.testing.assert_array_equal(got, model.predict_group(qd)[:, 1])


def test_identify_coupling_and_predict_beat_per_joint_lugre(tmp_path, arm_logs):
    folder, _ = arm_logs
    train, test = folder / "train.parquet", folder / "test.parquet"
    res = run("identify", train, "--coupling", "-o", tmp_path / "coupled", "-q")
    assert res.exit_code == 0, res.output
    assert sorted(p.name for p in (tmp_path / "coupled").iterdir()) == [
        "joint_1.npz", "joint_2.npz", "joint_3.npz", "joint_4.npz", "joints_5_6.npz"]
    res = run("identify", train, "--joint", 5, "-o", tmp_path / "l5.npz", "-q")
    assert res.exit_code == 0, res.output
    res = run("identify", train, "--joint", 6, "-o", tmp_path / "l6.npz", "-q")
    assert res.exit_code == 0, res.output
    floor = dict(zip((5, 6), default_arm().noise_floor()[WRIST]))

    def rmse(model, joint):
        out = tmp_path / f"pred_{model.name}_{joint}.parquet"
        res = run("predict", model, test, "--joint", joint, "-o", out, "-q")
        assert res.exit_code == 0, res.output
        t = pq.read_table(out)
        assert set(t.column("joint").to_pylist()) == {joint}
        e = t.column("tau_f_pred").to_numpy() - (t.column("tau_m").to_numpy() - t.column("tau_g").to_numpy()
                                                   - t.column("tau_dyn").to_numpy())
        return float(np.sqrt(np.mean(e ** 2)))

    for joint in (5, 6):
        coupled = rmse(tmp_path / "coupled", joint)
        lugre = rmse(tmp_path / f"l{joint}.npz", joint)
        assert coupled <= 1.3 * floor[joint]
        assert lugre > 2 * coupled, (joint, lugre, coupled)
    # the group's file alone on the whole arm covers its two joints
    res = run("predict", tmp_path / "coupled" / "joints_5_6.npz", test, "-o", tmp_path / "p56.parquet", "-q")
    assert res.exit_code == 0, res.output
    assert set(pq.read_table(tmp_path / "p56.parquet").column("joint").to_pylist()) == {5, 6}


def test_group_model_refuses_other_joints_and_missing_partners(tmp_path, arm_logs):
    folder, _ = arm_logs
    train = folder / "train.parquet"
    model = tmp_path / "g.npz"
    assert run("identify", train, "--coupling", "--joint", 5, "-o", model, "-q").exit_code == 0
    res = run("predict", model, train, "--joint", 3, "-o", tmp_path / "p.parquet")
    assert res.exit_code == 4 and "fitted on joints 5, 6, not on joint 3" in res.output
    only5 = pq.read_table(train).filter(pq.read_table(train).column("joint").to_numpy() == 5)
    logs.write_table(only5, str(tmp_path / "only5.parquet"))
    res = run("predict", model, tmp_path / "only5.parquet", "-o", tmp_path / "p.parquet")
    assert res.exit_code == 3 and "depends on joint 6" in res.output
    assert not (tmp_path / "p.parquet").exists()


def test_coupling_needs_a_transmission(tmp_path, arm_logs):
    folder, _ = arm_logs
    table = pq.read_table(folder / "train.parquet")
    logs.write_table(table.replace_schema_metadata({}), str(tmp_path / "bare.parquet"))
    res = run("identify", tmp_path / "bare.parquet", "--coupling", "-o", tmp_path / "m")
    assert res.exit_code == 3 and "records none" in res.output
    assert not (tmp_path / "m").exists()


def test_coupled_fit_refuses_a_motor_that_does_not_move():
    qd = np.zeros((100, 2))
    qd[:, 0] = np.linspace(-1, 1, 100)
    from fricli.core.errors import FitError
    with pytest.raises(FitError, match="motor 1"):
        CoupledModel.fit([5, 6], [[1.0, 0.0], [0.0, 1.0]], qd[:, ::-1], np.zeros((100, 2)))


# --------------------------------------------------------------------------- C export

GROUP_DRIVER = r"""#include <stdio.h>
#include <stdlib.h>
#include "HEADER"
/* driver IN OUT: rows of PREFIX_N_JOINTS joint velocities in, rows of PREFIX_N_JOINTS frictions out */
int main(int argc, char **argv) {
    const size_t k = PREFIX_N_JOINTS;
    double qd[PREFIX_N_JOINTS], tau[PREFIX_N_JOINTS];
    PREFIX_state s;
    FILE *in, *out;
    if (argc != 3 || !(in = fopen(argv[1], "rb")) || !(out = fopen(argv[2], "wb"))) return 2;
    PREFIX_init(&s);
    while (fread(qd, sizeof(double), k, in) == k) {
        PREFIX_step(&s, qd, tau);
        if (fwrite(tau, sizeof(double), k, out) != k) return 3;
    }
    fclose(in);
    return fclose(out) == 0 ? 0 : 4;
}
"""


def _build_group(header, prefix, exe, cxx):
    import subprocess

    import export_check as check
    src = f"{exe}.c"
    with open(src, "w") as fh:
        fh.write(GROUP_DRIVER.replace("HEADER", str(header)).replace("PREFIX", prefix))
    cmd = [check.compiler(cxx), *(check.CXX_FLAGS if cxx else check.C_FLAGS), src, "-o", str(exe), "-lm"]
    proc = subprocess.run(cmd, capture_output=True, text=True)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr


@pytest.mark.parametrize("cxx", [False, True], ids=["c99", "c++"])
def test_exported_group_matches_predict_double(cxx, tmp_path, arm_logs):
    import export_check as check
    if check.compiler(cxx) is None:
        pytest.skip("no compiler")
    folder, _ = arm_logs
    test = folder / "test.parquet"
    assert run("identify", folder / "train.parquet", "--coupling", "-o", tmp_path / "arm", "-q").exit_code == 0
    header = tmp_path / "arm.h"
    res = run("export", tmp_path / "arm", "--prefix", "arm", "-o", header, "-q")
    assert res.exit_code == 0, res.output
    text = header.read_text()
    assert "arm_joints_5_6_step(arm_joints_5_6_state *s, const double *qd, double *tau_f)" in text
    assert "arm_joint_4_step(" in text
    check_group_export(header, "arm_joints_5_6", tmp_path / "arm", test, tmp_path, cxx)


def check_group_export(header, prefix, model, log, tmp_path, cxx):
    """The group step function ``prefix`` of ``header``, compiled and run on the joint velocities of
    joints 5 and 6 of ``log``, against ``fricli predict MODEL LOG --precision double`` to 1e-9."""
    import subprocess

    _build_group(header, prefix, tmp_path / "drv", cxx)
    res = run("predict", model, log, "--precision", "double", "-o", tmp_path / "p.parquet", "-q")
    assert res.exit_code == 0, res.output
    pred = pq.read_table(tmp_path / "p.parquet")
    joint = pred.column("joint").to_numpy()
    qd = np.column_stack([pred.column("qd").to_numpy()[joint == j] for j in (5, 6)])
    ref = np.column_stack([pred.column("tau_f_pred").to_numpy()[joint == j] for j in (5, 6)])
    qd.tofile(tmp_path / "in.bin")
    subprocess.run([str(tmp_path / "drv"), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")], check=True)
    got = np.fromfile(tmp_path / "out.bin").reshape(-1, 2)
    assert got.shape == ref.shape
    assert np.max(np.abs(got - ref) / (1e-12 + np.abs(ref))) <= 1e-9


# --------------------------------------------------------------------------- diagnose


def test_diagnose_names_the_coupling_that_per_joint_models_miss(tmp_path, arm_logs):
    import json

    folder, _ = arm_logs
    train = folder / "train.parquet"
    for joint in (4, 5, 6):
        res = run("identify", train, "--joint", joint, "-o", tmp_path / f"l{joint}.npz", "-q")
        assert res.exit_code == 0, res.output
    found = {}
    for joint in (4, 5, 6):
        res = run("diagnose", tmp_path / f"l{joint}.npz", train, "--json")
        assert res.exit_code == 0, res.output
        found[joint] = json.loads(res.output)
    for joint in (5, 6):
        assert found[joint]["added"][:1] == ["coupling"], found[joint]["added"]
    assert "coupling" not in [e["name"] for e in found[4]["effects"]]     # joint 4 shares no motor
    # joint 6 = 40 f6(30 qd5 + 40 qd6): the Coulomb level of motor 6 seen at joint 6 is 40 x 0.025 Nm
    params = next(e for e in found[6]["effects"] if e["name"] == "coupling")["params"]
    assert params["Fc motor 6"]["value"] == pytest.approx(1.0, rel=0.05)


# --------------------------------------------------------------------------- import, motor side


def _wrist_mapping(tr, *, files=("positions", "torques"), rate=2000.0, torque_scale=-1e-3) -> str:
    lines = [f"files = {list(files)!r}".replace("'", '"'), f"time = {{rate = {rate!r}}}", "", "[transmission]",
             f"ratio = {tr.ratio.tolist()!r}", f"offset = {tr.offset.tolist()!r}", ""]
    for k, joint in enumerate(tr.joints):
        lines += ["[[joints]]", f"name = {joint}", f'theta = {{file = "{files[0]}", column = {k + 1}}}',
                  f'tau_motor = {{file = "{files[1]}", column = {k + 1}, unit = "Nm", scale = {torque_scale!r}}}', ""]
    return "\n".join(lines)


@pytest.fixture(scope="module")
def motor_recording(tmp_path_factory):
    """The simulated arm's motor-side recording: two files without time, torques in mNm, negated."""
    from fricli.sim.coupled import write_recording

    folder = tmp_path_factory.mktemp("motor")
    r = simulate_coupled(duration=3.0, rate_hz=2000.0, rng=np.random.default_rng(5))
    write_recording(r, str(folder / "pos.csv"), str(folder / "tor.csv"), torque_scale=-1e-3)
    (folder / "wrist.toml").write_text(_wrist_mapping(default_arm().transmission))
    return folder, r


def _per_joint(table, column, joints):
    j = table.column("joint").to_numpy()
    return np.column_stack([table.column(column).to_numpy()[j == x] for x in joints])


def test_motor_side_recording_in_two_files_gives_joint_positions_and_torques(tmp_path, motor_recording):
    folder, r = motor_recording
    out = tmp_path / "arm.parquet"
    res = run("import", folder / "pos.csv", folder / "tor.csv", "--mapping", folder / "wrist.toml", "-o", out)
    assert res.exit_code == 0, res.output
    table = pq.read_table(out)
    joints = default_arm().transmission.joints
    for column, truth in (("q", r.q), ("tau_m", r.tau_m)):
        got = _per_joint(table, column, joints)
        assert np.max(np.abs(got - truth) / np.max(np.abs(truth), axis=0)) <= 1e-9
    np.testing.assert_array_equal(_per_joint(table, "t", joints)[:, 0], r.t)
    recorded, arm = of_schema(table.schema.metadata), default_arm().transmission
    np.testing.assert_array_equal(recorded.ratio, arm.ratio)
    np.testing.assert_array_equal(recorded.offset, arm.offset)


def test_diagonal_transmission_is_the_same_as_joint_side_scales(tmp_path, motor_recording):
    """A diagonal R on motor-side columns gives the log, byte for byte, of the mapping without a
    transmission whose columns carry scale = 1/r, offset = -theta0/r (positions) and scale = r
    (torques); and identify makes the same model file of both."""
    from fricli.sim.coupled import write_recording

    _, r = motor_recording
    folder = tmp_path
    write_recording(r, str(folder / "pos.csv"), str(folder / "tor.csv"))     # motor torques in Nm
    tr = Transmission.diagonal([1, 2, 3, 4, 5, 6], [-120.0, 100.0, -80.0, 60.0, -50.0, 40.0],
                               offset=[0.3, -1.0, 2.0, 0.0, 0.5, -0.7])
    (tmp_path / "motor.toml").write_text(_wrist_mapping(tr, torque_scale=1.0).replace(
        f"ratio = {tr.ratio.tolist()!r}", f"gear_ratios = {np.diag(tr.ratio).tolist()!r}"))
    lines = ['files = ["positions", "torques"]', "time = {rate = 2000.0}", ""]
    for k, (joint, r, off) in enumerate(zip(tr.joints, np.diag(tr.ratio), tr.offset)):
        offset = f", offset = {float(-off / r)!r}" if off else ""
        lines += ["[[joints]]", f"name = {joint}",
                  f'q = {{file = "positions", column = {k + 1}, scale = {float(1 / r)!r}{offset}}}',
                  f'tau_m = {{file = "torques", column = {k + 1}, scale = {float(r)!r}}}', ""]
    (tmp_path / "joint.toml").write_text("\n".join(lines))
    outs = []
    for side in ("motor", "joint"):
        (tmp_path / side).mkdir()
        out = tmp_path / side / "arm.parquet"
        res = run("import", folder / "pos.csv", folder / "tor.csv", "--mapping", tmp_path / f"{side}.toml", "-o", out)
        assert res.exit_code == 0, res.output
        res = run("identify", out, "--joint", 5, "--no-gravity", "--no-dynamics", "-o", tmp_path / side / "m5.npz",
                  "-q")
        assert res.exit_code == 0, res.output
        outs.append((out.read_bytes(), (tmp_path / side / "m5.npz").read_bytes()))
    assert outs[0] == outs[1]


def test_defects_of_either_file_drop_the_row_from_both(tmp_path, motor_recording):
    folder, _ = motor_recording
    pos = (folder / "pos.csv").read_text().splitlines()
    tor = (folder / "tor.csv").read_text().splitlines()
    pos[9] = "not,a,number,at,all,x"          # line 10 garbage in the positions
    tor = tor[:-3]                              # the torques end three rows early
    (tmp_path / "pos.csv").write_text("\n".join(pos) + "\n")
    (tmp_path / "tor.csv").write_text("\n".join(tor) + "\n")
    out = tmp_path / "arm.parquet"
    res = run("import", tmp_path / "pos.csv", tmp_path / "tor.csv", "--mapping", folder / "wrist.toml", "-o", out)
    assert res.exit_code == 0, res.output
    # each file's line numbers, named by the file
    assert f"dropped 1 row with non-numeric or non-finite value ({tmp_path / 'pos.csv'}: first at line 10)" in res.output
    assert (f"dropped 3 rows with no matching row in another of the recording's files ({tmp_path / 'pos.csv'}: lines "
            f"{len(pos) - 2}-{len(pos)})") in res.output
    table = pq.read_table(out)
    assert table.num_rows == 6 * (len(pos) - 4)
    t = _per_joint(table, "t", [5])[:, 0]
    assert 9 / 2000.0 not in t and 10 / 2000.0 in t    # the row's time stays its line's: a gap, no shift


@pytest.mark.parametrize("edit, message", [
    (lambda m: m.replace("[transmission]", "[unused]"), "unknown key 'unused'"),
    (lambda m: m.replace("theta = {", "q = {", 1), "positions and torques are motor-side"),
    (lambda m: m.replace('file = "torques"', 'file = "currents"', 1), "expected one of the mapping's files"),
    (lambda m: m.replace(", [0.0, 0.0, 0.0, 0.0, 30.0, 40.0]]", "]"), "expected 6 rows of 6 numbers"),
    (lambda m: m.replace("time = {rate = 2000.0}", "time = {rate = 0.0}"), "must be positive"),
    (lambda m: m.replace('files = ["positions", "torques"]', 'files = ["positions", "torques", "currents"]'),
     "no column is read from file 'currents'"),
    (lambda m: m.replace("[0.0, 0.0, 0.0, 0.0, 30.0, 40.0]", "[0.0, 0.0, 0.0, 0.0, -50.0, 0.0]"), "singular"),
])
def test_mapping_mistakes_are_one_line(edit, message, tmp_path, motor_recording):
    folder, _ = motor_recording
    (tmp_path / "bad.toml").write_text(edit((folder / "wrist.toml").read_text()))
    res = run("import", folder / "pos.csv", folder / "tor.csv", "--mapping", tmp_path / "bad.toml", "-o",
              tmp_path / "x.parquet")
    assert res.exit_code == 3 and message in res.output, res.output
    assert len(res.output.strip().splitlines()) == 1 and not (tmp_path / "x.parquet").exists()


def test_two_files_need_files_in_the_mapping(tmp_path, motor_recording):
    folder, _ = motor_recording
    res = run("import", folder / "pos.csv", "--mapping", folder / "wrist.toml", "-o", tmp_path / "x.parquet")
    assert res.exit_code == 3 and "names 2 files (positions, torques), but 1 recordings were given" in res.output


def test_files_joined_by_time(tmp_path, motor_recording):
    """join = "time": each file has the time column (ms here); rows pair up by equal time."""
    _, r = motor_recording
    t_ms = np.round(r.t * 1000.0, 6)
    pos = np.column_stack([t_ms, r.theta])
    tor = np.column_stack([t_ms, r.tau_motor])
    np.savetxt(tmp_path / "pos.csv", np.delete(pos, 100, axis=0), delimiter=",", fmt="%.17g")   # a sample missing
    np.savetxt(tmp_path / "tor.csv", tor, delimiter=",", fmt="%.17g")
    tr = default_arm().transmission
    text = _wrist_mapping(tr, torque_scale=1.0)
    for k in range(6, 0, -1):    # the signals one column to the right
        text = text.replace(f"column = {k}}}", f"column = {k + 1}}}").replace(f"column = {k}, unit", f"column = {k + 1}, unit")
    text = text.replace("time = {rate = 2000.0}", 'join = "time"\ntime = {column = 1, unit = "ms"}')
    (tmp_path / "map.toml").write_text(text)
    res = run("import", tmp_path / "pos.csv", tmp_path / "tor.csv", "--mapping", tmp_path / "map.toml", "-o",
              tmp_path / "arm.parquet")
    assert res.exit_code == 0, res.output
    assert (f"dropped 1 row with no matching row in another of the recording's files ({tmp_path / 'tor.csv'}: "
            "line 101)") in res.output
    table = pq.read_table(tmp_path / "arm.parquet")
    keep = np.arange(len(r.t)) != 100
    got = _per_joint(table, "tau_m", tr.joints)
    np.testing.assert_allclose(got, r.tau_m[keep], rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(_per_joint(table, "t", [1])[:, 0], t_ms[keep] * 1e-3)


def test_motor_rotor_inertias_reach_the_dynamics_with_their_cross_term(tmp_path, rng):
    """With --urdf, motor-side rotor inertias J_m become the armature diag(R^T J_m R) and the
    off-diagonal part of R^T J_m R is added to tau_dyn as a torque in qdd."""
    pytest.importorskip("pinocchio")
    from test_urdf import URDF, motion

    n = 400
    q, qd, _ = motion(rng, n)
    t = np.arange(n) * 0.01
    tr = Transmission(["a", "b"], [[10.0, 0.0], [4.0, 5.0]], rotor_inertia=[0.01, 0.02])
    tau = rng.normal(size=(n, 2))
    np.savetxt(tmp_path / "motor.csv", np.column_stack([t, tr.motor_positions(q), tr.motor_torques(tau)]),
               delimiter=",", fmt="%.17g")
    np.savetxt(tmp_path / "joint.csv", np.column_stack([t, q, tau]), delimiter=",", fmt="%.17g")
    (tmp_path / "two_link.urdf").write_text(URDF)
    head = 'time = 1\n[robot]\nmatch = "order"\ngravity = [0.0, -9.81, 0.0]\n'
    motor = head + "[transmission]\nratio = [[10.0, 0.0], [4.0, 5.0]]\nrotor_inertia = [0.01, 0.02]\n"
    joint = head
    for k, (name, armature) in enumerate(zip("ab", tr.armature())):
        motor += f'[[joints]]\nname = "{name}"\ntheta = {2 + k}\ntau_motor = {4 + k}\n'
        joint += f'[[joints]]\nname = "{name}"\nq = {2 + k}\ntau_m = {4 + k}\nrotor_inertia = {float(armature)!r}\n'
    (tmp_path / "motor.toml").write_text(motor)
    (tmp_path / "joint.toml").write_text(joint)
    tables = {}
    for side in ("motor", "joint"):
        res = run("import", tmp_path / f"{side}.csv", "--mapping", tmp_path / f"{side}.toml", "--urdf",
                  tmp_path / "two_link.urdf", "-o", tmp_path / f"{side}.parquet")
        assert res.exit_code == 0, res.output
        tables[side] = pq.read_table(tmp_path / f"{side}.parquet")
    qdd = _per_joint(tables["motor"], "qdd", "ab")
    extra = _per_joint(tables["motor"], "tau_dyn", "ab") - _per_joint(tables["joint"], "tau_dyn", "ab")
    cross = tr.cross_inertia()
    assert cross[0, 1] == pytest.approx(0.02 * 4 * 5)
    np.testing.assert_allclose(extra, qdd @ cross.T, rtol=1e-6, atol=1e-9 * np.abs(qdd @ cross.T).max())
    np.testing.assert_allclose(_per_joint(tables["motor"], "tau_m", "ab"), tau, rtol=1e-12, atol=1e-12)


def test_estimate_ext_with_a_group_model(tmp_path, arm_logs):
    folder, runs = arm_logs
    test = folder / "test.parquet"
    model = tmp_path / "wrist.npz"
    assert run("identify", folder / "train.parquet", "--coupling", "--joint", 6, "-o", model, "-q").exit_code == 0
    res = run("estimate-ext", model, test, "-o", tmp_path / "ext.parquet", "-q")
    assert res.exit_code == 0, res.output
    table = pq.read_table(tmp_path / "ext.parquet")
    # no external torque in the simulation: the estimate is the friction error, at the noise floor
    ext = _per_joint(table, "tau_ext_pred", [5, 6])
    assert np.all(np.sqrt(np.mean(ext ** 2, axis=0)) <= 1.3 * default_arm().noise_floor()[WRIST])


def test_a_log_of_the_wrist_alone_gives_one_model_file(tmp_path, arm_logs):
    folder, _ = arm_logs
    table = pq.read_table(folder / "train.parquet")
    wrist = table.filter(np.isin(table.column("joint").to_numpy(), [5, 6]))
    logs.write_table(wrist, str(tmp_path / "wrist.parquet"))
    res = run("identify", tmp_path / "wrist.parquet", "--coupling", "-o", tmp_path / "wrist.npz", "--json")
    assert res.exit_code == 0, res.output
    assert models.load(str(tmp_path / "wrist.npz"))[1]["joints"] == [5, 6]
    res = run("identify", folder / "train.parquet", "--coupling", "-o", tmp_path / "arm.npz")
    assert res.exit_code == 3 and "give -o a folder" in res.output


# --------------------------------------------------------------------------- Stribeck curve per motor


@pytest.fixture(scope="module")
def stribeck_logs(tmp_path_factory):
    folder = tmp_path_factory.mktemp("stribeck")
    arm = default_arm(stribeck=True)
    runs = {}
    for name, seed in (("train", 11), ("test", 12)):
        runs[name] = simulate_coupled(arm, duration=20.0, rate_hz=1000.0, rng=np.random.default_rng(seed))
        logs.write_table(runs[name].table, str(folder / f"{name}.parquet"))
    return folder, runs


def test_motor_stribeck_curve_reaches_the_noise_floor_where_the_linear_motor_model_cannot(stribeck_logs):
    _, runs = stribeck_logs
    tr = default_arm().transmission.sub(WRIST)
    floor = default_arm().noise_floor()[WRIST]
    ratio = {}
    for stribeck in (False, True):
        model, _ = CoupledModel.fit(tr.joints, tr.ratio, runs["train"].qd[:, WRIST], _target(runs["train"])[:, WRIST],
                                    stribeck=stribeck)
        err = model.predict_group(runs["test"].qd[:, WRIST]) - _target(runs["test"])[:, WRIST]
        ratio[stribeck] = np.sqrt(np.mean(err ** 2, axis=0)) / floor
    assert np.all(ratio[True] <= 1.3) and np.all(ratio[False] > 1.3), ratio
    np.testing.assert_allclose(model.fs, [0.042, 0.035], rtol=0.05)
    np.testing.assert_allclose(model.vs, [5.0, 5.0], rtol=0.15)


def test_exported_stribeck_group_matches_predict_double(tmp_path, stribeck_logs):
    import subprocess

    import export_check as check
    if check.compiler() is None:
        pytest.skip("no compiler")
    folder, _ = stribeck_logs
    model = tmp_path / "wrist.npz"
    res = run("identify", folder / "train.parquet", "--coupling", "--motor-stribeck", "--joint", 5, "-o", model, "-q")
    assert res.exit_code == 0, res.output
    assert models.load(str(model))[0].stribeck
    assert run("export", model, "--prefix", "wr", "-o", tmp_path / "wr.h", "-q").exit_code == 0
    _build_group(tmp_path / "wr.h", "wr", tmp_path / "drv", False)
    assert run("predict", model, folder / "test.parquet", "--precision", "double", "-o", tmp_path / "p.parquet",
               "-q").exit_code == 0
    pred = pq.read_table(tmp_path / "p.parquet")
    _per_joint(pred, "qd", WRIST_NAMES).tofile(tmp_path / "in.bin")
    subprocess.run([str(tmp_path / "drv"), str(tmp_path / "in.bin"), str(tmp_path / "out.bin")], check=True)
    ref = _per_joint(pred, "tau_f_pred", WRIST_NAMES)
    got = np.fromfile(tmp_path / "out.bin").reshape(ref.shape)
    assert np.max(np.abs(got - ref) / (1e-12 + np.abs(ref))) <= 1e-9
    res = run("identify", folder / "train.parquet", "--motor-stribeck", "-o", tmp_path / "x")
    assert res.exit_code == 2 and "--motor-stribeck applies to --coupling" in res.output


WRIST_NAMES = [5, 6]
