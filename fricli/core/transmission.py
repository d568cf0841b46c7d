"""Transmissions: from motor-side to joint-side signals, with signed gear ratios and coupled wrists.

For k joints driven by k motors (rotary axes; a linear axis reads m and N where rad and Nm are):

    theta   = R q + theta0            motor angles [rad] from joint angles q [rad]
    theta_d = R q_d                   motor velocities [rad/s]
    tau     = R^T tau_motor           joint torques [Nm] from motor torques [Nm] (power balance:
                                      tau_motor . theta_d = tau . q_d)
    M_rotor = R^T J_m R               rotor inertias J_m [kg m^2] (motor side) seen at the joints

R (k, k) is invertible; a diagonal R is the per-joint signed gear ratios, a full block a coupled
wrist (motor 6 turning with joint 5 as well as joint 6: row 6 of R = [.., r65, r66]). The joints
that share motors, the coupled groups, are the connected components of R's sparsity pattern.

The diagonal of R^T J_m R is the reflected rotor inertia of each joint (what a dynamics model
takes as its armature). Its off-diagonal part couples joint accelerations: a dynamics model
whose armature is diagonal only (Pinocchio's ``model.armature``) misses the torque
``cross_inertia() @ qdd``, which is added to tau_dyn (``cross_torque``).

Arrays of samples are (n, k): one row per sample, one column per joint (or motor) in the order
of ``joints``.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np

_COND_MAX = 1e12     # a ratio matrix worse conditioned than this is taken as singular
META_KEY = b"fricli.transmission"   # Parquet schema metadata key of a log's transmission (``to_json``)


@dataclasses.dataclass(frozen=True)
class Transmission:
    """R (k, k), theta0 (k,) [rad] and motor rotor inertias J_m (k,) [kg m^2] of joints ``joints``."""

    joints: tuple
    ratio: np.ndarray
    offset: np.ndarray
    rotor_inertia: np.ndarray

    def __init__(self, joints, ratio, offset=None, rotor_inertia=None):
        ratio = np.array(ratio, dtype=np.float64)
        k = len(joints)
        if ratio.shape != (k, k):
            raise ValueError(f"the ratio matrix must be {k} x {k} (one row per motor, one column per joint), "
                             f"not {' x '.join(map(str, ratio.shape))}")
        if not np.all(np.isfinite(ratio)):
            raise ValueError("the ratio matrix holds a non-finite value")
        if k and np.linalg.cond(ratio) > _COND_MAX:
            raise ValueError("the ratio matrix is singular: joint positions cannot be recovered from the motors'")
        offset = np.zeros(k) if offset is None else np.array(offset, dtype=np.float64).reshape(-1)
        inertia = np.zeros(k) if rotor_inertia is None else np.array(rotor_inertia, dtype=np.float64).reshape(-1)
        for what, v in (("offset", offset), ("rotor_inertia", inertia)):
            if v.shape != (k,) or not np.all(np.isfinite(v)):
                raise ValueError(f"{what} needs {k} finite numbers")
        if np.any(inertia < 0):
            raise ValueError("rotor_inertia must not be negative")
        for name, value in (("joints", tuple(joints)), ("ratio", ratio), ("offset", offset),
                            ("rotor_inertia", inertia)):
            if isinstance(value, np.ndarray):
                value.setflags(write=False)
            object.__setattr__(self, name, value)

    @classmethod
    def diagonal(cls, joints, ratios, offset=None, rotor_inertia=None) -> "Transmission":
        """Per-joint signed gear ratios (k,): motor turns per joint turn."""
        return cls(joints, np.diag(np.asarray(ratios, dtype=np.float64)), offset, rotor_inertia)

    # ----------------------------------------------------------------- mapping

    def motor_positions(self, q: np.ndarray) -> np.ndarray:
        """theta (n, k) [rad] from joint positions q (n, k) [rad]."""
        return q @ self.ratio.T + self.offset

    def joint_positions(self, theta: np.ndarray) -> np.ndarray:
        """q (n, k) [rad] from motor positions theta (n, k) [rad]. A diagonal R is applied per joint
        as q = theta * (1/r) + (-theta0/r), the offset added only where theta0 is not zero: the
        arithmetic of a column's ``scale`` and ``offset`` in a mapping (fricli.robot.mapping)."""
        if self.is_diagonal:
            d = np.diag(self.ratio)
            q = theta * (1.0 / d)
            off = -self.offset / d
            return np.where(off != 0, q + off, q)
        return np.linalg.solve(self.ratio, (theta - self.offset).T).T

    def motor_velocities(self, qd: np.ndarray) -> np.ndarray:
        """theta_d (n, k) [rad/s] (or accelerations) from joint velocities qd (n, k)."""
        return qd @ self.ratio.T

    def joint_velocities(self, theta_d: np.ndarray) -> np.ndarray:
        """qd (n, k) [rad/s] (or accelerations) from motor velocities theta_d (n, k) (a diagonal R:
        theta_d * (1/r))."""
        if self.is_diagonal:
            return theta_d * (1.0 / np.diag(self.ratio))
        return np.linalg.solve(self.ratio, theta_d.T).T

    def joint_torques(self, tau_motor: np.ndarray) -> np.ndarray:
        """tau (n, k) [Nm] = R^T tau_motor, from motor torques tau_motor (n, k) [Nm] (a diagonal R:
        tau_motor * r)."""
        if self.is_diagonal:
            return tau_motor * np.diag(self.ratio)
        return tau_motor @ self.ratio

    def motor_torques(self, tau: np.ndarray) -> np.ndarray:
        """tau_motor (n, k) [Nm] from joint torques tau (n, k) [Nm] (inverse of ``joint_torques``)."""
        return np.linalg.solve(self.ratio.T, tau.T).T

    # ----------------------------------------------------------------- inertia

    def reflected_inertia(self) -> np.ndarray:
        """R^T diag(J_m) R (k, k) [kg m^2]: the rotors' inertia seen at the joints."""
        return self.ratio.T @ (self.rotor_inertia[:, None] * self.ratio)

    def armature(self) -> np.ndarray:
        """The diagonal of ``reflected_inertia`` (k,) [kg m^2]: each joint's reflected rotor inertia."""
        return np.diag(self.reflected_inertia()).copy()

    def cross_inertia(self) -> np.ndarray:
        """The off-diagonal part of ``reflected_inertia`` (k, k) [kg m^2] (zero for a diagonal R)."""
        m = self.reflected_inertia()
        return m - np.diag(np.diag(m))

    def cross_torque(self, qdd: np.ndarray) -> np.ndarray:
        """Torque (n, k) [Nm] of the rotors' cross-inertia for joint accelerations qdd (n, k) [rad/s^2]:
        what a dynamics model with a diagonal armature leaves out of tau_dyn."""
        return qdd @ self.cross_inertia().T

    # ------------------------------------------------------------------ groups

    def groups(self) -> list[list[int]]:
        """Indices of the joints that share motors: the connected components of R's sparsity
        pattern (R + R^T != 0), each sorted, in the order of their first joint."""
        k = len(self.joints)
        linked = (self.ratio != 0) | (self.ratio.T != 0)
        seen = np.zeros(k, dtype=bool)
        out = []
        for start in range(k):
            if seen[start]:
                continue
            group, todo = [], [start]
            seen[start] = True
            while todo:
                i = todo.pop()
                group.append(i)
                for j in np.flatnonzero(linked[i] & ~seen):
                    seen[j] = True
                    todo.append(int(j))
            out.append(sorted(group))
        return out

    def coupled_groups(self) -> list[list[int]]:
        """The groups of more than one joint."""
        return [g for g in self.groups() if len(g) > 1]

    @property
    def is_diagonal(self) -> bool:
        return not np.any(self.ratio - np.diag(np.diag(self.ratio)))

    def sub(self, indices) -> "Transmission":
        """The transmission of the joints ``indices`` (a group: no motor links them to the others)."""
        idx = list(indices)
        return Transmission([self.joints[i] for i in idx], self.ratio[np.ix_(idx, idx)], self.offset[idx],
                            self.rotor_inertia[idx])

    # ------------------------------------------------------------ persistence

    def to_meta(self) -> dict:
        """A JSON-able record (joint names as text or integers, as given)."""
        return {"joints": list(self.joints), "ratio": self.ratio.tolist(), "offset": self.offset.tolist(),
                "rotor_inertia": self.rotor_inertia.tolist()}

    @classmethod
    def from_meta(cls, meta: dict) -> "Transmission":
        if not isinstance(meta, dict) or not {"joints", "ratio"} <= set(meta):
            raise ValueError("a transmission needs 'joints' and 'ratio'")
        return cls(meta["joints"], meta["ratio"], meta.get("offset"), meta.get("rotor_inertia"))

    def to_json(self) -> str:
        return json.dumps(self.to_meta())


def of_schema(metadata: dict | None) -> Transmission | None:
    """The transmission recorded in a log's schema metadata, or None; ValueError when damaged."""
    raw = (metadata or {}).get(META_KEY)
    if raw is None:
        return None
    try:
        return Transmission.from_meta(json.loads(raw))
    except (ValueError, TypeError) as exc:
        raise ValueError(f"damaged transmission record ({exc})") from None
