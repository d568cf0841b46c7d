"""The LuGre model at rest on a noisy measured velocity: how fast the held friction fades.

    python benchmarks/lugre_rest_noise.py

The simulated joint 2's LuGre parameters (``fricli.sim.joints``), 1 kHz: one second of sliding at
0.05 rad/s, then the joint held still while the velocity column carries zero-mean Gaussian noise
of standard deviation s. At rest dz/dt = v - sigma0 |v| / g z: the noise's mean is zero, its
magnitude is not, so the deflection, and with it the friction the model holds, decays with the
time constant tau = g / (sigma0 E|v|), E|v| = s sqrt(2 / pi). Printed: the friction held (mean
over 50 ms) at several times after the stop, that time constant, and the time the held friction
took to fall below 1/e of its value at the stop.
"""

from __future__ import annotations

import math

import numpy as np

from fricli.models.lugre import LuGreModel
from fricli.sim.joints import joint

RATE = 1000.0
SLIDE, SPEED, HOLD = 1.0, 0.05, 4.0
NOISE = (0.0, 1e-4, 3e-4, 1e-3)
AFTER = (0.1, 0.5, 1.0, 2.0)


def held(noise: float, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """(time after the stop [s], friction [Nm]) over the hold."""
    params = joint(2).lugre()
    n = int((SLIDE + HOLD) * RATE)
    t = np.arange(n) / RATE
    rest = t >= SLIDE
    qd = np.where(rest, rng.normal(0.0, noise, n) if noise else 0.0, SPEED)
    sig = {"t": t, "qd": qd, "qdd": np.gradient(qd, t), "tau_g": np.zeros(n)}
    tau_f = LuGreModel(**params).predict(sig)[0]
    return t[rest] - SLIDE, tau_f[rest]


def main() -> None:
    params = joint(2).lugre()
    rng = np.random.default_rng(0)
    print(f"simulated joint 2: Fs {params['fs']} Nm, sigma0 {params['sigma0']:g} Nm/rad; slid at {SPEED} rad/s, "
          f"then held for {HOLD:g} s at {RATE:g} Hz")
    print("| velocity noise s [rad/s] | " + " | ".join(f"held after {a:g} s [Nm]" for a in AFTER)
          + " | tau = Fs / (sigma0 s sqrt(2/pi)) [s] | measured 1/e time [s] |")
    print("|---|" + "---:|" * (len(AFTER) + 2))
    for s in NOISE:
        after, f = held(s, rng)
        window = [float(np.mean(f[(after >= a) & (after < a + 0.05)])) for a in AFTER]
        below = np.flatnonzero(np.abs(f) < abs(f[0]) / math.e)
        measured = f"{after[below[0]]:.2f}" if len(below) else f"> {HOLD:g}"
        tau = params["fs"] / (params["sigma0"] * s * math.sqrt(2 / math.pi)) if s else math.inf
        print(f"| {s:g} | " + " | ".join(f"{x:.2f}" for x in window)
              + f" | {tau:.2f} | {measured} |".replace("inf", "-"))


if __name__ == "__main__":
    main()
