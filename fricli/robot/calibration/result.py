"""A calibration's result: the identified parameters with the layout they were fitted in."""

from __future__ import annotations

import dataclasses

import numpy as np

from fricli.robot.calibration.motion import reflected


@dataclasses.dataclass
class Calibration:
    """The identified parameters and the report (plain JSON types)."""

    x: np.ndarray              # every parameter, (14 or 15 * joints,): inertial, armature, friction (, Fs - Fc)
    x0: np.ndarray             # the prior's centre (CAD, prior armature, zero friction)
    names: list[str]
    bodies: list[str]
    joints: list[str]          # URDF joints
    report: dict
    ratio: np.ndarray | None = None   # R (joints, joints) of ``motor_layout``; None: one rotor per joint
    motors: list[int] | None = None   # URDF indices of the joints whose motors a transmission gives
    payload: np.ndarray | None = None   # (10 * joints,) a declared payload in each body: not the URDF's
    attached: list | None = None        # per body, the links with an inertia fixed to its moving link
    attached_cad: np.ndarray | None = None   # (10 * joints,) their CAD parameters, summed in the joint frame

    def links(self, x: np.ndarray | None = None) -> np.ndarray:
        """What the URDF's links of each body hold (10 * joints,): the body less a declared payload."""
        pi = (self.x if x is None else x)[:10 * len(self.joints)]
        return pi if self.payload is None else pi - self.payload

    def armature(self, x: np.ndarray | None = None) -> np.ndarray:
        """Each joint's reflected rotor inertia (joints,) [kg m^2]: the diagonal of R^T diag(J_m) R."""
        nj = len(self.joints)
        rotor = (self.x if x is None else x)[10 * nj:11 * nj]
        return rotor.copy() if self.ratio is None else np.diag(reflected(self.ratio, rotor)).copy()

    def motor_of(self, j: int) -> str:
        """How the report names the rotor of URDF joint index ``j``."""
        return f"motor of joint {self.joints[j]}" if j in (self.motors or ()) else f"joint {self.joints[j]}"
