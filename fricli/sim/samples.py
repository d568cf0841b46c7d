"""The bundled sample logs: how each file in sample_data/ is made."""

from __future__ import annotations

import os

SAMPLES = {
    f"joint{j}_{name}": dict(scenario=scenario, joint=j, load=load, seed=seed)
    for j in (2, 4)
    for name, scenario, load, seed in (
        ("base", "base", "none", 1),
        ("extended_none", "extended", "none", 2),
        ("extended_sym", "extended", "sym", 3),
        ("extended_asym", "extended", "asym", 4),
        ("adapt", "adapt", "none", 5),
    )
}


def sample_path(folder: str, name: str) -> str:
    """Path of sample ``name`` in ``folder``, simulating it there first if it is missing."""
    from fricli.sim.simulator import simulate, write

    path = os.path.join(folder, f"{name}.parquet")
    if not os.path.exists(path):
        os.makedirs(folder, exist_ok=True)
        write(simulate(**SAMPLES[name]), path)
    return path
