"""The closed loop on a 7-joint arm with Stribeck friction: which friction law the calibration of
``diagnose --fix --calibrate`` needs (docs/diagnose.md, "Robot-model errors of a whole arm").

    PYTHONPATH=. python benchmarks/arm7_closed_loop.py [--work DIR]     # about a minute on 2 cores

The arm (7 revolute joints, one continuous; a tilted, offset base; a fixed hand) is simulated through
Pinocchio's RNEA, independently of fricli: reflected rotor inertia per joint, friction
``(Fc + (Fs - Fc) exp(-(qd/vs)^2)) sign(qd) + Fv qd + offset`` with a Stribeck bump on every joint,
motor currents with noise, encoder-quantised positions, 60 s at 500 Hz along sums of harmonics. The
URDF given to fricli is a CAD one: masses off by 12-25 %, centres of mass by up to 22 %.

One run is recorded for fitting, another (other harmonics) for scoring. The user's commands::

    fricli import fit.csv --mapping arm7.toml --urdf cad.urdf --cutoff 10 -o fit.parquet
    fricli identify fit.parquet -o lugre
    fricli diagnose lugre fit.parquet --fix --calibrate cal-LAW.urdf --calibrate-friction LAW -o fixed-LAW
    fricli import score.csv --mapping arm7.toml --urdf cal-LAW.urdf --cutoff 10 -o score-LAW.parquet
    fricli predict fixed-LAW score-LAW.parquet -o pred-LAW.parquet

for LAW in linear and stribeck. Printed per joint: the RMS of the predicted friction minus the true
friction on the scoring run (0.5 s from each end left out), and of the calibrated URDF's rigid-body
torque (tau_g + tau_dyn of the import) minus the true one.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
FS, DURATION, JOINTS = 500.0, 60.0, 7     # [Hz], [s] (--duration), joints
# link: mass [kg], centre of mass [m], principal inertia [kg m^2], its frame's rpy
LINKS = {
    "link1": (4.0, (0.0, -0.03, -0.07), (0.030, 0.028, 0.010), (0.2, 0.0, 0.1)),
    "link2": (3.6, (0.0, -0.07, 0.03), (0.028, 0.010, 0.026), (0.0, 0.15, 0.0)),
    "link3": (3.0, (0.04, 0.03, -0.07), (0.014, 0.013, 0.008), (0.1, 0.0, 0.0)),
    "link4": (2.8, (-0.05, 0.06, 0.03), (0.013, 0.008, 0.013), (0.0, 0.0, 0.2)),
    "link5": (2.2, (0.0, 0.04, -0.11), (0.025, 0.022, 0.006), (0.1, 0.1, 0.0)),
    "link6": (1.5, (0.05, -0.01, 0.01), (0.004, 0.006, 0.006), (0.0, 0.0, 0.0)),
    "link7": (0.8, (0.01, 0.01, 0.07), (0.002, 0.002, 0.001), (0.0, 0.0, 0.3)),
    "hand": (1.2, (0.0, 0.0, 0.05), (0.003, 0.001, 0.003), (0.0, 0.0, 0.0)),
}
# CAD errors: mass factor, centre-of-mass factor per axis
CAD = {"link1": (1.15, (1.0, 0.85, 1.2)), "link2": (0.82, (1.0, 1.18, 0.8)), "link3": (1.2, (0.85, 1.15, 1.12)),
       "link4": (0.88, (1.2, 0.8, 1.15)), "link5": (1.12, (1.0, 0.78, 1.2)), "link6": (0.85, (1.2, 1.1, 0.9)),
       "link7": (1.25, (0.8, 1.2, 0.85)), "hand": (1.18, (1.0, 1.0, 0.85))}
# parent, child, origin xyz, origin rpy, limits (None: continuous)
H = np.pi / 2
CHAIN = [("link0", "link1", "0 0 0.333", "0 0 0", 2.9), ("link1", "link2", "0 0 0", f"{-H} 0 0", 1.76),
         ("link2", "link3", "0 -0.316 0", f"{H} 0 0", 2.9), ("link3", "link4", "0.0825 0 0", f"{H} 0 0", 3.07),
         ("link4", "link5", "-0.0825 0.384 0", f"{-H} 0 0", 2.9), ("link5", "link6", "0 0 0", f"{H} 0 0", 3.75),
         ("link6", "link7", "0.088 0 0", f"{H} 0 0", None)]
FC = np.array([2.0, 2.5, 1.8, 1.8, 0.9, 0.8, 0.6])                        # Coulomb [Nm]
FSTAT = FC * np.array([1.5, 1.4, 1.5, 1.3, 1.6, 1.4, 1.5])                 # static [Nm]
VS = np.array([0.05, 0.06, 0.04, 0.05, 0.08, 0.06, 0.07])                  # Stribeck velocity [rad/s]
FV = np.array([3.0, 3.5, 2.0, 2.2, 1.0, 0.8, 0.5])                         # viscous [Nm s/rad]
OFFSET = np.array([0.1, -0.2, 0.0, 0.05, 0.0, 0.0, 0.02])                  # [Nm]
ARMATURE = np.array([0.25, 0.25, 0.18, 0.18, 0.06, 0.06, 0.04])            # reflected rotor inertia [kg m^2]
KT = np.array([10.5, 10.5, 8.0, 8.0, 4.2, 4.2, 4.2])                       # drive gains [Nm/A]
Q0 = np.array([0.0, 0.0, 0.0, -1.6, 0.0, 1.8, 0.0])
SPAN = np.array([1.4, 0.85, 1.4, 0.85, 1.4, 0.95, 3.6])                    # half range of each joint [rad]


def urdf(cad: bool) -> str:
    """The arm's URDF: the true one, or the CAD one (masses and centres of mass off)."""
    def inertial(name):
        m, c, d, rpy = LINKS[name]
        if cad:
            m, c = m * CAD[name][0], [ci * fi for ci, fi in zip(c, CAD[name][1])]
        return (f'<inertial><origin xyz="{c[0]:.5f} {c[1]:.5f} {c[2]:.5f}" rpy="{rpy[0]} {rpy[1]} {rpy[2]}"/>'
                f'<mass value="{m:.5f}"/><inertia ixx="{d[0]}" ixy="0" ixz="0" iyy="{d[1]}" iyz="0" izz="{d[2]}"/>'
                "</inertial>")
    out = ['<?xml version="1.0"?>', '<robot name="arm7">', '<link name="world"/>',
           '<joint name="mount" type="fixed"><parent link="world"/><child link="link0"/>'
           '<origin xyz="0.3 -0.2 0.75" rpy="0.349066 0 0.523599"/></joint>',
           '<link name="link0"><inertial><origin xyz="-0.04 0 0.05"/><mass value="4.0"/>'
           '<inertia ixx="0.02" ixy="0" ixz="0" iyy="0.02" iyz="0" izz="0.02"/></inertial></link>']
    for k, (parent, child, xyz, rpy, limit) in enumerate(CHAIN, start=1):
        kind = "continuous" if limit is None else "revolute"
        lim = "" if limit is None else f'<limit lower="{-limit}" upper="{limit}" effort="87" velocity="2.1"/>'
        out += [f'<link name="{child}">{inertial(child)}</link>',
                f'<joint name="joint{k}" type="{kind}"><parent link="{parent}"/><child link="{child}"/>'
                f'<origin xyz="{xyz}" rpy="{rpy}"/><axis xyz="0 0 1"/>{lim}</joint>']
    out += [f'<link name="hand">{inertial("hand")}</link>',
            '<joint name="flange" type="fixed"><parent link="link7"/><child link="hand"/>'
            '<origin xyz="0 0 0.107" rpy="0 0 -0.785398"/></joint>', "</robot>", ""]
    return "\n".join(out)


def friction(qd: np.ndarray) -> np.ndarray:
    """The true friction (n, 7) [Nm]."""
    return (FC + (FSTAT - FC) * np.exp(-(qd / VS) ** 2)) * np.tanh(qd / 1e-3) + FV * qd + OFFSET


def trajectory(seed: int, f0: float, duration: float = DURATION, harmonics: int = 5):
    """t (n,), q, qd, qdd (n, 7): sums of harmonics of f0, at most 1.6 rad/s; the continuous joint
    also swings +-3.2 rad, past +-pi."""
    rng = np.random.default_rng(seed)
    t = np.arange(int(duration * FS)) / FS
    w = 2 * np.pi * f0 * np.arange(1, harmonics + 1)
    q, qd, qdd = (np.zeros((t.size, JOINTS)) for _ in range(3))
    for j in range(JOINTS):
        a, b = rng.normal(size=(2, harmonics)) / np.arange(1, harmonics + 1)
        s, c = np.sin(np.outer(t, w)), np.cos(np.outer(t, w))
        x, xd = s @ a + c @ b, c @ (a * w) - s @ (b * w)
        xdd = -(s @ (a * w ** 2) + c @ (b * w ** 2))
        scale = min(SPAN[j] / np.abs(x).max(), 1.6 / np.abs(xd).max())
        q[:, j], qd[:, j], qdd[:, j] = Q0[j] + scale * x, scale * xd, scale * xdd
    ws = 2 * np.pi / duration
    q[:, 6] += 3.2 * np.sin(ws * t)
    qd[:, 6] += 3.2 * ws * np.cos(ws * t)
    qdd[:, 6] -= 3.2 * ws ** 2 * np.sin(ws * t)
    return t, q, qd, qdd


def simulate(path: str, true_urdf: str, seed: int, f0: float, duration: float = DURATION) -> dict:
    """Write a controller's CSV dump (ms, degrees, amperes) of one run; the truth."""
    import pinocchio as pin

    model = pin.buildModelFromXML(true_urdf)
    data = model.createData()
    t, q, qd, qdd = trajectory(seed, f0, duration)
    config = np.zeros((t.size, model.nq))
    for j in range(JOINTS):
        joint = model.joints[model.getJointId(f"joint{j + 1}")]
        if joint.nq == 2:
            config[:, joint.idx_q], config[:, joint.idx_q + 1] = np.cos(q[:, j]), np.sin(q[:, j])
        else:
            config[:, joint.idx_q] = q[:, j]
    rigid = np.array([pin.rnea(model, data, config[i], qd[i], qdd[i]) for i in range(t.size)])
    rigid += ARMATURE * qdd
    tau_f = friction(qd)
    rng = np.random.default_rng(seed + 100)
    current = (rigid + tau_f) / KT + rng.normal(scale=0.01, size=rigid.shape)
    step = 2 * np.pi / 2 ** 18                                    # encoder resolution [rad]
    degrees = np.degrees(np.round(q / step) * step)
    header = "time_ms," + ",".join(f"q{j}_deg" for j in range(1, 8)) + "," + ",".join(f"i{j}_A" for j in range(1, 8))
    rows = np.column_stack([1234567.0 + 1e3 * t, degrees, current])
    np.savetxt(path, rows, delimiter=",", header=header, comments="", fmt="%.6f")
    return {"rigid": rigid, "tau_f": tau_f}


MAPPING = 'header = true\ntime = {column = "time_ms", unit = "ms"}\n[robot]\nmatch = "name"\n' + "".join(
    f'[[joints]]\nname = "joint{j}"\nq = {{column = "q{j}_deg", unit = "deg"}}\n'
    f'i_m = {{column = "i{j}_A", unit = "A"}}\nkt = {KT[j - 1]}\n' for j in range(1, 8))


def fricli(*args) -> None:
    cmd = [sys.executable, "-m", "fricli", *map(str, args)]
    print("$ fricli " + " ".join(map(str, args)), file=sys.stderr)
    subprocess.run(cmd, check=True, env={**os.environ, "PYTHONPATH": ROOT}, stdout=subprocess.DEVNULL)


def by_joint(path: str, column: str) -> np.ndarray:
    """``column`` of a long-format log as (n, 7), joints 1..7."""
    import pyarrow.parquet as pq

    table = pq.read_table(path, columns=["joint", column])
    joint = np.asarray(table.column("joint").to_pylist())
    values = table.column(column).to_numpy()
    return np.column_stack([values[joint == f"joint{j}"] for j in range(1, 8)])


def study(work: str, duration: float = DURATION) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """Per friction law of the calibration: RMS [Nm] per joint (7,) of the predicted minus the true
    friction and of the calibrated rigid body minus the true one, on the scoring run."""
    os.makedirs(work, exist_ok=True)
    p = lambda name: os.path.join(work, name)          # noqa: E731
    for name, cad in (("true.urdf", False), ("cad.urdf", True)):
        with open(p(name), "w", encoding="utf-8") as fh:
            fh.write(urdf(cad))
    with open(p("arm7.toml"), "w", encoding="utf-8") as fh:
        fh.write(MAPPING)
    true = urdf(False)
    simulate(p("fit.csv"), true, seed=1, f0=0.1, duration=duration)
    truth = simulate(p("score.csv"), true, seed=2, f0=0.125, duration=duration)
    fricli("import", p("fit.csv"), "--mapping", p("arm7.toml"), "--urdf", p("cad.urdf"), "--cutoff", 10,
           "-o", p("fit.parquet"), "-q")
    fricli("identify", p("fit.parquet"), "-o", p("lugre"), "-q")
    edge = slice(int(0.5 * FS), -int(0.5 * FS))
    rms = lambda x: np.sqrt(np.mean(x[edge] ** 2, axis=0))     # noqa: E731
    results = {}
    for law in ("linear", "stribeck"):
        fricli("diagnose", p("lugre"), p("fit.parquet"), "--fix", "--calibrate", p(f"cal-{law}.urdf"),
               "--calibrate-friction", law, "-o", p(f"fixed-{law}"), "-q")
        fricli("import", p("score.csv"), "--mapping", p("arm7.toml"), "--urdf", p(f"cal-{law}.urdf"), "--cutoff", 10,
               "-o", p(f"score-{law}.parquet"), "-q")
        fricli("predict", p(f"fixed-{law}"), p(f"score-{law}.parquet"), "-o", p(f"pred-{law}.parquet"), "-q")
        rigid = by_joint(p(f"score-{law}.parquet"), "tau_g") + by_joint(p(f"score-{law}.parquet"), "tau_dyn")
        results[law] = (rms(by_joint(p(f"pred-{law}.parquet"), "tau_f_pred") - truth["tau_f"]),
                        rms(rigid - truth["rigid"]))
    return results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--work", default=None, help="folder for the recordings, logs and models (default: temporary)")
    ap.add_argument("--duration", type=float, default=DURATION, help="seconds of each run")
    args = ap.parse_args()
    work = args.work or tempfile.mkdtemp(prefix="fricli-arm7-")
    results = study(work, args.duration)
    print(f"scoring run, RMS [Nm] per joint 1..7 (work folder {work})")
    print("| calibration's friction | predicted minus true friction | calibrated rigid body minus the true one |")
    print("|---|---|---|")
    for law, (fric, body) in results.items():
        print(f"| {law} | {', '.join(f'{x:.3f}' for x in fric)} | {', '.join(f'{x:.3f}' for x in body)} |")


if __name__ == "__main__":
    main()
