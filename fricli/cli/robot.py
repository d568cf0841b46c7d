"""fricli import: a robot's delimited text recording (+ URDF) -> a long-format Parquet log;
fricli dynamics: the URDF terms for a log that exists."""

from __future__ import annotations

import click

from fricli.cli import cli
from fricli.cli.options import Cutoff, Number, common, output_option, say, warn
from fricli.core.errors import LogError, ModelFileError


def _pairs(what: str, nonnegative: bool = False):
    """A callback turning repeated JOINT=VALUE options into {joint: value}; a malformed pair is
    a bad option (USAGE)."""
    def parse(ctx, param, pairs):
        from fricli.robot import mapping as mp

        try:
            return mp.parse_overrides(pairs, what, nonnegative=nonnegative)
        except LogError as exc:
            raise click.BadParameter(str(exc).removeprefix(f"{what}: "), ctx=ctx, param=param) from None
    return parse


def urdf_options(f):
    """--match, --rotor-inertia, --gravity, --payload-*, --hold, --cutoff: the robot model's options."""
    for option in reversed([
        click.option("--match", type=click.Choice(["name", "order"]), default=None,
                     help="How log joints match URDF joints (import: overrides the mapping's robot.match)."),
        click.option("--rotor-inertia", "inertia_pairs", multiple=True, metavar="JOINT=VALUE",
                     callback=_pairs("--rotor-inertia", nonnegative=True),
                     help="Reflected rotor inertia [kg m^2] added to the joint's mass-matrix diagonal. Repeatable."),
        click.option("--gravity", nargs=3, type=Number(), default=None, metavar="X Y Z",
                     help="Gravity in the URDF's base frame [m/s^2] (default 0 0 -9.81; import: the mapping's if given; "
                          "dynamics: the one the log's tau_g was computed with, if recorded)."),
        click.option("--payload-mass", type=Number(min=0), default=None, help="Known payload mass [kg]."),
        click.option("--payload-com", nargs=3, type=Number(), default=None, metavar="X Y Z",
                     help="Payload centre of mass [m] in the payload frame (default 0 0 0)."),
        click.option("--payload-frame", default=None, help="URDF frame (link) that carries the payload."),
        click.option("--hold", "held", multiple=True, metavar="JOINT",
                     help="A URDF joint the log does not record (a gripper's finger), held at its zero position: "
                          "its links move with their parent (joints that mimic it too). Repeatable; import: adds "
                          "to the mapping's robot.hold."),
        click.option("--cutoff", type=Cutoff(), default=None, metavar="HZ|auto",
                     help="Low-pass cut-off [Hz] used when qd/qdd are derived for the robot model, or auto: the "
                          "one of 2 Hz to the Nyquist frequency with which the robot model explains tau_m best "
                          "(default: auto when every joint has tau_m or i_m, else the log contract's 50 Hz)."),
    ]):
        f = option(f)
    return f


def _derived_text(record: dict) -> str:
    derived = record["derived"]
    if not derived:
        return ""
    lowpass = f"low-pass {derived['cutoff_hz']:g} Hz" if derived["filtered"] else "no low-pass"
    chosen = " chosen from the data" if "cutoff_choice" in derived else ""
    return f", derived {' and '.join(derived['columns'])} ({lowpass}{chosen}, central differences)"


def _choice_line(record: dict) -> str | None:
    """What the cut-off was chosen from (``choose_cutoff``), for stderr; None when none was chosen."""
    choice = (record.get("derived") or {}).get("cutoff_choice")
    if not choice:
        return None
    grid, score = choice["candidates_hz"], choice["score"]
    best = grid.index(choice["cutoff_hz"])

    def named(k):
        return "no low-pass" if k == len(grid) - 1 else f"{grid[k]:g} Hz"

    default = min(range(len(grid)), key=lambda k: abs(grid[k] - min(choice["default_hz"], grid[-1])))
    others = ", ".join(f"{named(k)} x{score[k] / score[best]:.2f}" for k in sorted({0, default, len(grid) - 1} - {best}))
    return (f"cut-off of the derived columns: {named(best)}, chosen of {grid[0]:g} Hz to no low-pass (--cutoff HZ sets "
            f"one): the robot model's tau_dyn with a gain per joint and each joint's linear friction leave the least "
            f"of tau_m - tau_g in motion, {score[best]:.4g} Nm RMS (geometric mean over the joints, {choice['rows']:,} "
            f"rows); {others}")


def _robot_notes(record: dict | None, name: str) -> list[str]:
    """The stderr lines on how the robot terms were computed: joints unwrapped, the cut-off chosen."""
    if not record:
        return []
    out = []
    if record.get("unwrapped"):
        joints = record["unwrapped"]
        out.append(f"note: {name}: the position of joint{'s' if len(joints) > 1 else ''} {', '.join(joints)} "
                   "jumps by a turn where it wraps: qd and qdd are derived from it unwrapped (q is kept as recorded)")
    if _choice_line(record):
        out.append(_choice_line(record))
    return out


def urdf_joint_names(pairs) -> dict[str, str]:
    """--urdf-joint JOINT=NAME pairs as {log joint: URDF joint name}."""
    names = {}
    for pair in pairs:
        joint, sep, urdf_name = pair.partition("=")
        if not sep or not joint or not urdf_name:
            raise click.UsageError(f"--urdf-joint: expected JOINT=NAME, got {pair!r}")
        names[joint] = urdf_name
    return names

@cli.command("import")
@click.argument("recordings", nargs=-1, required=True, metavar="RECORDING...")
@click.option("--mapping", "mapping_path", default=None, metavar="MAP.toml",
              help="Which column holds what (docs/robot-import.md; docs/ur10e-mapping.toml is an example). "
                   "Required for a text recording; for a ROS bag it says what the effort is and which joints.")
@click.option("--topic", default=None, metavar="TOPIC",
              help="ROS bag: the sensor_msgs/JointState topic (default: the bag's only one).")
@click.option("--kt", "kt_pairs", multiple=True, metavar="JOINT=VALUE", callback=_pairs("--kt"),
              help="Drive gain [Nm/A] of a joint (torque constant x gear ratio); overrides the mapping. Repeatable.")
@click.option("--urdf", default=None, metavar="ROBOT.urdf",
              help="Add tau_g and tau_dyn from this robot description (needs Pinocchio: pip install 'fricli[robot]').")
@urdf_options
@click.option("--drop-backward", is_flag=True,
              help="Drop rows whose time goes back a little (reported) instead of refusing the recording.")
@click.option("--template", is_flag=True,
              help="Write a skeleton mapping (TOML) from RECORDING's first line and --urdf's joints to -o, "
                   "instead of importing.")
@output_option(help="Output Parquet log (- for stdout).")
@common
def import_cmd(recordings, mapping_path, topic, kt_pairs, urdf, match, inertia_pairs, gravity, payload_mass,
               payload_com, payload_frame, held, cutoff, drop_backward, template, output, quiet):
    """Import a robot's delimited text recording or ROS bag as one long-format log.

    RECORDING is a CSV (or other delimited) text file, - for stdin, several text files that the
    mapping joins row by row (its 'files', e.g. motor positions and motor torques), or a ROS bag (a rosbag2
    folder in MCAP or sqlite3 storage, or a ROS 1 .bag file: needs pip install 'fricli[ros]').
    For a text file the mapping says which column is the time and, per joint, which are q, qd,
    i_m or tau_m, with units and drive gains; a bag's sensor_msgs/JointState messages name their
    joints and give position, velocity and effort. Malformed rows, garbage rows (implausible
    magnitudes, rows of zeros, spikes of one or two samples, time outside the longest consistent
    stretch), a truncated last line and repeated time steps are dropped and reported on stderr;
    time going back a little inside the recording is refused unless --drop-backward.

    \b
    Example:
      fricli import run.csv --mapping docs/ur10e-mapping.toml -o run.parquet
      fricli import run.csv --mapping docs/ur10e-mapping.toml --urdf ur10e.urdf -o run.parquet
      fricli import load.csv --mapping docs/ur10e-mapping.toml --urdf ur10e.urdf \\
          --payload-mass 2.805 --payload-com 0 0 0.05 --payload-frame tool0 -o load.parquet
      fricli import rosbag2_2026_01_01-12_00_00 --urdf robot.urdf -o run.parquet
      fricli import positions.csv torques.csv --mapping wrist.toml -o arm.parquet   # motor side, docs/drives.md
    """
    from fricli.core.logs import read_bytes
    from fricli.robot import importing

    recording = recordings[0]
    if template:
        from fricli.core import files
        from fricli.core.atomic import atomic_write_bytes
        from fricli.robot.template import skeleton

        if urdf is None:
            raise click.UsageError("--template needs --urdf ROBOT.urdf (the joints of the mapping)")
        urdf_data = files.read_bytes(urdf, ModelFileError, "URDF file", "URDF file")
        text = skeleton(read_bytes(recording), "stdin" if recording == "-" else recording,
                        urdf_data.decode("utf-8", "replace"), urdf)
        if output == "-":
            click.echo(text, nl=False)
        else:
            atomic_write_bytes(output, text.encode())
            say(f"wrote a skeleton mapping for {urdf} -> {output}: fill in and check it (docs/robot-import.md)", quiet)
        return
    result = importing.import_log(list(recordings), mapping_path, output=output, urdf=urdf, topic=topic,
                                  kt=kt_pairs, rotor_inertia=inertia_pairs, match=match, gravity=gravity,
                                  payload_mass=payload_mass, payload_com=payload_com, payload_frame=payload_frame,
                                  held=held, cutoff_hz=cutoff, drop_backward=drop_backward)
    for level, line in result.notices:
        if level == "warning":
            warn(line)
        else:
            say(line, quiet)
    robot = result.meta["robot"]
    extra = ""
    if robot:
        extra = f", tau_g and tau_dyn from {urdf} (joints matched by {robot['match']}{_derived_text(robot)})"
    where = "stdout" if output == "-" else output
    rows = f"{result.meta['rows']:,} {'messages' if result.meta['counted_in'] == 'message' else 'rows'}"
    name = result.name
    for line in _robot_notes(robot, name):
        say(line, quiet)
    for finding in (robot or {}).get("mapping_check", {}).get("findings", []):
        warn(f"warning: {name}: the mapping disagrees with {urdf}: {finding['message']}")
    say(f"imported {rows} x {len(result.mapping.joints)} joints from {result.source}{extra} -> {where}", quiet)


@cli.command("dynamics")
@click.argument("log")
@click.option("--urdf", required=True, metavar="ROBOT.urdf",
              help="Robot description (needs Pinocchio: pip install 'fricli[robot]').")
@click.option("--urdf-joint", "urdf_pairs", multiple=True, metavar="JOINT=NAME",
              help="The URDF joint of a log joint, with --match name (default: the log joint's name). Repeatable.")
@urdf_options
@output_option(help="Output Parquet log (- for stdout).")
@common
def dynamics_cmd(log, urdf, urdf_pairs, match, inertia_pairs, gravity, payload_mass, payload_com, payload_frame,
                 held, cutoff, output, quiet):
    """Add tau_g and tau_dyn from a URDF to a long-format log of all joints of a robot.

    Every moving joint of the URDF must be in the log, all sampled at the same times; qd and
    qdd come from the log or are derived as the log contract derives them. Existing tau_g and
    tau_dyn columns are replaced. See docs/robot-import.md.

    \b
    Example:
      fricli dynamics run.parquet --urdf ur10e.urdf --match order --rotor-inertia 2=3.7434 -o run2.parquet
    """
    from fricli.robot.logterms import add_dynamics

    _, record = add_dynamics(log, urdf, output, match=match, urdf_joints=urdf_joint_names(urdf_pairs),
                             rotor_inertia=inertia_pairs, gravity=gravity, payload_mass=payload_mass,
                             payload_com=payload_com, payload_frame=payload_frame, held=held, cutoff_hz=cutoff)
    name = "stdin" if log == "-" else log
    where = "stdout" if output == "-" else output
    for line in _robot_notes(record, name):
        say(line, quiet)
    pairs = ": " + ", ".join(f"{j}={u}" for j, u in record["joints"].items()) if match == "order" else ""
    say(f"added tau_g and tau_dyn from {urdf} to {len(record['joints'])} joints of {name} "
        f"(matched by {match}{pairs}{_derived_text(record)}) -> {where}", quiet)
