"""fricli calibrate: a four-joint arm simulated through Pinocchio (RNEA with armature, linear friction)
from a model whose masses and centres of mass differ from the URDF's CAD values by up to 20 %."""

import json
import subprocess
import sys

import numpy as np
import pyarrow.parquet as pq
import pytest

from conftest import run_in
from fricli.core import errors, logs
from fricli.core.errors import DataError

pin = pytest.importorskip("pinocchio")

from fricli.robot import calibration as cb  # noqa: E402
from fricli.robot.dynamics import RobotModel, link_inertials  # noqa: E402

# a four-joint serial arm: a vertical base axis, two pitch joints, a wrist roll; one link with a
# rotated inertial frame, a massive fixed flange merged into the last body
URDF = """<?xml version="1.0"?>
<robot name="four">
  <link name="base"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0 0 0.2"/><axis xyz="0 0 1"/><limit lower="-6" upper="6" effort="100" velocity="5"/></joint>
  <link name="l1"><inertial><origin xyz="0.01 0.02 0.05"/><mass value="4.0"/>
    <inertia ixx="0.03" ixy="0.001" ixz="0" iyy="0.025" iyz="0" izz="0.02"/></inertial></link>
  <joint name="j2" type="revolute"><parent link="l1"/><child link="l2"/>
    <origin xyz="0 0.1 0.1" rpy="0 1.5707963 0"/><axis xyz="0 1 0"/><limit lower="-6" upper="6" effort="100" velocity="5"/></joint>
  <link name="l2"><inertial><origin xyz="0.25 0 0.02" rpy="0.3 0 0.2"/><mass value="6.0"/>
    <inertia ixx="0.02" ixy="0" ixz="0.002" iyy="0.15" iyz="0" izz="0.14"/></inertial></link>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.5 0 0"/><axis xyz="0 1 0"/><limit lower="-6" upper="6" effort="100" velocity="5"/></joint>
  <link name="l3"><inertial><origin xyz="0.2 0.01 0"/><mass value="2.5"/>
    <inertia ixx="0.008" ixy="0" ixz="0" iyy="0.05" iyz="0.001" izz="0.05"/></inertial></link>
  <joint name="j4" type="continuous"><parent link="l3"/><child link="l4"/>
    <origin xyz="0.4 0 0"/><axis xyz="1 0 0"/></joint>
  <link name="l4"><inertial><origin xyz="0.03 0.02 0.01"/><mass value="0.8"/>
    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.0025"/></inertial></link>
  <joint name="flange_joint" type="fixed"><parent link="l4"/><child link="flange"/>
    <origin xyz="0.08 0 0" rpy="0 0 1.5707963"/></joint>
  <link name="flange"><inertial><origin xyz="0.01 0 0"/><mass value="0.3"/>
    <inertia ixx="0.0004" ixy="0" ixz="0" iyy="0.0004" iyz="0" izz="0.0004"/></inertial></link>
</robot>
"""
JOINTS = ("j1", "j2", "j3", "j4")
ARMATURE = np.array([0.9, 1.6, 0.45, 0.05])              # kg m^2
FRICTION = np.array([[8.0, 5.0, 0.3], [12.0, 7.0, -0.5], [5.0, 2.5, 0.2], [1.0, 0.6, 0.02]])  # Fv, Fc, offset
RATE = 100.0


def true_model(rng, scale=0.2):
    """The CAD model with each body's mass and centre of mass changed by up to ``scale`` (its
    inertia at the centre of mass kept), plus armature: (pinocchio model, parameter vector)."""
    model = pin.buildModelFromXML(URDF)
    for i in range(1, model.njoints):
        old = model.inertias[i]
        mass = old.mass * (1 + rng.uniform(-scale, scale))
        com = old.lever * (1 + rng.uniform(-scale, scale, 3)) + rng.uniform(-0.02, 0.02, 3)
        model.inertias[i] = pin.Inertia(mass, com, old.inertia)
    model.armature = ARMATURE.copy()
    x = np.concatenate([cb.cad_parameters(_Robot(model)), ARMATURE, FRICTION.reshape(-1)])
    return model, x


class _Robot:
    def __init__(self, model):
        self.pin_model = model


def harmonics(rng, n, freqs, amp):
    """q, qd, qdd (n, 4) as sums of harmonics of the given base frequencies [Hz]."""
    t = np.arange(n) / RATE
    q, qd, qdd = (np.zeros((n, 4)) for _ in range(3))
    for j in range(4):
        for f in freqs:
            w, a, ph = 2 * np.pi * f * rng.uniform(0.8, 1.2), amp * rng.uniform(0.3, 1.0) / max(f, 0.05), rng.uniform(0, 6.3)
            q[:, j] += a * np.sin(w * t + ph)
            qd[:, j] += a * w * np.cos(w * t + ph)
            qdd[:, j] -= a * w * w * np.sin(w * t + ph)
    return t, q, qd, qdd


def simulate(model, t, q, qd, qdd, rng=None, noise=0.0):
    """tau_m (n, 4): RNEA of ``model`` (armature included) plus the linear friction."""
    robot = RobotModel(URDF, "cad")
    data = model.createData()
    config = robot.configuration(q)
    tau = np.array([pin.rnea(model, data, config[k], qd[k], qdd[k]) for k in range(len(t))])
    tau += FRICTION[:, 0] * qd + FRICTION[:, 1] * np.sign(qd) + FRICTION[:, 2]
    if noise:
        tau += rng.normal(0.0, noise, tau.shape)
    return tau


def write_log(path, t, q, qd, qdd, tau):
    n = len(t)
    columns = {"t": np.tile(t, 4), "joint": np.repeat(np.arange(1, 5), n),
               **{c: v.T.reshape(-1) for c, v in (("q", q), ("qd", qd), ("qdd", qdd), ("tau_m", tau))}}
    table = logs.table_from_arrays(columns, {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", "tau_m": "Nm"})
    logs.write_table(table, str(path))
    return str(path)


def motion(t, q, qd, qdd, tau):
    return cb.Motion(t=t, q=q, qd=qd, qdd=qdd, tau=tau, names=[1, 2, 3, 4], rotor_inertia=np.full(4, np.nan))


def fricli(*args, cwd):
    return run_in(cwd, *args)


@pytest.fixture(scope="module")
def arm():
    rng = np.random.default_rng(7)
    model, x_true = true_model(rng)
    fit = harmonics(rng, 1500, (0.2, 0.45, 0.7, 1.1), 0.25)
    held = harmonics(rng, 800, (0.3, 0.6, 0.9), 0.3)
    return model, x_true, fit, held


def test_calibration_recovers_the_true_model(arm, tmp_path):
    model, x_true, fit, held = arm
    robot = RobotModel(URDF, "cad")
    cal = cb.calibrate(robot, motion(*fit, simulate(model, *fit)))
    base, names = cb.base_parameters(robot, cal.x)
    base_true, _ = cb.base_parameters(robot, x_true)
    assert len(base) == cal.report["excitation"]["base_parameters"] < len(x_true)
    np.testing.assert_allclose(base, base_true, rtol=1e-6, atol=1e-6 * np.abs(base_true).max())
    # what the data cannot separate is split towards CAD; a body that split leaves inconsistent is
    # fitted again over consistent parameters, with the same base parameters (checked above)
    assert cal.report["consistency"]["ok"]
    assert not cal.report["excitation"]["undetermined"]
    # the CAD model was off: the calibration must have changed something the data determine
    assert max(f["rms_before"] for f in cal.report["fit"].values()) > 1e3 * max(f["rms_after"] for f in cal.report["fit"].values())

    # the written URDF, loaded by fricli (armature from rotor_params) and friction from the report,
    # predicts a held-out trajectory
    text = cb.calibrated_urdf(URDF, "cad", cal)
    path = tmp_path / "cal.urdf"
    path.write_text(text)
    calibrated = RobotModel(text, "cal")
    # each armature is identifiable only together with link inertias about the same axis
    np.testing.assert_allclose(calibrated.armature, cal.x[40:44])
    t, q, qd, qdd = held
    tau_g, tau_dyn = calibrated.terms(q, qd, qdd, rotor_inertia=np.full(4, 100.0))   # the URDF's armature wins
    fr = cal.report["friction"]["joints"]
    friction = np.column_stack([fr[j]["Fv"] * qd[:, k] + fr[j]["Fc"] * np.sign(qd[:, k]) + fr[j]["offset"]
                                for k, j in enumerate(["1", "2", "3", "4"])])
    truth = simulate(model, *held)
    assert np.linalg.norm(tau_g + tau_dyn + friction - truth) < 1e-6 * np.linalg.norm(truth)
    # Pinocchio reads the file as a URDF, and its rotor_params as Pinocchio's SRDF element does
    loaded = pin.buildModelFromUrdf(str(path))
    assert loaded.nv == 4
    srdf = tmp_path / "cal.srdf"
    srdf.write_text(text)
    pin.loadRotorParameters(loaded, str(srdf), False)
    np.testing.assert_allclose(loaded.armature, calibrated.armature)


def test_a_urdf_link_without_mass_is_calibrated(arm):
    """A moving link whose CAD has no <inertial> (mass 0, as URDFs leave frame links): its body has
    no centre of mass, which the consistency check divided by (LinAlgError, an internal error)."""
    import re

    model, x_true, fit, held = arm
    massless = re.sub(r'(<link name="l3">)<inertial>.*?</inertial>', r"\1", URDF, flags=re.S)
    assert "<mass value=\"2.5\"/>" not in massless
    robot = RobotModel(massless, "cad without l3's mass")
    cal = cb.calibrate(robot, motion(*fit, simulate(model, *fit)))
    assert cal.report["consistency"]["ok"]
    calibrated = RobotModel(cb.calibrated_urdf(massless, "cad", cal), "cal")
    t, q, qd, qdd = held
    tau_g, tau_dyn = calibrated.terms(q, qd, qdd)
    fr = cal.report["friction"]["joints"]
    friction = np.column_stack([fr[j]["Fv"] * qd[:, k] + fr[j]["Fc"] * np.sign(qd[:, k]) + fr[j]["offset"]
                                for k, j in enumerate(["1", "2", "3", "4"])])
    truth = simulate(model, *held)
    assert np.linalg.norm(tau_g + tau_dyn + friction - truth) < 1e-6 * np.linalg.norm(truth)


def test_an_unknown_rotor_inertia_behind_a_light_link_is_found():
    """A geared wrist: the rotor reflects 0.4 kg m^2 behind a 0.2 kg link of 1e-4 kg m^2 (a UR10e's
    last joint: 0.44 behind 2e-4), no rotor inertia given. The prior's scale of an armature must not
    come from the link alone: it held this one 13 % low and left the joint's error above the noise."""
    light = (URDF.replace('<mass value="0.8"/>\n    <inertia ixx="0.002" ixy="0" ixz="0" iyy="0.003" iyz="0" izz="0.0025"/>',
                          '<mass value="0.2"/>\n    <inertia ixx="0.0001" ixy="0" ixz="0" iyy="0.00015" iyz="0" izz="0.00015"/>')
             .replace('<origin xyz="0.01 0 0"/><mass value="0.3"/>', '<origin xyz="0.01 0 0"/><mass value="0.01"/>'))
    assert light.count("0.00015") == 2 and 'mass value="0.01"' in light
    rng = np.random.default_rng(7)
    model = pin.buildModelFromXML(light)
    model.armature = np.array([0.9, 1.6, 0.45, 0.4])
    fit = harmonics(rng, 1500, (0.2, 0.45, 0.7, 1.1), 0.25)
    robot = RobotModel(light, "cad")
    data = model.createData()
    tau = np.array([pin.rnea(model, data, robot.configuration(fit[1])[k], fit[2][k], fit[3][k]) for k in range(1500)])
    tau += FRICTION[:, 0] * fit[2] + FRICTION[:, 1] * np.sign(fit[2]) + FRICTION[:, 2] + rng.normal(0.0, 0.3, tau.shape)
    cal = cb.calibrate(robot, motion(*fit, tau))
    assert abs(cal.armature()[3] - 0.4) < 0.01
    assert cal.report["fit"]["4"]["rms_after"] < 1.03 * 0.3


def test_rows_at_rest_do_not_bias_the_calibration(arm):
    """A joint at rest holds whatever torque its last motion left, up to the breakaway level: no
    Fc sign(qd) says what. Here each joint stands still for 2 s in turn, its motor holding 0.8 Fc
    set by the direction of its last motion, while the others move; the calibration fits each
    joint's rows in motion and recovers the model as from a log without rest."""
    model, x_true, fit, _ = arm
    t, q, qd, qdd = (a.copy() for a in fit)
    rest = np.zeros(q.shape, dtype=bool)
    for j in range(4):
        a = 150 + 300 * j
        rest[a:a + 200, j] = True
        q[a:a + 200, j], qd[a:a + 200, j], qdd[a:a + 200, j] = q[a - 1, j], 0.0, 0.0
    tau = simulate(model, t, q, qd, qdd)
    last = np.array([np.sign(fit[2][150 + 300 * j - 1, j]) for j in range(4)])
    tau += np.where(rest, -0.8 * FRICTION[:, 1] * last, 0.0)
    robot = RobotModel(URDF, "cad")
    cal = cb.calibrate(robot, motion(t, q, qd, qdd, tau))
    base, _ = cb.base_parameters(robot, cal.x)
    base_true, _ = cb.base_parameters(robot, x_true)
    np.testing.assert_allclose(base, base_true, rtol=1e-6, atol=1e-6 * np.abs(base_true).max())
    np.testing.assert_allclose(cal.x[44:], FRICTION.reshape(-1), rtol=1e-6, atol=1e-9)
    assert cal.report["rows"] == int(cb.edge_rows(t, cb.DEFAULT_EDGE_S).sum())


def test_a_mass_the_torques_cannot_tell_apart_is_flagged_as_the_priors(arm):
    """A serial arm's joint torques see some masses only together with other parameters: moved with
    them, the mass changes and no torque does. The report names such masses and a flagged change
    says the prior chose it."""
    model, _, fit, _ = arm
    robot = RobotModel(URDF, "cad")
    cal = cb.calibrate(robot, motion(*fit, simulate(model, *fit)))
    tied = cal.report["excitation"]["masses_not_determined_alone"]
    assert tied and set(tied) <= {f"{b}.m" for b in cal.bodies}
    name = next(k for k, v in tied.items() if v)
    c = cal.names.index(name)
    Y = cb._random_regressor(robot, seed=5)          # other random states than the report's
    _, sv, vt = np.linalg.svd(Y, full_matrices=False)
    null = vt[int(np.sum(sv > 1e-9 * sv[0])):].T
    v = null @ null[c]                               # the unseen direction along which the mass moves most
    assert abs(v[c]) > 1e-6
    x = cal.x + v * (0.5 * cal.x0[c] / v[c])        # that mass +50 % of CAD, every torque unchanged
    assert np.abs(Y @ (x - cal.x)).max() < 1e-9 * np.abs(Y @ cal.x).max()
    moved = cb.Calibration(x=x, x0=cal.x0, names=cal.names, bodies=cal.bodies, joints=cal.joints, report={})
    line = next(w for w in cb.suspicious(moved, tied) if w.startswith(f"link {name[:-2]}: mass"))
    assert "no joint torque determines this mass alone: it trades with " + tied[name][0] in line


def test_a_moved_armature_names_a_stribeck_bump_only_beside_linear_friction(arm):
    """Friction rising towards rest peaks at reversals, where the acceleration does: a linear friction
    model leaves it to the armature, and the flagged change says so and names the remedy."""
    model, _, fit, _ = arm
    cal = cb.calibrate(RobotModel(URDF, "cad"), motion(*fit, simulate(model, *fit)))
    nj = len(cal.joints)
    x0 = cal.x0.copy()
    x0[10 * nj + 1] = 0.01                                       # joint j2's prior armature [kg m^2]
    for x in (cal.x, np.concatenate([cal.x, np.zeros(nj)])):     # linear friction, then with Fs - Fc (stribeck)
        x = x.copy()
        x[10 * nj + 1] = 0.03                                    # +200 %
        moved = cb.Calibration(x=x, x0=x0, names=cal.names, bodies=cal.bodies, joints=cal.joints, report={})
        line = next(w for w in cb.suspicious(moved) if w.startswith("joint j2: armature"))
        assert line.endswith("(--friction stribeck fits it)") == (len(x) == 14 * nj), line


def test_the_excitation_report_does_not_depend_on_the_prior(arm):
    """The condition number is the run's: of its regressor over the structural base parameters
    (those of ``base_parameters``), whatever prior the fit then uses."""
    model, _, fit, _ = arm
    robot = RobotModel(URDF, "cad")
    m = motion(*fit, simulate(model, *fit))
    reports = [cb.calibrate(robot, m, prior=p).report["excitation"] for p in (0.01, 10.0)]
    assert set(reports[0]["base"]) == set(cb.base_parameters(robot, np.zeros(56))[1])
    assert reports[0]["base"] == reports[1]["base"]
    assert reports[0]["condition_number"] == pytest.approx(reports[1]["condition_number"], rel=1e-12)


def test_cli_writes_urdf_and_report_that_dynamics_uses(arm, tmp_path):
    model, x_true, fit, held = arm
    log = write_log(tmp_path / "fit.parquet", *fit, simulate(model, *fit))
    cad = tmp_path / "cad.urdf"
    cad.write_text(URDF)
    res = fricli("calibrate", log, "--urdf", str(cad), "--match", "order", "-o", "cal.urdf", "--json", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "base parameters" in res.stderr and "calibrated 4 joints" in res.stderr
    report = json.loads((tmp_path / "cal.calibration.json").read_text())
    assert json.loads(res.stdout)["fit"] == report["fit"]
    tied = report["excitation"]["masses_not_determined_alone"]
    assert tied and (f"excitation: the masses of {', '.join(m.removesuffix('.m') for m in tied)} are not determined "
                     "alone") in res.stderr
    np.testing.assert_allclose([report["friction"]["joints"][j]["Fv"] for j in "1234"], FRICTION[:, 0], rtol=1e-6)

    held_log = write_log(tmp_path / "held.parquet", *held, simulate(model, *held))
    res = fricli("dynamics", held_log, "--urdf", "cal.urdf", "--match", "order", "-o", "terms.parquet", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    t, q, qd, qdd = held
    truth = simulate(model, *held) - (FRICTION[:, 0] * qd + FRICTION[:, 1] * np.sign(qd) + FRICTION[:, 2])
    terms = logs.read_table(str(tmp_path / "terms.parquet"))[0]
    got = (logs.float64_values(terms.column("tau_g")) + logs.float64_values(terms.column("tau_dyn"))).reshape(4, -1).T
    assert np.linalg.norm(got - truth) < 1e-6 * np.linalg.norm(truth)
    # the log names its URDF as given (cal.urdf) and by absolute path: usable from another folder
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    res = fricli("payload", str(tmp_path / "terms.parquet"), "--frame", "flange", "--json", cwd=elsewhere)
    assert res.returncode == 0, res.stderr
    assert json.loads(res.stdout)["verdict"] == "none"


TOOL = URDF.replace("</robot>", """  <joint name="tool_joint" type="fixed"><parent link="flange"/><child link="tool"/>
    <origin xyz="0.1 0 0"/></joint>
  <link name="tool"><inertial><origin xyz="0.02 0.12 0"/><mass value="2.0"/>
    <inertia ixx="0.004" ixy="0" ixz="0" iyy="0.006" iyz="0" izz="0.006"/></inertial></link>
</robot>""")


def test_a_tool_the_arm_does_not_carry_is_not_written_as_a_negative_link(arm, tmp_path):
    """The URDF holds a 2 kg tool off the wrist's axis that the arm does not carry (the log comes from
    the URDF without it): no link l4 with the flange and the tool at CAD gives the wrist what its
    torques show. The calibrated URDF holds that whole body in l4 and no inertia in the flange and the
    tool, every link a real body, says so, and predicts a held-out trajectory as the arm moves it."""
    model, x_true, fit, held = arm
    (tmp_path / "tool.urdf").write_text(TOOL)
    log = write_log(tmp_path / "fit.parquet", *fit, simulate(model, *fit))
    res = fricli("calibrate", log, "--urdf", "tool.urdf", "--match", "order", "-o", "cal.urdf", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert ("warning: link l4: with flange, tool fixed to it (2.3 kg at CAD), its body comes out at" in res.stderr
            and "the calibrated URDF holds the whole body in l4 and no inertia in flange, tool. The joint torques see "
                "only the body they form; a large gap means they are not mounted as the URDF says" in res.stderr)
    text = (tmp_path / "cal.urdf").read_text()
    links = link_inertials(text, "cal.urdf")
    assert not links["tool"].any() and not links["flange"].any()
    assert all(cb._physical(p) is None for name, p in links.items() if name.startswith("l"))
    calibrated = RobotModel(text, "cal.urdf")
    t, q, qd, qdd = held
    tau_g, tau_dyn = calibrated.terms(q, qd, qdd)
    truth = simulate(model, *held) - (FRICTION[:, 0] * qd + FRICTION[:, 1] * np.sign(qd) + FRICTION[:, 2])
    assert np.linalg.norm(tau_g + tau_dyn - truth) < 1e-6 * np.linalg.norm(truth)


def _two_body_problem(seed: int):
    """A consistent fit's problem with two random bodies: (A (400, 28), b, x_true, x0 (the prior's
    centre, 30 % off), s (its std))."""
    rng = np.random.default_rng(seed)
    bodies = [pin.Inertia(rng.uniform(0.5, 3), rng.uniform(-0.1, 0.1, 3), np.diag(rng.uniform(0.005, 0.05, 3)))
              for _ in range(2)]
    x_true = np.concatenate([b.toDynamicParameters() for b in bodies] + [rng.uniform(0.1, 1, 2), rng.uniform(0, 2, 6)])
    A = rng.normal(size=(400, 28))
    b = A @ x_true + rng.normal(0, 0.01, 400)
    x0 = x_true * rng.uniform(0.7, 1.3, len(x_true))
    return A, b, x_true, x0, (np.abs(x0) + 1e-3) * 0.5


def test_the_consistent_fit_is_not_stuck_where_an_estimate_was_clipped():
    """The consistent fit is convex in the parameters but not in the Cholesky factors it runs on: from
    an estimate of a body far outside consistency (here the true body mirrored), clipped to a nearly
    singular factor, its steps vanish. The true parameters are consistent, so the fit must reach a
    cost no higher than theirs (from the clipped estimate alone: 100 to 1,000 times higher)."""
    for seed in range(3):
        A, b, x_true, x0, s = _two_body_problem(seed)
        mirrored = x_true.copy()
        mirrored[:10] *= -1
        x = cb.consistent_fit(A, b, mirrored, x0, s, 2)

        def cost(x):
            return np.sum((A @ x - b) ** 2) + np.sum(((x - x0) / s) ** 2)

        assert cost(x) <= cost(x_true) * (1 + 1e-6)


def test_the_consistent_fit_reaches_the_optimum_it_certifies():
    """The barrier method's result is strictly consistent and within its reported gap of the optimum:
    no consistent point costs less than its cost minus the gap (checked at the true parameters and
    at the end of Levenberg-Marquardt run from the result over each body's Cholesky factor), and the
    gap is within ``GAP`` of the cost."""
    from scipy import optimize

    from fricli.robot.calibration import fit

    tril = np.tril_indices(4)
    for seed in range(3):
        A, b, x_true, x0, s = _two_body_problem(10 + seed)
        estimate = x_true.copy()
        estimate[10:20] *= -1          # far outside consistency
        info = {}
        x = cb.consistent_fit(A, b, estimate, x0, s, 2, info=info)

        def cost(x):
            return np.sum((A @ x - b) ** 2) + np.sum(((x - x0) / s) ** 2)

        assert all(np.linalg.eigvalsh(cb.pseudo_inertia(x[k:k + 10])).min() > 0 for k in (0, 10))
        assert np.all(x[20:22] > 0)
        assert 0 <= info["gap"] <= fit.GAP * cost(x)

        def params(th):
            pis = []
            for k in range(2):
                low = np.zeros((4, 4))
                low[tril] = th[10 * k:10 * k + 10]
                pis.append(cb._from_pseudo(low @ low.T))
            return np.concatenate(pis + [th[20:22] ** 2, th[22:]])

        start = np.concatenate([np.linalg.cholesky(cb.pseudo_inertia(x[k:k + 10]))[tril] for k in (0, 10)]
                               + [np.sqrt(x[20:22]), x[22:]])
        polished = optimize.least_squares(lambda th: np.concatenate([A @ params(th) - b, (params(th) - x0) / s]),
                                          start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15, max_nfev=20000)
        bound = cost(x) - info["gap"] - 1e-12 * cost(x)
        assert cost(params(polished.x)) >= bound and cost(x_true) >= bound


def test_a_urdf_link_of_negative_mass_is_refused(tmp_path):
    """Pinocchio merges a link of negative mass into its body without a word, into nonsense."""
    with pytest.raises(errors.ModelFileError, match="link 'flange': mass -0.3 kg"):
        RobotModel(URDF.replace('<mass value="0.3"/>', '<mass value="-0.3"/>'), "neg.urdf")
    with pytest.raises(errors.ModelFileError, match="link 'flange': its <inertial> holds a value that is no number"):
        RobotModel(URDF.replace('<mass value="0.3"/>', '<mass value="heavy"/>'), "bad.urdf")


def test_inconsistent_estimate_is_refused_or_enforced(tmp_path):
    rng = np.random.default_rng(3)
    model, _ = true_model(rng, scale=0.0)
    # link l3's first moment doubled with its inertia about the joint kept: a negative inertia at the
    # centre of mass, which no real body has
    pi = model.inertias[3].toDynamicParameters()
    pi[1:4] *= 2.0
    model.inertias[3] = pin.Inertia.FromDynamicParameters(pi)
    fit = harmonics(rng, 1200, (0.2, 0.45, 0.7, 1.1), 0.25)
    log = write_log(tmp_path / "fit.parquet", *fit, simulate(model, *fit))
    (tmp_path / "cad.urdf").write_text(URDF)
    res = fricli("calibrate", log, "--urdf", "cad.urdf", "--match", "order", "--consistency", "check", "-o", "cal.urdf",
                 cwd=tmp_path)
    assert res.returncode == errors.FIT, res.stderr
    assert "physically inconsistent: " in res.stderr and "link l3: " in res.stderr and "Traceback" not in res.stderr
    assert not (tmp_path / "cal.urdf").exists() and not (tmp_path / "cal.calibration.json").exists()

    robot = RobotModel(URDF, "cad")
    cal = cb.calibrate(robot, motion(*fit, simulate(model, *fit)))
    assert cal.report["consistency"]["ok"]
    assert any("l3" in p for p in cal.report["consistency_enforced"]["inconsistent_before"])
    # the consistent fit is the closest a real body gets: worse than the exact (inconsistent) one, not broken
    assert 0 < cal.report["fit"]["3"]["rms_after"] < cal.report["fit"]["3"]["rms_before"]


def test_badly_excited_run_reports_undetermined_directions(tmp_path):
    rng = np.random.default_rng(11)
    model, _ = true_model(rng)
    # slow, small motion: gravity and friction dominate, accelerations are tiny against the noise
    slow = harmonics(rng, 1500, (0.03, 0.05), 0.004)
    log = write_log(tmp_path / "slow.parquet", *slow, simulate(model, *slow, rng=rng, noise=0.05))
    (tmp_path / "cad.urdf").write_text(URDF)
    res = fricli("calibrate", log, "--urdf", "cad.urdf", "--match", "order", "-o", "cal.urdf", cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "undetermined (kept near CAD)" in res.stderr
    report = json.loads((tmp_path / "cal.calibration.json").read_text())
    undetermined = report["excitation"]["undetermined"]
    assert undetermined and all(d["information"] < 1.0 for d in undetermined)
    named = {p["parameter"] for d in undetermined for p in d["combination"]}
    assert any(".armature" in p or ".I" in p for p in named)


def test_refusals(arm, tmp_path):
    model, _, fit, _ = arm
    t, q, qd, qdd = fit
    qd, q = qd.copy(), q.copy()
    q[:, 2], qd[:, 2] = 0.3, 0.0
    log = write_log(tmp_path / "still.parquet", t, q, qd, qdd, simulate(model, t, q, qd, qdd))
    (tmp_path / "cad.urdf").write_text(URDF)
    res = fricli("calibrate", log, "--urdf", "cad.urdf", "-o", "cal.urdf", cwd=tmp_path)
    assert res.returncode == errors.INPUT and "--match" in res.stderr
    res = fricli("calibrate", log, "--urdf", "cad.urdf", "--match", "order", "-o", "cal.urdf", cwd=tmp_path)
    assert res.returncode == errors.DATA and "joint 3 is held still (position span under 0.01 rad)" in res.stderr
    qd[700:710, 2] = 0.5           # ten rows of motion: its friction has too few rows to be fitted
    q[700:, 2] += np.minimum(np.arange(len(t) - 700), 10) * 0.005
    log = write_log(tmp_path / "brief.parquet", t, q, qd, qdd, simulate(model, t, q, qd, qdd))
    res = fricli("calibrate", log, "--urdf", "cad.urdf", "--match", "order", "-o", "cal.urdf", cwd=tmp_path)
    assert res.returncode == errors.DATA and "joint 3 is in motion in 10 rows" in res.stderr, res.stderr
    # a log of velocities without positions: the rigid-body terms need q (it was an internal error)
    pq.write_table(pq.read_table(log).drop_columns(["q"]), tmp_path / "no_q.parquet")
    res = fricli("calibrate", "no_q.parquet", "--urdf", "cad.urdf", "--match", "order", "-o", "cal.urdf", cwd=tmp_path)
    assert res.returncode == errors.INPUT and "joint 1: the robot model needs positions q" in res.stderr, res.stderr
    # a prismatic joint for a rotary log's joint: refused as fricli import refuses it
    (tmp_path / "prismatic.urdf").write_text(URDF.replace('<joint name="j3" type="revolute">',
                                                          '<joint name="j3" type="prismatic">'))
    res = fricli("calibrate", log, "--urdf", "prismatic.urdf", "--match", "order", "-o", "cal.urdf", cwd=tmp_path)
    assert res.returncode == errors.MODEL and "joint j3 is linear, but log joint 3 is rotary" in res.stderr, res.stderr
    # NaN rows: no --drop-invalid to advise (a whole-arm fit takes every row of every joint)
    nan_q = q.copy()
    nan_q[100:105, 1] = np.nan
    bad = write_log(tmp_path / "nan.parquet", t, nan_q, qd, qdd, simulate(model, t, q, qd, qdd))
    res = fricli("calibrate", bad, "--urdf", "cad.urdf", "--match", "order", "-o", "cal.urdf", cwd=tmp_path)
    assert res.returncode == errors.INPUT and "remove those rows from the log" in res.stderr, res.stderr
    assert "--drop-invalid" not in res.stderr
    # a report into a missing folder: the existing URDF stays as it was
    (tmp_path / "cal.urdf").write_text("mine")
    t, q, qd, qdd = fit
    good = write_log(tmp_path / "good.parquet", t, q, qd, qdd, simulate(model, t, q, qd, qdd))
    res = fricli("calibrate", good, "--urdf", "cad.urdf", "--match", "order", "-o", "cal.urdf", "--report",
                 "missing/r.json", cwd=tmp_path)
    assert res.returncode == errors.OUTPUT and (tmp_path / "cal.urdf").read_text() == "mine", res.stderr


def test_stribeck_friction_is_found_with_the_rigid_body(arm):
    """With a Stribeck bump in the true friction at a velocity on the search grid, --friction stribeck
    finds that velocity and the whole model; the linear friction cannot follow it."""
    model, _, fit, held = arm
    t, q, qd, qdd = fit
    keep = cb.edge_rows(t, cb.DEFAULT_EDGE_S)
    vs = np.abs(qd[keep]).max(axis=0) * cb.STRIBECK_GRID[12]
    bump = np.array([4.0, -3.0, 2.0, 0.5])                     # Fs - Fc [Nm]

    def torque(t, q, qd, qdd):
        return simulate(model, t, q, qd, qdd) + bump * np.sign(qd) * np.exp(-np.square(qd / vs))

    robot = RobotModel(URDF, "cad")
    cal = cb.calibrate(robot, motion(*fit, torque(*fit)), friction="stribeck")
    linear = cb.calibrate(robot, motion(*fit, torque(*fit)))
    fr = cal.report["friction"]
    assert fr["kind"] == "stribeck"
    np.testing.assert_allclose([fr["joints"][j]["vs"] for j in "1234"], vs, rtol=1e-9)
    np.testing.assert_allclose([fr["joints"][j]["Fs"] - fr["joints"][j]["Fc"] for j in "1234"], bump, rtol=1e-6)
    after = max(f["rms_after"] for f in cal.report["fit"].values())
    assert after < 1e-6 * min(f["rms_after"] for f in linear.report["fit"].values())


def test_poor_excitation_and_an_unexplained_offset_are_flagged(arm):
    """A run of small motions leaves the base regressor ill-conditioned; a constant torque the
    rigid body cannot give (a spring, a cable) ends up as a friction offset above the Coulomb level."""
    model = arm[0]
    robot = RobotModel(URDF, "cad")
    small = harmonics(np.random.default_rng(1), 1500, (0.2, 0.45, 0.7, 1.1), 0.02)
    cal = cb.calibrate(robot, motion(*small, simulate(model, *small, rng=np.random.default_rng(2), noise=0.05)))
    assert cal.report["excitation"]["condition_number_scaled"] > cb.POOR_EXCITATION
    assert cal.report["suspicious"][0].startswith("the run excites the arm's dynamics poorly")
    fit = arm[2]
    tau = simulate(model, *fit)

    def offsets(tau):
        return [w for w in cb.calibrate(robot, motion(*fit, tau)).report["suspicious"] if "friction offset" in w]

    assert offsets(tau) == []
    tau[:, 1] += 10.0                       # joint 2: Fc 7 Nm
    flagged = offsets(tau)
    assert len(flagged) == 1 and flagged[0].startswith("joint j2: friction offset 9.5 exceeds its Coulomb level 7")
    # a negative Coulomb level is no level an offset could exceed: the consistency warning says what is wrong
    cal = cb.calibrate(robot, motion(*fit, tau))
    x = cal.x.copy()
    x[44 + 3 * 2 + 1] = -0.5                 # joint 3's Fc
    flipped = cb.Calibration(x=x, x0=cal.x0, names=cal.names, bodies=cal.bodies, joints=cal.joints, report={})
    assert not any(w.startswith("joint j3: friction offset") for w in cb.suspicious(flipped))
    assert any(w.startswith("joint j3: friction Fv 5, Fc -0.5: a negative coefficient") for w in
               cb.consistency(flipped)["warnings"])


def test_a_log_too_large_for_memory_is_refused_before_the_regressor(arm, monkeypatch):
    model, _, fit, _ = arm
    robot = RobotModel(URDF, "cad")
    monkeypatch.setattr(cb, "available_memory", lambda: 10 * 2**20)     # 10 MiB
    with pytest.raises(DataError, match=r"calibrating 1,400 samples of 4 joints needs about 0\.015 GiB of memory, "
                                        r"0\.0098 GiB are available: calibrate on part of the log \(--from, --until\)"):
        cb.calibrate(robot, motion(*fit, simulate(model, *fit)))


def test_from_and_until_calibrate_on_part_of_the_log(arm, tmp_path):
    model, _, fit, _ = arm
    log = write_log(tmp_path / "fit.parquet", *fit, simulate(model, *fit))
    (tmp_path / "cad.urdf").write_text(URDF)
    res = fricli("calibrate", log, "--urdf", "cad.urdf", "--match", "order", "-o", "cal.urdf", "--until", "50%",
                 cwd=tmp_path)
    assert res.returncode == 0, res.stderr
    assert "calibrating 4 joints on 750 samples" in res.stderr


@pytest.mark.slow
def test_the_gravity_recorded_with_the_log_is_used(arm, tmp_path):
    """A tilted base: the gravity given to dynamics (or import) is the one calibrate and a later
    dynamics use unless told otherwise."""
    model, _, fit, _ = arm
    raw = write_log(tmp_path / "raw.parquet", *fit, simulate(model, *fit))
    (tmp_path / "cad.urdf").write_text(URDF)
    tilted = ["--gravity", "0", "-3.355", "-9.218"]
    for args in (["dynamics", raw, "--urdf", "cad.urdf", "--match", "order", *tilted, "-o", "log.parquet"],
                 ["dynamics", "log.parquet", "--urdf", "cad.urdf", "--match", "order", "-o", "again.parquet"]):
        res = fricli(*args, cwd=tmp_path)
        assert res.returncode == 0, res.stderr
    first, again = (logs.read_table(str(tmp_path / f))[0] for f in ("log.parquet", "again.parquet"))
    assert logs.robot_record(again.schema)["gravity"] == [0.0, -3.355, -9.218]
    assert first.column("tau_g").equals(again.column("tau_g"))
    reports = []
    for extra in ([], tilted):
        # each in a process of its own: two calibrations in one busy process can differ in the 7th digit
        res = subprocess.run([sys.executable, "-m", "fricli", "calibrate", "log.parquet", "--urdf", "cad.urdf", "-o",
                              "cal.urdf", "--prior", "0.5", "--json", *extra], cwd=tmp_path, capture_output=True,
                             text=True)
        assert res.returncode == 0, res.stderr
        reports.append(json.loads(res.stdout)["fit"])
    assert reports[0] == reports[1]


def test_a_consistent_fit_stopped_short_of_its_optimum_is_a_warning(monkeypatch):
    """Cut to two Newton steps, the fit says it has not converged, and the report's warnings say so."""
    from fricli.robot.calibration import fit, report

    A, b, x_true, x0, s = _two_body_problem(0)
    estimate = x_true.copy()
    estimate[:10] *= -1
    info = {}
    monkeypatch.setattr(fit, "MAX_NEWTON", 2)
    cb.consistent_fit(A, b, estimate, x0, s, 2, info=info)
    assert info["newton_steps"] == 2 and not info["converged"]
    rep = {"consistency_enforced": {"converged": False, "newton_steps": 2, "optimality_gap": info["gap"]},
           "consistency": {"warnings": []}, "suspicious": []}
    (line,) = report.warnings(rep)
    assert line.startswith("the physically consistent fit stopped after 2 Newton steps")
    monkeypatch.undo()
    cb.consistent_fit(A, b, estimate, x0, s, 2, info=info)
    assert info["converged"]
