"""fricli import: a robot's delimited text recording (+ URDF) -> a long-format Parquet log."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.cli.options import common, output_option, say, warn


@cli.command("import")
@click.argument("recording")
@click.option("--mapping", "mapping_path", required=True, metavar="MAP.toml",
              help="Which column holds what (docs/robot-import.md; docs/ur10e-mapping.toml is an example).")
@click.option("--kt", "kt_pairs", multiple=True, metavar="JOINT=VALUE",
              help="Drive gain [Nm/A] of a joint (torque constant x gear ratio); overrides the mapping. Repeatable.")
@click.option("--urdf", default=None, metavar="ROBOT.urdf",
              help="Add tau_g and tau_dyn from this robot description (needs Pinocchio: pip install 'fricli[robot]').")
@click.option("--match", type=click.Choice(["name", "order"]), default=None,
              help="How log joints match URDF joints (overrides the mapping's robot.match).")
@click.option("--rotor-inertia", "inertia_pairs", multiple=True, metavar="JOINT=VALUE",
              help="Reflected rotor inertia [kg m^2] added to the joint's mass-matrix diagonal. Repeatable.")
@click.option("--gravity", nargs=3, type=float, default=None, metavar="X Y Z",
              help="Gravity in the URDF's base frame [m/s^2] (default: the mapping's, else 0 0 -9.81).")
@click.option("--payload-mass", type=click.FloatRange(min=0), default=None, help="Known payload mass [kg].")
@click.option("--payload-com", nargs=3, type=float, default=None, metavar="X Y Z",
              help="Payload centre of mass [m] in the payload frame (default 0 0 0).")
@click.option("--payload-frame", default=None, help="URDF frame (link) that carries the payload.")
@click.option("--cutoff", type=click.FloatRange(min=0, min_open=True), default=None,
              help="Low-pass cut-off [Hz] used when qd/qdd are derived for the robot model (default: the log "
                   "contract's, 50 Hz).")
@click.option("--drop-backward", is_flag=True,
              help="Drop rows whose time goes back (reported) instead of refusing the recording.")
@output_option(help="Output Parquet log (- for stdout).")
@common
def import_cmd(recording, mapping_path, kt_pairs, urdf, match, inertia_pairs, gravity, payload_mass, payload_com,
               payload_frame, cutoff, drop_backward, output, quiet):
    """Import a robot's delimited text recording as one long-format log.

    RECORDING is a CSV (or other delimited) text file, - for stdin. The mapping says which
    column is the time and, per joint, which are q, qd, i_m or tau_m, with units and drive
    gains. Malformed rows, a truncated last line and repeated time steps are dropped and
    reported on stderr; time going back is refused unless --drop-backward.

    \b
    Example:
      fricli import run.csv --mapping docs/ur10e-mapping.toml -o run.parquet
      fricli import run.csv --mapping docs/ur10e-mapping.toml --urdf ur10e.urdf -o run.parquet
      fricli import load.csv --mapping docs/ur10e-mapping.toml --urdf ur10e.urdf \\
          --payload-mass 2.805 --payload-com 0 0 0.05 --payload-frame tool0 -o load.parquet
    """
    from fricli.logs import DEFAULT_CUTOFF_HZ, read_bytes, write_table
    from fricli.robot import mapping as mp
    from fricli.robot.importing import import_recording

    mapping = mp.load_mapping(mapping_path)
    payload_given = payload_mass is not None or payload_com is not None or payload_frame is not None
    if payload_given and payload_frame is None and mapping.payload is None:
        raise click.UsageError("--payload-mass/--payload-com need --payload-frame (or robot.payload in the mapping)")
    payload = mp.merge_payload(mapping.payload, payload_mass, payload_com, payload_frame) if payload_given else None
    mp.apply_overrides(mapping, kt=mp.parse_overrides(kt_pairs, "--kt"),
                       rotor_inertia=mp.parse_overrides(inertia_pairs, "--rotor-inertia", nonnegative=True),
                       match=match, gravity=gravity or None, payload=payload)
    model = None
    if urdf is not None:
        from fricli.robot.dynamics import load_model

        model = load_model(urdf, mapping)
    name = "stdin" if recording == "-" else recording
    result = import_recording(read_bytes(recording), mapping, name, model=model,
                              cutoff_hz=DEFAULT_CUTOFF_HZ if cutoff is None else cutoff,
                              drop_backward=drop_backward)
    for kind, d in result.meta["dropped"].items():
        warn(f"warning: {name}: dropped {d['count']} row{'s' if d['count'] != 1 else ''} with {d['what']} "
             f"(first at line {d['first_line']})")
    if result.meta["unterminated_last_line"]:
        say(f"note: {name}: the last line (line {result.meta['unterminated_last_line']}) has no line end; it is "
            "complete and kept", quiet)
    write_table(result.table, output)
    robot = result.meta["robot"]
    extra = ""
    if robot:
        derived = robot["derived"]
        lowpass = f"low-pass {derived['cutoff_hz']:g} Hz" if derived and derived["filtered"] else "no low-pass"
        how = f", derived {' and '.join(derived['columns'])} ({lowpass}, central differences)" if derived else ""
        extra = f", tau_g and tau_dyn from {urdf} (joints matched by {robot['match']}{how})"
    where = "stdout" if output == "-" else output
    say(f"imported {result.meta['rows']:,} rows x {len(mapping.joints)} joints from {name}{extra} -> {where}", quiet)
