"""The names of the effects a friction model may lack: one name per effect in every layer.

The simulator adds effects by these names (``fricli simulate --effect``, ``fricli.sim.effects``),
the diagnosis finds them by them (``fricli diagnose --effects``, ``fricli.fitting.diagnosis``), and
an augmented model stores the names of the effects it adds in its model file
(``fricli.models.augmented``: ``effects``, ``errors``, the keys of ``params``), which the exported
C repeats in its header. The names below are the only ones; an effect of an extra log column is
``column:NAME``. Older names (``ALIASES``) are still accepted where a name is read: the simulator's
effects, the effects the diagnosis is asked to test (``fricli.fitting.diagnosis.effects.library``),
a model file.
"""

from __future__ import annotations

OFFSET = "offset"
LEVEL = "level"
DIRECTION = "direction"
TEMPERATURE = "temperature"
DRIFT = "drift"
ACCELERATION = "acceleration"
LOAD = "load"
PAYLOAD = "payload"
GRAVITY = "gravity"
QUADRANT = "quadrant"
VELOCITY = "velocity"
POSITION = "position"
COLUMN = "column"
COUPLING = "coupling"
DISTURBANCE = "disturbance"
HYSTERESIS = "hysteresis"

#: every effect's name -> what it is (in any layer that knows it)
EFFECTS = {
    OFFSET: "a constant bias in the measured torque",
    LEVEL: "the Coulomb and viscous levels changed as a whole",
    DIRECTION: "friction that differs between the two directions of motion",
    TEMPERATURE: "friction that changes with the temperature",
    DRIFT: "friction that changes over the log (wear)",
    ACCELERATION: "a torque in the acceleration: an inertia missing or wrong in tau_dyn",
    LOAD: "Coulomb friction growing with the gravity load on the gear",
    PAYLOAD: "friction growing with a load the robot model's tau_g lacks (a payload)",
    GRAVITY: "the robot model's gravity torque off by a factor",
    QUADRANT: "friction that differs between driving and back-driven motion",
    VELOCITY: "a viscous curve of another shape than linear",
    POSITION: "friction periodic in the position (gear ripple)",
    COLUMN: "friction that follows an extra column of the log (column:NAME)",
    COUPLING: "friction that moves with the joints sharing a motor",
    DISTURBANCE: "a periodic disturbance torque in tau_m",
    HYSTERESIS: "friction with memory (Maxwell-slip elements)",
}

#: older names -> the name they stand for
ALIASES = {"ripple": POSITION, "asymmetry": DIRECTION, "inertia": ACCELERATION}

COLUMN_PREFIX = COLUMN + ":"


def canonical(name: str) -> str:
    """The registered name ``name`` stands for: an alias (``ALIASES``) replaced, any other name as it is."""
    return ALIASES.get(name, name)


def registered(name: str) -> bool:
    """Whether ``name`` is an effect's name (``EFFECTS``, or ``column:NAME``); an alias is not."""
    return name in EFFECTS or (name.startswith(COLUMN_PREFIX) and len(name) > len(COLUMN_PREFIX))
