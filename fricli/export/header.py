"""What ``fricli export`` writes: the header of a model file or folder (``c``), or the arm's
header with its observer around the joints' friction (``observer``)."""

from __future__ import annotations

from fricli.core.atomic import atomic_write_bytes
from fricli.export import c
from fricli.export import observer as arm
from fricli.fitting.optionspec import OptionError


def export_header(model: str, output: str | None = None, *, prefix: str = "friction", observer: bool = False,
                  thresholds: str | None = None, adapt: bool = False, adapt_offset: bool = False,
                  time_constant: float | None = None, gain: float | None = None) -> str:
    """``fricli export``: the C header of the model file or folder ``model`` (``c.export``), with
    ``observer`` the arm's momentum observer and contact detection around it (``thresholds``,
    ``adapt``, ``adapt_offset``, ``time_constant``, ``gain`` as ``fricli replay``'s), written to
    ``output`` when given (- for stdout); returns its text. Options that do not go together, or a
    prefix that is no C name, raise ``OptionError`` naming the option."""
    from fricli.core.files import path_arg
    from fricli.robot.replay import checked, settings

    model = path_arg(model, "model", "export_header")
    output = None if output is None else path_arg(output, "output", "export_header")
    checked("export", observer=observer, adapt=adapt, adapt_offset=adapt_offset, time_constant=time_constant,
            gain=gain)
    try:
        c.check_prefix(prefix)
    except ValueError as exc:
        raise OptionError(str(exc), "prefix") from None
    if observer:
        k, thr, adaptation = settings(thresholds, adapt, adapt_offset, time_constant, gain)
        text = arm.export(model, prefix, k, thr, adaptation)
    elif thresholds or adapt or adapt_offset or time_constant is not None or gain is not None:
        raise OptionError("--thresholds, --adapt, --adapt-offset, --time-constant and --gain go with --observer",
                          "observer")
    else:
        text = c.export(model, prefix)
    if output is not None:
        atomic_write_bytes(output, text.encode("ascii"))
    return text
