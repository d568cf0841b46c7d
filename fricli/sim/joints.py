"""Joint presets: the true friction parameters and the rigid-body figures of the simulated joints.

Two harmonic-drive joints of a torque-controlled arm like the DLR-KUKA LWR-IV+: joint 2 (a
shoulder joint carrying most of the arm) and joint 4 (an elbow joint, about a third to a half of
the friction and a third of the gravity load). Friction parameters use the names of the LuGre
model kind (``fricli.models.lugre``), in rad, Nm, s, degC.
"""

from __future__ import annotations

import dataclasses

from fricli.core.errors import DataError

# Parameter -> unit, for the parameters written into a simulated log's metadata.
PARAM_UNITS = {
    "fc": "Nm", "fs": "Nm", "vs": "rad/s", "delta": "-", "fv": "Nm s/rad",
    "kc": "Nm/Nm", "ks": "Nm/Nm", "sigma0": "Nm/rad", "sigma1": "Nm s/rad",
    "t_ref": "degC", "alpha_c": "1/K", "alpha_v": "1/K",
    "temperature": "degC", "kq": "Nm/Nm", "fc_shift_pos": "Nm", "fc_shift_neg": "Nm",
    "inertia": "kg m^2", "gravity_amplitude": "Nm", "load_amplitude": "Nm",
    "noise_sd": "Nm", "ext_noise_sd": "Nm",
}

LUGRE_PARAMS = ("fc", "fs", "vs", "delta", "fv", "kc", "ks", "sigma0", "sigma1")


@dataclasses.dataclass(frozen=True)
class Joint:
    """One joint: friction in the warm base state, the shifted ("new dynamics") state, mechanics.

    Friction (base state, T = t_ref):
        Fc(tau_l) = fc + kc*tau_l,  Fs(tau_l) = fs + ks*tau_l,  tau_l = |tau_g - tau_ext| [Nm]
        tau_f     = sigma0*z + sigma1*dz/dt + fv*v   with the Stribeck curve g(v) (vs, delta)
    Temperature law: Fc(tau_l), Fs(tau_l) scaled by 1 - alpha_c*(T - t_ref), fv by
    exp(-alpha_v*(T - t_ref)).
    Shifted state (scenarios extended and adapt): temperature ``cold_temp``, plus, in the
    magnitude of the Coulomb and static levels, ``kq*tau_gear*sign(v)`` (the gear loses more when
    it drives the load than when the load back-drives it; tau_gear = tau_g - tau_ext) and a
    direction-dependent shift ``fc_shift_pos`` (v > 0) / ``fc_shift_neg`` (v < 0).
    """

    number: int
    fc: float                 # Coulomb friction [Nm]
    fs: float                 # static friction [Nm]
    vs: float                 # Stribeck velocity [rad/s]
    delta: float              # Stribeck exponent [-]
    fv: float                 # viscous friction [Nm s/rad]
    kc: float                 # load slope of Coulomb friction [Nm/Nm]
    ks: float                 # load slope of static friction [Nm/Nm]
    sigma0: float             # bristle stiffness [Nm/rad]
    sigma1: float             # bristle damping [Nm s/rad]
    t_ref: float              # warm (base) temperature [degC]
    alpha_c: float            # temperature coefficient of Coulomb/static friction [1/K]
    alpha_v: float            # temperature coefficient of viscous friction [1/K]
    cold_temp: float          # temperature of the shifted state [degC]
    kq: float                 # driving/back-driven slope of the shifted state [Nm/Nm]
    fc_shift_pos: float       # Coulomb shift of the shifted state for v > 0 [Nm]
    fc_shift_neg: float       # Coulomb shift of the shifted state for v < 0 [Nm]
    inertia: float            # link-side inertia J [kg m^2]
    gravity_amplitude: float  # tau_g = A*sin(q + phi) [Nm]
    load_amplitude: float     # external payload torque scale for --load sym/asym [Nm]
    noise_sd: float           # Gaussian noise on tau_m [Nm]
    ext_noise_sd: float       # Gaussian noise of the external torque sensor [Nm]
    q_min: float = -1.65      # position range used by the motions [rad]
    q_max: float = 1.65

    def lugre(self) -> dict[str, float]:
        """The extended LuGre parameters of the warm base state."""
        return {name: getattr(self, name) for name in LUGRE_PARAMS}


JOINTS = {
    2: Joint(number=2, fc=7.0, fs=9.0, vs=0.04, delta=1.2, fv=12.0, kc=0.04, ks=0.05,
             sigma0=2.0e4, sigma1=20.0, t_ref=38.0, alpha_c=0.01, alpha_v=0.01,
             cold_temp=28.0, kq=0.065, fc_shift_pos=1.2, fc_shift_neg=-0.5,
             inertia=3.0, gravity_amplitude=43.0, load_amplitude=8.0,
             noise_sd=0.25, ext_noise_sd=0.05),
    4: Joint(number=4, fc=3.0, fs=4.0, vs=0.05, delta=1.0, fv=5.0, kc=0.04, ks=0.05,
             sigma0=1.0e4, sigma1=10.0, t_ref=38.0, alpha_c=0.01, alpha_v=0.01,
             cold_temp=28.0, kq=0.1, fc_shift_pos=0.6, fc_shift_neg=-0.25,
             inertia=0.6, gravity_amplitude=13.0, load_amplitude=2.5,
             noise_sd=0.15, ext_noise_sd=0.03),
}

FRICTION_STATES = ("base", "shifted")


def joint(number: int) -> Joint:
    try:
        return JOINTS[int(number)]
    except (KeyError, ValueError):
        listed = ", ".join(str(j) for j in JOINTS)
        raise DataError(f"no simulated joint {number} (available: {listed})") from None


def state_params(j: Joint, state: str) -> dict[str, float]:
    """Temperature and the extra terms of a friction state (``base`` or ``shifted``)."""
    if state == "base":
        return {"temperature": j.t_ref, "kq": 0.0, "fc_shift_pos": 0.0, "fc_shift_neg": 0.0}
    if state == "shifted":
        return {"temperature": j.cold_temp, "kq": j.kq, "fc_shift_pos": j.fc_shift_pos,
                "fc_shift_neg": j.fc_shift_neg}
    raise DataError(f"unknown friction state {state!r} (use {' or '.join(FRICTION_STATES)})")
