"""A simulated fleet: N robots x joints x days of daily-check logs, some joints wearing.

Every joint gets its own friction (a joint preset scaled by factors drawn per joint); each day
its Coulomb, static and viscous friction vary by a few percent (``DAY_SD``), and on a wearing
joint Coulomb/static friction grow by ``rate_c`` and viscous friction by ``rate_v`` per day
(relative to the joint's own level) from an onset day on. The folder tree is

    FOLDER/ROBOT/jointJ/YYYY-MM-DD.parquet     one daily-check log per joint and day
    FOLDER/fleet.toml                          a manifest for ``fricli fleet``
    FOLDER/truth.json                          the true parameters and which joints wear
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import os

import numpy as np

from fricli.core import atomic
from fricli.core.errors import OutputError
from fricli.sim import joints, simulator

DAY_SD = 0.02              # day-to-day variation of the friction levels (relative sd)
SCALE_RANGE = (0.75, 1.25)  # per-joint scale of the preset friction
WEAR_RATE_C = (0.015, 0.03)  # growth of Coulomb/static friction on a wearing joint [1/day]
WEAR_RATE_V = (0.005, 0.015)  # growth of viscous friction [1/day]
DEFAULT_RATE = 50.0        # output rate of the daily-check logs [Hz]
_STREAM_FLEET = 1000


@dataclasses.dataclass(frozen=True)
class FleetJoint:
    """One joint of the fleet: its friction on day 0 and its wear (rates 0 when it does not wear)."""

    robot: str
    number: int
    preset: int
    scale_c: float
    scale_v: float
    onset: int = 0          # first day of wear
    rate_c: float = 0.0     # Coulomb/static growth [1/day]
    rate_v: float = 0.0     # viscous growth [1/day]

    @property
    def wears(self) -> bool:
        return self.rate_c > 0 or self.rate_v > 0

    def on_day(self, day: int, rng: np.random.Generator) -> joints.Joint:
        """The joint's true friction on ``day`` (0-based), with the day's variation from ``rng``."""
        p = joints.JOINTS[self.preset]
        worn = max(0, day - self.onset)
        c = self.scale_c * (1.0 + self.rate_c * worn) * (1.0 + DAY_SD * rng.standard_normal())
        v = self.scale_v * (1.0 + self.rate_v * worn) * (1.0 + DAY_SD * rng.standard_normal())
        return dataclasses.replace(p, number=self.number, fc=p.fc * c, fs=p.fs * c, fv=p.fv * v)


def plan(robots: int, joints_per_robot: int, *, wearing: int, days: int, seed: int) -> list[FleetJoint]:
    """The fleet's joints; ``wearing`` of them, chosen by ``seed``, wear from an onset day in the
    first half of the ``days`` (not before day 7)."""
    rng = np.random.default_rng([seed, _STREAM_FLEET])
    out = []
    for r in range(robots):
        for k in range(1, joints_per_robot + 1):
            preset = 2 if k <= (joints_per_robot + 1) // 2 else 4
            sc, sv = rng.uniform(*SCALE_RANGE, 2)
            out.append(FleetJoint(robot=f"robot{r + 1:03d}", number=k, preset=preset, scale_c=float(sc),
                                  scale_v=float(sv)))
    chosen = rng.choice(len(out), size=min(wearing, len(out)), replace=False)
    for i in sorted(int(c) for c in chosen):
        onset = int(rng.integers(min(7, days // 2), max(min(7, days // 2), days // 2) + 1))
        out[i] = dataclasses.replace(out[i], onset=onset, rate_c=float(rng.uniform(*WEAR_RATE_C)),
                                     rate_v=float(rng.uniform(*WEAR_RATE_V)))
    return out


def log_path(folder: str, robot: str, joint: int, date: dt.date) -> str:
    return os.path.join(folder, robot, f"joint{joint}", f"{date.isoformat()}.parquet")


MANIFEST = """\
# A simulated fleet (fricli simulate --fleet): every joint's daily-check logs, identified nightly.
[fleet]
history = "history"                  # Parquet dataset, one row per joint and log
models = "models"                    # models/ROBOT/jointJ/DATE.npz
pipeline = "identify"

[defaults]
logs = "{{robot}}/joint{{joint}}/*.parquet"
joints = [{joints}]

{robots}"""


def manifest_text(robot_names: list[str], joint_numbers: list[int]) -> str:
    robots = "\n".join(f'[[robot]]\nname = "{name}"\n' for name in robot_names)
    return MANIFEST.format(joints=", ".join(str(j) for j in joint_numbers), robots=robots)


def simulate_fleet(folder: str, *, robots: int = 4, joints_per_robot: int = 6, days: int = 1, wearing: int = 0,
                   seed: int = 0, rate: float = DEFAULT_RATE, start: dt.date = dt.date(2026, 1, 1),
                   map_fn=map) -> list[FleetJoint]:
    """Write the fleet's logs, manifest and truth under ``folder`` (new, or empty; OutputError
    otherwise); returns its joints.

    ``map_fn`` runs the per-log simulations (the built-in ``map``, or a pool's map)."""
    fleet = plan(robots, joints_per_robot, wearing=wearing, days=days, seed=seed)
    if os.path.isdir(folder) and os.listdir(folder):
        raise OutputError(f"{folder}: the folder exists and is not empty: simulate a fleet into a new folder")
    try:
        os.makedirs(folder, exist_ok=True)
    except OSError as exc:
        raise OutputError(f"cannot write {folder}: {exc.strerror or exc}") from None
    tasks = [(folder, fj, day, start, seed, rate) for fj in fleet for day in range(days)]
    truth_days = list(map_fn(_write_day, tasks))
    truth = {"seed": seed, "days": days, "start": start.isoformat(), "rate_hz": rate, "day_sd": DAY_SD,
             "joints": [dict(dataclasses.asdict(fj), wears=fj.wears) for fj in fleet],
             "daily": truth_days}
    atomic.atomic_write_bytes(os.path.join(folder, "truth.json"), json.dumps(truth, indent=1).encode())
    names = list(dict.fromkeys(fj.robot for fj in fleet))
    text = manifest_text(names, list(range(1, joints_per_robot + 1)))
    atomic.atomic_write_bytes(os.path.join(folder, "fleet.toml"), text.encode())
    return fleet


def _write_day(task) -> dict:
    folder, fj, day, start, seed, rate = task
    robot_index = int(fj.robot.removeprefix("robot"))
    rng = np.random.default_rng([seed, _STREAM_FLEET + 1, robot_index, fj.number, day])
    j = fj.on_day(day, rng)
    date = start + dt.timedelta(days=day)
    path = log_path(folder, fj.robot, fj.number, date)
    os.makedirs(os.path.dirname(path), exist_ok=True)
    sim_seed = int(rng.integers(2**31))
    simulator.write(simulator.simulate("daily", j, seed=sim_seed, rate=rate), path)
    return {"robot": fj.robot, "joint": fj.number, "date": date.isoformat(), "fc": j.fc, "fs": j.fs, "fv": j.fv}
