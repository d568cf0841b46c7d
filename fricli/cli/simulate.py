"""fricli simulate."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.cli.options import Number, bad_parameter, common, say
from fricli.sim import effects as fx
from fricli.sim import fleet
from fricli.sim import simulator

_EFFECT_HELP = "; ".join(f"{name} [{fx.EFFECTS[name].unit}]" for name in sorted(fx.EFFECTS))


def _effects(ctx, param, values):
    try:
        return simulator.resolve_effects(values)
    except ValueError as exc:
        raise click.BadParameter(str(exc), ctx=ctx, param=param) from None


def _contacts(ctx, param, values):
    from fricli.core.errors import OptionError
    from fricli.sim.writing import contact_of

    try:
        return tuple(contact_of(value) for value in values)
    except OptionError as exc:
        raise click.BadParameter(str(exc), ctx=ctx, param=param) from None


def _fleet_size(ctx, param, value):
    if value is None:
        return None
    try:
        sizes = tuple(int(v) for v in value.lower().split("x"))
    except ValueError:
        sizes = ()
    if len(sizes) != 3 or min(sizes) < 1:
        raise click.BadParameter(f"expected ROBOTSxJOINTSxDAYS like 40x6x1, got {value!r}", ctx=ctx, param=param)
    return sizes


@cli.command("simulate")
@click.option("--scenario", type=click.Choice(simulator.SCENARIOS), default="base", show_default=True,
              help="base: constant-velocity sweeps (warm joint); extended: simultaneous motion, new "
                   "friction state (~2 min); adapt: one out-and-back movement at one velocity (<60 s); daily: a short check, every velocity level out and back (~70 s).")
@click.option("--joint", type=click.Choice(["2", "4"]), default="2", show_default=True, help="Joint preset.")
@click.option("--load", type=click.Choice(simulator.LOADS), default="none", show_default=True,
              help="External payload measured as tau_ext (not in tau_g): sym zero-mean, asym one-sided.")
@click.option("--effect", "effect_specs", multiple=True, metavar="NAME[=STRENGTH]", callback=_effects,
              help=f"Add an undeclared effect (repeatable): {_EFFECT_HELP}; named as fricli diagnose names what it "
                   f"finds; the older names are accepted ({', '.join(f'{a} for {n}' for a, n in fx.ALIASES.items())}). "
                   "See docs/simulator.md.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True, help="Random seed.")
@click.option("--rate", type=Number(min=1.0, max=10000.0), default=100.0, show_default=True,
              help="Output sample rate [Hz] (friction is integrated at >= 1 kHz); with --fleet the default is "
                   f"{fleet.DEFAULT_RATE:g}.")
@click.option("--duration", type=Number(min=10.0, max=36000.0), default=None,
              help="Length of the extended scenario [s] (default 120).")
@click.option("--friction-state", type=click.Choice(["base", "shifted"]), default=None,
              help="Friction state: base (warm, an exact extended LuGre model) or shifted (cold, "
                   "quadrant and direction dependence). Default: base for --scenario base, else shifted.")
@click.option("--thin", is_flag=True,
              help="base scenario: each slow level (< 0.1 rad/s) one short stretch at a random position, "
                   "so it meets one narrow band of gravity torques.")
@click.option("--fleet", "fleet_size", callback=_fleet_size, metavar="RxJxD", default=None,
              help="Simulate a fleet of R robots x J joints x D days of daily-check logs into the folder -o, "
                   "with a manifest for fricli fleet (see docs/fleet.md).")
@click.option("--wearing", type=click.IntRange(min=0), default=0, show_default=True,
              help="--fleet: joints whose Coulomb and viscous friction grow over the days.")
@click.option("--contact", "contacts", multiple=True, callback=_contacts,
              metavar="START,TORQUE,DURATION",
              help="An external torque of TORQUE [Nm] from START for DURATION [s] (repeatable): the joint keeps "
                   "its path, the motor torque takes the push, tau_ext holds it (docs/simulator.md, Contacts).")
@click.option("-o", "--output", required=True, help="Output Parquet log (- for stdout); with --fleet a folder.")
@common
def simulate_cmd(scenario, joint, load, effect_specs, seed, rate, duration, friction_state, thin, fleet_size, wearing,
                 contacts, output, quiet):
    """Simulate a log of a harmonic-drive robot joint with known friction.

    The log holds t, joint, q, qd, qdd, tau_m (with noise), tau_g, tau_dyn, tau_ext, temp and
    the noise-free friction tau_f_true; the scenario, seed and true parameters are stored in
    the Parquet schema metadata (key fricli.sim). The same arguments give the same file.

    \b
    Example:
      fricli simulate --scenario base --joint 2 --seed 1 -o base.parquet
      fricli simulate --scenario extended --load asym --effect position --effect drift=0.5 -o ext.parquet
      fricli simulate --scenario adapt -o - | fricli predict lugre.npz - -o pred.parquet
    """
    from fricli.fitting.optionspec import OptionError
    from fricli.sim.writing import simulate_log

    def simulated(**kwargs):
        try:
            return simulate_log(output, **kwargs)
        except OptionError as exc:
            raise bad_parameter(exc, {"contacts": "--contact", "effects": "--effect", "output": "-o"}) from None

    ctx = click.get_current_context()
    if fleet_size is not None:
        # simulate_log refuses values other than the defaults; an option given at its default is refused here
        given = [f"--{p.replace('_', '-')}" for p in ("scenario", "joint", "load", "effect_specs", "duration",
                                                        "friction_state", "thin")
                 if ctx.get_parameter_source(p) is not click.core.ParameterSource.DEFAULT]
        if given:
            raise click.UsageError(f"{given[0].replace('-specs', '')} does not apply to --fleet (it simulates daily "
                                   "checks)")
        if ctx.get_parameter_source("rate") is click.core.ParameterSource.DEFAULT:
            rate = None
        joints = simulated(seed=seed, rate=rate, fleet=fleet_size, wearing=wearing, contacts=contacts)
        robots, joints_per_robot, days = fleet_size
        wear = ", ".join(f"{j.robot}/{j.number}" for j in joints if j.wears) or "none"
        say(f"simulated a fleet of {robots} robot{'s' * (robots != 1)} x {joints_per_robot} joint"
            f"{'s' * (joints_per_robot != 1)} x {days} day{'s' * (days != 1)} "
            f"({robots * joints_per_robot * days} logs, seed {seed}) -> {output}/fleet.toml; wearing: {wear}", quiet)
        return
    table = simulated(scenario=scenario, joint=int(joint), load=load, effects=effect_specs, seed=seed, rate=rate,
                      duration=duration, friction_state=friction_state, thin=thin, contacts=contacts, wearing=wearing)
    t = table.column("t")
    names = ", ".join(name if s is None else f"{name}={s:g}" for name, s in effect_specs) or "no effects"
    where = "stdout" if output == "-" else output
    say(f"simulated {'thin ' if thin else ''}{scenario} joint {joint} (load {load}, {names}, seed {seed}): {table.num_rows} rows, "
        f"{t[-1].as_py() - t[0].as_py():.1f} s at {rate:g} Hz -> {where}", quiet)
