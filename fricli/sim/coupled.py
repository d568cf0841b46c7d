"""A simulated arm whose friction lives in its motors, with a coupled wrist.

Six rotary joints driven by six motors through a transmission ``fricli.core.transmission``:
joints 1-4 each through a signed gear ratio, joints 5 and 6 through a coupled wrist (motor 6
turns with joint 5 as well as joint 6, as in wrists whose last two axes share gearing):

    theta_d   = R q_d                                              motor velocities [rad/s]
    f_i(w)    = sign(w) (Fc_i + (Fs_i - Fc_i) exp(-(w/vs_i)^2)) + Fv_i w   motor i's friction [Nm]
    tau_f     = R^T f(theta_d)                                     joint friction [Nm]
    tau_g     = a cos(q)                                           a simple gravity load [Nm]
    tau_dyn   = (diag(J_link) + R^T J_m R) q_dd                    rigid body and rotors [Nm]
    tau_motor = R^-T (tau_g + tau_dyn + tau_f) + e,  e ~ N(0, sd_i^2) per motor   [Nm]
    tau_m     = R^T tau_motor                                      the joint torque a log holds

Joint trajectories are sums of harmonics (each joint its own frequencies). The measurement
noise ``e`` is on the motor torques, so the noise floor of a joint's friction target is
sqrt(sum_i R_ij^2 sd_i^2) (``noise_floor``). ``simulate_coupled`` returns the long-format log
table (log contract, one row per joint per sample; the transmission in the schema metadata key
``fricli.transmission``) and the motor-side recording as a controller dumps it: motor positions
and motor torques, two arrays without time (``write_recording`` writes them as two text files).
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

from fricli.core.transmission import META_KEY, Transmission

JOINTS = (1, 2, 3, 4, 5, 6)


@dataclasses.dataclass(frozen=True)
class MotorFriction:
    """Friction of one motor (motor side): Coulomb fc [Nm], viscous fv [Nm s/rad], optionally a
    Stribeck bump to fs [Nm] below vs [rad/s] (fs = None: none)."""

    fc: float
    fv: float
    fs: float | None = None
    vs: float = 5.0

    def torque(self, w: np.ndarray) -> np.ndarray:
        """Friction (n,) [Nm] at motor velocities w (n,) [rad/s], positive along the motion."""
        level = self.fc if self.fs is None else self.fc + (self.fs - self.fc) * np.exp(-(w / self.vs) ** 2)
        return np.sign(w) * level + self.fv * w


@dataclasses.dataclass(frozen=True)
class CoupledArm:
    transmission: Transmission
    friction: tuple[MotorFriction, ...]     # one per motor
    gravity: np.ndarray                     # (k,) gravity amplitude a [Nm]
    link_inertia: np.ndarray                # (k,) [kg m^2]
    noise_sd: np.ndarray                    # (k,) motor torque noise sd [Nm]

    def noise_floor(self) -> np.ndarray:
        """(k,) [Nm]: the sd of the noise in each joint's friction target, sqrt(sum_i R_ij^2 sd_i^2)."""
        return np.sqrt((self.transmission.ratio ** 2 * self.noise_sd[:, None] ** 2).sum(axis=0))

    def motor_friction(self, theta_d: np.ndarray) -> np.ndarray:
        """(n, k) [Nm] per motor at motor velocities theta_d (n, k) [rad/s]."""
        return np.column_stack([f.torque(theta_d[:, i]) for i, f in enumerate(self.friction)])

    def joint_friction(self, qd: np.ndarray) -> np.ndarray:
        """(n, k) [Nm] at the joints for joint velocities qd (n, k) [rad/s]."""
        tr = self.transmission
        return tr.joint_torques(self.motor_friction(tr.motor_velocities(qd)))


def default_arm(stribeck: bool = False, rigid_body: bool = True) -> CoupledArm:
    """The arm of docs/drives.md: signed gear ratios, wrist R[5:7, 5:7] = [[-50, 0], [30, 40]].
    ``rigid_body`` False: no gravity and no inertia, the motor torques are friction and noise alone
    (a recording a log needs no robot model for)."""
    ratio = np.diag([-120.0, 100.0, -80.0, 60.0, -50.0, 40.0])
    ratio[5, 4] = 30.0
    fc = (0.05, 0.06, 0.04, 0.03, 0.03, 0.025)
    fv = (2e-4, 2.5e-4, 2e-4, 1.5e-4, 1.5e-4, 1.2e-4)
    friction = tuple(MotorFriction(c, v, fs=1.4 * c if stribeck else None) for c, v in zip(fc, fv))
    tr = Transmission(JOINTS, ratio, offset=[0.3, -1.0, 2.0, 0.0, 0.5, -0.7],
                      rotor_inertia=[1.5e-4, 1.5e-4, 8e-5, 5e-5, 3e-5, 3e-5])
    body = 1.0 if rigid_body else 0.0
    tr = Transmission(JOINTS, ratio, offset=tr.offset, rotor_inertia=body * tr.rotor_inertia)
    return CoupledArm(tr, friction, gravity=body * np.array([0.0, 40.0, 15.0, 2.0, 1.0, 0.2]),
                      link_inertia=body * np.array([3.0, 4.0, 1.0, 0.2, 0.1, 0.05]),
                      noise_sd=np.full(6, 0.002))


@dataclasses.dataclass
class CoupledRun:
    t: np.ndarray              # (n,) [s]
    q: np.ndarray              # (n, k) joint positions [rad]
    qd: np.ndarray             # (n, k) [rad/s]
    qdd: np.ndarray            # (n, k) [rad/s^2]
    theta: np.ndarray          # (n, k) motor positions [rad]
    tau_motor: np.ndarray      # (n, k) measured motor torques [Nm]
    tau_m: np.ndarray          # (n, k) joint torques R^T tau_motor [Nm]
    tau_g: np.ndarray          # (n, k)
    tau_dyn: np.ndarray        # (n, k)
    tau_f: np.ndarray          # (n, k) true joint friction [Nm]
    table: object              # pyarrow.Table, the long-format log


def trajectories(t: np.ndarray, k: int, rng: np.random.Generator, harmonics: int = 4) -> tuple:
    """q, qd, qdd (n, k) [rad, rad/s, rad/s^2]: per joint a sum of ``harmonics`` sines with its own
    frequencies (0.05-0.6 Hz) and random phases, peak speeds around 1 rad/s."""
    q, qd, qdd = (np.zeros((len(t), k)) for _ in range(3))
    for j in range(k):
        freqs = rng.uniform(0.05, 0.6, harmonics)
        phases = rng.uniform(0, 2 * np.pi, harmonics)
        amps = 0.5 / (2 * np.pi * freqs) / np.sqrt(harmonics)
        for a, f, p in zip(amps, freqs, phases):
            w = 2 * np.pi * f
            q[:, j] += a * np.sin(w * t + p)
            qd[:, j] += a * w * np.cos(w * t + p)
            qdd[:, j] -= a * w * w * np.sin(w * t + p)
    return q, qd, qdd


def simulate_coupled(arm: CoupledArm | None = None, *, duration: float = 20.0, rate_hz: float = 2000.0,
                     rng: np.random.Generator) -> CoupledRun:
    """Simulate ``arm`` (default: ``default_arm()``) for ``duration`` [s] sampled at ``rate_hz``."""
    from fricli.core import logs

    arm = arm or default_arm()
    tr = arm.transmission
    k = len(tr.joints)
    n = int(round(duration * rate_hz))
    t = np.arange(n) / rate_hz
    q, qd, qdd = trajectories(t, k, rng)
    tau_f = arm.joint_friction(qd)
    tau_g = arm.gravity * np.cos(q)
    tau_dyn = qdd @ (np.diag(arm.link_inertia) + tr.reflected_inertia()).T
    tau_motor = tr.motor_torques(tau_g + tau_dyn + tau_f) + rng.normal(size=(n, k)) * arm.noise_sd
    tau_m = tr.joint_torques(tau_motor)
    theta = tr.motor_positions(q)
    columns = {"t": np.tile(t, k), "joint": np.repeat(np.array(tr.joints, dtype=np.int64), n)}
    for name, values in (("q", q), ("qd", qd), ("qdd", qdd), ("tau_m", tau_m), ("tau_g", tau_g),
                         ("tau_dyn", tau_dyn), ("tau_f_true", tau_f)):
        columns[name] = values.T.reshape(-1)
    units = {"t": "s", "q": "rad", "qd": "rad/s", "qdd": "rad/s^2", **{c: "Nm" for c in logs.TORQUES}}
    table = logs.table_from_arrays(columns, units)
    sim = {"noise_floor": dict(zip(map(str, tr.joints), arm.noise_floor().tolist())),
           "motor_noise_sd": arm.noise_sd.tolist(), "rate_hz": rate_hz}
    table = table.replace_schema_metadata({META_KEY: tr.to_json().encode(),
                                           b"fricli.sim.coupled": json.dumps(sim).encode()})
    return CoupledRun(t, q, qd, qdd, theta, tau_motor, tau_m, tau_g, tau_dyn, tau_f, table)


def write_recording(run: CoupledRun, positions: str, torques: str, *, position_scale: float = 1.0,
                    torque_scale: float = 1.0) -> None:
    """The motor-side recording as a controller dumps it: ``positions`` holds the motor angles
    divided by ``position_scale`` (one column per motor, no time), ``torques`` the motor torques
    divided by ``torque_scale``; comma-separated, no header, every digit of a float64."""
    np.savetxt(positions, run.theta / position_scale, delimiter=",", fmt="%.17g")
    np.savetxt(torques, run.tau_motor / torque_scale, delimiter=",", fmt="%.17g")


def mapping_text(tr: Transmission, rate_hz: float, torque_scale: float) -> str:
    """The import mapping (TOML) of ``write_recording``'s two files for transmission ``tr``."""
    rows = ",\n         ".join("[" + ", ".join(f"{x:g}" for x in row) + "]" for row in tr.ratio)
    lines = ['files = ["positions", "torques"]     # the two files, in the order they are given',
             f"time = {{rate = {rate_hz!r}}}             # no time column", "",
             "[transmission]                       # theta = R q + theta0, tau = R^T tau_motor",
             f"ratio = [{rows}]", f"offset = {tr.offset.tolist()!r}", ""]
    for k, joint in enumerate(tr.joints):
        lines += ["[[joints]]", f"name = {joint}", f'theta = {{file = "positions", column = {k + 1}}}',
                  f'tau_motor = {{file = "torques", column = {k + 1}, unit = "Nm", scale = {torque_scale!r}}}', ""]
    return "\n".join(lines)


def write_example(folder: str, *, seed: int, duration: float = 20.0, rate_hz: float = 4000.0) -> list[str]:
    """The motor-side recording of the friction-only arm (``default_arm(rigid_body=False)``) in
    ``folder``: positions.csv, torques.csv (mNm, sign reversed) and wrist.toml. Returns the paths."""
    import os

    arm = default_arm(rigid_body=False)
    run = simulate_coupled(arm, duration=duration, rate_hz=rate_hz, rng=np.random.default_rng(seed))
    paths = [os.path.join(folder, n) for n in ("positions.csv", "torques.csv", "wrist.toml")]
    write_recording(run, paths[0], paths[1], torque_scale=-1e-3)
    with open(paths[2], "w") as fh:
        fh.write(mapping_text(arm.transmission, rate_hz, -1e-3))
    return paths


if __name__ == "__main__":
    import argparse
    import os

    parser = argparse.ArgumentParser(prog="python -m fricli.sim.coupled",
                                     description="Write a motor-side recording of the simulated coupled-wrist arm.")
    parser.add_argument("folder")
    parser.add_argument("--seed", type=int, default=1)
    parser.add_argument("--duration", type=float, default=20.0, help="[s]")
    parser.add_argument("--rate", type=float, default=4000.0, help="[Hz]")
    args = parser.parse_args()
    os.makedirs(args.folder, exist_ok=True)
    print("wrote " + ", ".join(write_example(args.folder, seed=args.seed, duration=args.duration, rate_hz=args.rate)))
