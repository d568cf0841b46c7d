"""A physics simulator of a harmonic-drive robot joint that writes fricli logs.

    from fricli.sim import simulate, true_params
    table = simulate("base", joint=2, seed=1)            # pyarrow table, log contract
    params = true_params(2, "base")                       # the friction it was made with

Scenarios (``base``, ``extended``, ``adapt``), joints, effects and the physics are described
in docs/simulator.md.
"""

from fricli.sim.effects import EFFECTS
from fricli.sim.joints import JOINTS
from fricli.sim.simulator import LOADS, SCENARIOS, metadata, simulate, true_params

__all__ = ["EFFECTS", "JOINTS", "LOADS", "SCENARIOS", "metadata", "simulate", "true_params"]
