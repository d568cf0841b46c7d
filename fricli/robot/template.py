"""A skeleton mapping (TOML) from a recording's first line and a URDF: ``fricli import --template``.

The URDF gives the joints that move (their names, order and kind); the recording's first line
gives the columns: a header names them, and a column whose name holds a signal's word (position,
q, velocity, qd, v, current, amps, i, torque, force, effort, tau) and a joint's number or URDF name is taken for
that signal of that joint, in the unit its name states (``q1_deg``, ``time_ms``, ``i_2_mA``) or
else the default of the joint's kind; a line of numbers only gives their count. Every guess is
marked; what cannot be guessed is left as a comment to fill in. The skeleton is a start to be checked, not a
mapping to trust: ``fricli import --urdf`` then checks the result against the robot model.
"""

from __future__ import annotations

import re
import xml.etree.ElementTree as ET

from fricli.core.errors import LogError, ModelFileError, one_line
from fricli.core.logs import CANONICAL, column_unit
from fricli.robot.recording import NUMBER

_WORDS = {  # signal: words in a column name, most specific first
    "q": ("position", "pos", "angle", "q"),
    "qd": ("velocity", "vel", "speed", "qd", "dq", "v"),
    "i_m": ("current", "cur", "amps", "amp", "i", "iq"),
    "tau_m": ("torque", "force", "effort", "tau", "trq"),
}
_TIME_WORDS = ("t", "time", "timestamp", "stamp")
# words of a commanded signal's column (``target_q_0`` beside ``actual_q_0``): taken only when no measured one fits
_COMMAND_WORDS = {"target", "desired", "des", "cmd", "command", "commanded", "ref", "reference", "setpoint", "goal"}
# a word of a column's name that states its unit -> the unit, per signal (the joint's kind picks among them)
_UNIT_WORDS = {
    "t": {"s": "s", "sec": "s", "secs": "s", "seconds": "s", "ms": "ms", "msec": "ms", "us": "us", "usec": "us",
          "ns": "ns", "nsec": "ns", "nanosec": "ns"},
    "q": {"rad": "rad", "deg": "deg", "degree": "deg", "degrees": "deg", "m": "m", "mm": "mm"},
    "qd": {"rad": "rad/s", "deg": "deg/s", "degree": "deg/s", "degrees": "deg/s", "dps": "deg/s", "m": "m/s",
           "mm": "mm/s"},
    "i_m": {"a": "A", "amp": "A", "amps": "A", "ampere": "A", "ma": "mA"},
    "tau_m": {"nm": "Nm", "n": "N"},
}


def urdf_joints(text: str, name: str) -> list[tuple[str, str]]:
    """The URDF's moving joints (not fixed), in the file's order: (name, "rotary" or "linear")."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as exc:
        raise ModelFileError(f"{name}: not a usable URDF ({exc})") from None
    joints = [(j.get("name"), "linear" if j.get("type") == "prismatic" else "rotary")
              for j in root.findall("joint") if j.get("type") not in (None, "fixed")]
    if not joints:
        raise ModelFileError(f"{name}: the URDF has no moving joint")
    return joints


def header_fields(data: bytes, name: str) -> tuple[list[str] | None, int, str]:
    """(column names or None when the first line holds numbers only, the number of columns, delimiter).
    Blank lines and '#' comment lines before it are passed over, as ``fricli import`` does; the
    last comment names the columns when the first line holds numbers and as many fields
    ('# t,q,tau', as ``numpy.savetxt`` writes it)."""
    lines = (ln.decode("utf-8", "replace").strip("\r\ufeff \t") for ln in data.split(b"\n", 400)[:400])
    comment, first = None, ""
    for first in lines:
        if first and not first.startswith("#"):
            break
        comment = first[1:].strip() if first else comment
        first = ""
    if not first:
        raise LogError(f"{name}: empty input, no first line to read the columns from")
    delimiter = max((",", ";", "\t", " "), key=first.count)
    split = (lambda text: text.split()) if delimiter == " " else (lambda text: text.split(delimiter))  # noqa: E731
    fields = [f.strip().strip('"') for f in split(first)]
    number = re.compile(NUMBER)   # a field of numbers, as the import reads it
    if all(number.fullmatch(f) for f in fields if f):
        named = [f.strip().strip('"') for f in split(comment or "")]
        if len(named) == len(fields) > 1 and not any(number.fullmatch(f) for f in named):
            return named, len(fields), delimiter
        return None, len(fields), delimiter
    return fields, len(fields), delimiter


def _tokens(field: str) -> list[str]:
    return [t for t in re.split(r"[^a-z0-9]+|(?<=[a-z])(?=[0-9])", field.lower()) if t]


def _first_number(fields: list[str]) -> int:
    """0 when the columns that name a signal count the joints from 0 (``actual_q_0``, as Universal
    Robots' RTDE recorder writes them, ``position[0]``), else 1."""
    words = {w for ws in _WORDS.values() for w in ws}
    return 0 if any("0" in tokens and words & set(tokens) for tokens in map(_tokens, fields)) else 1


def _guess(fields: list[str], signal: str, k: int, joint: str, first: int = 1) -> int | None:
    """The 1-based column of ``signal`` of the k-th joint (1-based; counted from ``first`` in the
    names), or None; a measured signal before a commanded one (``_COMMAND_WORDS``)."""
    number = str(k - 1 + first)
    for commanded in (False, True):
        for word in _WORDS[signal]:
            for c, f in enumerate(fields, 1):
                tokens = _tokens(f)
                if (word in tokens and (number in tokens or joint.lower() in f.lower())
                        and bool(_COMMAND_WORDS & set(tokens)) == commanded):
                    return c
    return None


def _unit(field: str, signal: str, kind: str, skip: set[str] = frozenset()) -> str | None:
    """The unit the column name ``field`` states for ``signal`` on a joint of ``kind``, or None: the
    first word of the name (past the words in ``skip``) that names a unit fitting them."""
    if signal == "t" and field.strip().startswith("%time"):
        return "ns"   # rostopic echo -p writes the receipt time in ns as %time
    for token in _tokens(field):
        unit = _UNIT_WORDS[signal].get(token)
        if token not in skip and unit is not None and column_unit(signal, unit)[0] in (None, kind):
            return unit
    return None


def skeleton(data: bytes, name: str, urdf_text: str, urdf_name: str) -> str:
    """The skeleton mapping of the recording ``data`` for the URDF ``urdf_text``."""
    joints = urdf_joints(urdf_text, urdf_name)
    fields, count, delimiter = header_fields(data, name)
    lines = [f"# fricli import mapping: a skeleton from {one_line(name)} and {one_line(urdf_name)}.",
             "# Check every line (docs/robot-import.md); then fricli import --urdf checks it against the robot model.",
             f"# The recording has {count} columns"
             + (f": {', '.join(f'{c}={one_line(f)}' for c, f in enumerate(fields, 1))}" if fields else
                " and no header"), ""]
    if fields:
        lines.append("header = true                               # the first line names the columns")
    if delimiter != ",":
        lines.append(f"delimiter = {delimiter!r}".replace("'", '"'))
    time = None
    if fields:
        time = next((c for c, f in enumerate(fields, 1) if _tokens(f)[:1] in [[w] for w in _TIME_WORDS]), None)
    if time:
        unit = _unit(fields[time - 1], "t", "rotary")
        lines.append(f'time = {{column = {time}, unit = "{unit or "s"}"}}        # guessed from the header'
                     + ("" if unit else "; check the unit"))
    else:
        lines.append('time = {column = 1, unit = "s"}             # FILL IN: the time column (or time = {rate = HZ})')
    lines += ["", "[robot]", 'match = "name"                              # joints matched to the URDF by name', ""]
    first = _first_number(fields) if fields else 1
    for k, (joint, kind) in enumerate(joints, 1):
        lines += ["[[joints]]", f'name = "{joint}"                 # URDF joint {k} of {len(joints)}']
        default = dict(CANONICAL[kind], tau_m=CANONICAL[kind]["tau"], i_m="A")
        found = False
        for signal in ("q", "qd", "tau_m", "i_m"):
            column = _guess(fields, signal, k, joint, first) if fields else None
            if column is not None and not (signal == "i_m" and found):
                found = found or signal in ("tau_m", "i_m")
                unit = _unit(fields[column - 1], signal, kind,
                             {*_tokens(joint), *(set(_WORDS[signal]) - set(_UNIT_WORDS[signal]))})
                lines.append(f'{signal} = {{column = {column}, unit = "{unit or default[signal]}"}}'
                             f"        # guessed from {one_line(fields[column - 1])!r}"
                             + ("" if unit else "; check the unit"))
                if signal == "i_m":
                    lines.append("# kt = VALUE                                 # FILL IN: the drive gain [Nm/A] (torque "
                                 "constant x gear ratio), or --kt")
            elif signal == "q":
                lines.append(f'# q = {{column = N, unit = "{default["q"]}"}}          # FILL IN: joint {k}\'s position')
        if not found:
            lines.append(f'# tau_m = {{column = N, unit = "{default["tau_m"]}"}}         # FILL IN: the torque, or i_m '
                         f'with kt [{default["tau_m"]}/A]')
        lines.append("")
    lines += ["# A motor-side recording: theta and tau_motor per joint and a [transmission]", "# (docs/drives.md).", ""]
    return "\n".join(lines) + "\n"
