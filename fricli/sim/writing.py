"""``simulate_log``: ``fricli simulate`` (a log file, or a fleet's folder) as one call."""

from __future__ import annotations

import numpy as np

from fricli.sim.simulator import LOADS, SCENARIOS, resolve_effects, simulate, write


def _fleet_size(value) -> tuple[int, int, int]:
    try:
        sizes = tuple(int(v) for v in value.lower().split("x")) if isinstance(value, str) else tuple(value)
    except (TypeError, ValueError):
        sizes = ()
    if len(sizes) != 3 or not all(isinstance(s, (int, np.integer)) for s in sizes) or min(sizes) < 1:
        raise _option_error(f"expected ROBOTSxJOINTSxDAYS like 40x6x1, got {value!r}", "fleet")
    return tuple(int(s) for s in sizes)


def _option_error(message: str, option: str):
    from fricli.fitting.optionspec import OptionError

    return OptionError(message, option)


def simulate_log(output: str, *, scenario: str = "base", joint: int = 2, load: str = "none", effects=(),
                 seed: int = 0, rate: float | None = None, duration: float | None = None,
                 friction_state: str | None = None, thin: bool = False, fleet=None, wearing: int = 0,
                 contacts=(), map_fn=None):
    """``fricli simulate -o OUTPUT``: ``simulate``'s log (keywords as there; ``effects`` the --effect
    values, ``contacts`` the --contact ones as (start [s], torque [Nm], duration [s])) written to the
    Parquet file ``output`` (- for stdout); ``rate`` [Hz] defaults to 100. With ``fleet`` (R, J, D) or
    "RxJxD": R robots x J joints x D days of daily checks, ``wearing`` of the joints wearing, into the
    new folder ``output`` with its manifest (``fricli.sim.fleet``; ``rate`` defaults to its
    DEFAULT_RATE; ``map_fn`` runs the logs, default a process pool). Returns the log's table, or
    the fleet's joints. OptionError naming a wrong option or options that do not go together."""
    checks = (("scenario", scenario, SCENARIOS), ("load", load, LOADS),
              ("friction_state", friction_state, (None, "base", "shifted")))
    for option, value, allowed in checks:
        if value not in allowed:
            raise _option_error(f"simulate option {option}: expected one of "
                                f"{', '.join(str(a) for a in allowed if a)}, got {value!r}", option)
    if str(joint) not in ("2", "4") or isinstance(joint, bool):
        raise _option_error(f"simulate option joint: expected 2 or 4, got {joint!r}", "joint")
    for option, value, low in (("seed", seed, 0), ("wearing", wearing, 0)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < low:
            raise _option_error(f"simulate option {option}: expected a whole number >= {low}, got {value!r}", option)
    for option, value, low, high in (("rate", rate, 1.0, 10000.0), ("duration", duration, 10.0, 36000.0)):
        if value is not None and (isinstance(value, bool) or not isinstance(value, (int, float))
                                  or not low <= value <= high):
            raise _option_error(f"simulate option {option}: expected a number from {low:g} to {high:g}, got "
                                f"{value!r}", option)
    try:
        effects = resolve_effects(effects)
    except ValueError as exc:
        raise _option_error(str(exc), "effects") from None
    if fleet is not None:
        size = _fleet_size(fleet)
        if contacts:
            raise _option_error("contacts do not apply to a fleet", "contacts")
        daily = (("scenario", scenario, "base"), ("joint", str(joint), "2"), ("load", load, "none"),
                 ("effects", effects, []), ("duration", duration, None), ("friction_state", friction_state, None),
                 ("thin", thin, False))
        given = [name for name, value, default in daily if value != default]
        if given:
            raise _option_error(f"{given[0]} does not apply to a fleet (it simulates daily checks)", given[0])
        if output == "-":
            raise _option_error("a fleet is written into a folder, not to stdout", "output")
        return _simulate_fleet(output, size, wearing, seed, rate, map_fn)
    for option, value, applies in (("wearing", wearing, False), ("duration", duration, scenario == "extended"),
                                   ("thin", thin, scenario == "base")):
        if value and not applies:
            where = {"wearing": "a fleet", "duration": "the extended scenario", "thin": "the base scenario"}[option]
            raise _option_error(f"{option} applies to {where} only", option)
    try:
        table = simulate(scenario, int(joint), load=load, effects=effects, seed=seed,
                         rate=100.0 if rate is None else rate, duration=duration, friction_state=friction_state,
                         thin=thin, contacts=tuple(contacts))
    except ValueError as exc:
        if not contacts or "contact" not in str(exc):
            raise
        raise _option_error(str(exc), "contacts") from None
    write(table, output)
    return table


def _simulate_fleet(output: str, size: tuple, wearing: int, seed: int, rate: float | None, map_fn):
    import concurrent.futures
    import os

    from fricli.sim import fleet

    robots, joints_per_robot, days = size
    rate = fleet.DEFAULT_RATE if rate is None else rate
    kwargs = {"robots": robots, "joints_per_robot": joints_per_robot, "days": days, "wearing": wearing, "seed": seed,
              "rate": rate}
    if map_fn is not None:
        return fleet.simulate_fleet(output, map_fn=map_fn, **kwargs)
    with concurrent.futures.ProcessPoolExecutor(max_workers=os.cpu_count() or 1) as pool:
        return fleet.simulate_fleet(output, map_fn=lambda f, tasks: pool.map(f, tasks, chunksize=8), **kwargs)
