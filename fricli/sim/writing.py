"""``simulate_log``: ``fricli simulate`` (a log file, or a fleet's folder) as one call."""

from __future__ import annotations

import numpy as np

from fricli.fitting.optionspec import Option, OptionError, check_values
from fricli.sim.simulator import LOADS, SCENARIOS, resolve_effects, simulate, write

_SPEC = {o.name: o for o in (
    Option("scenario", "choice", choices=SCENARIOS), Option("load", "choice", choices=LOADS),
    Option("friction_state", "choice", choices=("base", "shifted")), Option("seed", "int", default=0, low=0),
    Option("wearing", "int", default=0, low=0), Option("rate", "float", low=1.0, high=10000.0),
    Option("duration", "float", low=10.0, high=36000.0))}


def _fleet_size(value) -> tuple[int, int, int]:
    try:
        sizes = tuple(int(v) for v in value.lower().split("x")) if isinstance(value, str) else tuple(value)
    except (TypeError, ValueError):
        sizes = ()
    if len(sizes) != 3 or not all(isinstance(s, (int, np.integer)) for s in sizes) or min(sizes) < 1:
        raise OptionError(f"expected ROBOTSxJOINTSxDAYS like 40x6x1, got {value!r}", "fleet")
    return tuple(int(s) for s in sizes)


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
    check_values({"scenario": scenario, "load": load, "friction_state": friction_state, "seed": seed,
                  "wearing": wearing, "rate": rate, "duration": duration}, _SPEC, "simulate")
    if str(joint) not in ("2", "4") or isinstance(joint, bool):
        raise OptionError(f"simulate option joint: expected 2 or 4, got {joint!r}", "joint")
    effects = (effects,) if isinstance(effects, str) else effects
    contacts = tuple(contact_of(c) for c in ((contacts,) if isinstance(contacts, str) else contacts))
    try:
        effects = resolve_effects(effects)
    except ValueError as exc:
        raise OptionError(str(exc), "effects") from None
    if fleet is not None:
        size = _fleet_size(fleet)
        if contacts:
            raise OptionError("contacts do not apply to a fleet", "contacts")
        daily = (("scenario", scenario, "base"), ("joint", str(joint), "2"), ("load", load, "none"),
                 ("effects", effects, []), ("duration", duration, None), ("friction_state", friction_state, None),
                 ("thin", thin, False))
        given = [name for name, value, default in daily if value != default]
        if given:
            raise OptionError(f"{given[0]} does not apply to a fleet (it simulates daily checks)", given[0])
        if output == "-":
            raise OptionError("a fleet is written into a folder, not to stdout", "output")
        return _simulate_fleet(output, size, wearing, seed, rate, map_fn)
    for option, value, applies in (("wearing", wearing, False), ("duration", duration, scenario == "extended"),
                                   ("thin", thin, scenario == "base")):
        if value and not applies:
            where = {"wearing": "a fleet", "duration": "the extended scenario", "thin": "the base scenario"}[option]
            raise OptionError(f"{option} applies to {where} only", option)
    try:
        table = simulate(scenario, int(joint), load=load, effects=effects, seed=seed,
                         rate=100.0 if rate is None else rate, duration=duration, friction_state=friction_state,
                         thin=thin, contacts=tuple(contacts))
    except ValueError as exc:
        if not contacts or "contact" not in str(exc):
            raise
        raise OptionError(str(exc), "contacts") from None
    _check_magnitudes(table, "contacts" if contacts else "effects")
    write(table, output)
    return table


def contact_of(value) -> tuple[float, float, float]:
    """A contact as (start [s], torque [Nm], duration [s]), from that or from "START,TORQUE,DURATION"
    (--contact); OptionError otherwise."""
    try:
        start, torque, length = (float(x) for x in (value.split(",") if isinstance(value, str) else value))
    except (TypeError, ValueError):
        raise OptionError(f"expected START,TORQUE,DURATION like 30,5,2, got {value!r}", "contacts") from None
    return start, torque, length


def _check_magnitudes(table, option: str) -> None:
    """OptionError when strengths so large (an --effect or --contact of 1e30) gave values that every
    command refuses as absurd (``logs.MAGNITUDE_LIMIT``): a log no command would read."""
    import pyarrow as pa

    from fricli.core.logs import MAGNITUDE_LIMIT

    for name, col in zip(table.column_names, table.columns):
        if pa.types.is_floating(col.type):
            top = float(np.max(np.abs(col.to_numpy()), initial=0.0))
            if not top <= MAGNITUDE_LIMIT:
                raise OptionError(f"the simulated {name!r} reaches {top:.3g}, beyond {MAGNITUDE_LIMIT:g}, which "
                                  "every command refuses: give smaller strengths", option)


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
