"""The options that shape a model, declared once per pipeline (identify, train-base, adapt).

The command line derives its click options from ``PIPELINES`` (``fricli.cli.options.spec_options``)
and the fleet manifest checks its ``[options.PIPELINE]`` tables against them (``check``), so a
command and a fleet job given the same options record the same job (``fricli.fitting.runs``).
"""

from __future__ import annotations

import dataclasses
import math
import numbers

import numpy as np

from fricli.fitting import learning
from fricli.core.errors import OptionError  # noqa: F401 - where the commands and the fleet take it from
from fricli.core.logs import DEFAULT_CUTOFF_HZ


@dataclasses.dataclass(frozen=True)
class Option:
    """One option: ``name`` as a Python name (``batch_size``; --batch-size on the command line);
    ``type`` one of float, int, choice, flag, sizes (positive layer widths, "30,30"), text;
    ``default`` None means "not given" (the help says what is used then)."""

    name: str
    type: str
    default: object = None
    help: str = ""
    unit: str | None = None
    low: float | None = None
    high: float | None = None
    low_open: bool = False
    choices: tuple = ()
    metavar: str | None = None
    high_open: bool = False

    @property
    def flag(self) -> str:
        return "--" + self.name.replace("_", "-")

    def expects(self) -> str:
        """What a value must be, in words: "a number > 0", "one of auto, steady, settled"."""
        if self.type == "choice":
            return "one of " + ", ".join(self.choices)
        if self.type == "flag":
            return "true or false"
        if self.type == "sizes":
            return "layer sizes: positive integers such as 30 or \"30,30\""
        if self.type == "text":
            return "a text"
        what = "a number" if self.type == "float" else "an integer"
        bounds = []
        if self.low is not None:
            bounds.append(f"{'>' if self.low_open else '>='} {self.low:g}")
        if self.high is not None:
            bounds.append(f"{'<' if self.high_open else '<='} {self.high:g}")
        return " ".join([what, " and ".join(bounds)]).strip()

    def check(self, value):
        """``value`` as the command would pass it (a TOML 50 for a float option is 50.0, a
        "30,30" for sizes is (30, 30)); ValueError saying what is expected otherwise."""
        if value is None and self.default is None and self.type != "flag":
            return None
        ok = True
        if self.type == "flag":
            ok = isinstance(value, bool)
        elif self.type == "choice":
            ok = value in self.choices
        elif self.type == "text":
            ok = isinstance(value, (str, int)) and not isinstance(value, bool)
            value = str(value) if ok else value
        elif self.type == "sizes":
            value = parse_sizes(value)
            ok = value is not None
        elif self.type in ("float", "int"):
            ok = isinstance(value, (numbers.Integral, float, np.floating)) and not isinstance(value, (bool, np.bool_)) \
                and (self.type == "float" or isinstance(value, numbers.Integral))
            if ok:
                value = float(value) if self.type == "float" else int(value)
                ok = math.isfinite(value) and (self.low is None or (value > self.low if self.low_open else value >= self.low)) \
                    and (self.high is None or (value < self.high if self.high_open else value <= self.high))
        if not ok:
            raise ValueError(f"{self.name} = {value!r}: expected {self.expects()}")
        return value


def parse_sizes(value) -> tuple[int, ...] | None:
    """Layer widths from "30,30", 30 or [30, 30]; None when not positive integers."""
    if isinstance(value, str):
        try:
            value = [int(part) for part in value.split(",")]
        except ValueError:
            return None
    elif isinstance(value, int) and not isinstance(value, bool):
        value = [value]
    if not isinstance(value, (list, tuple)) or not value:
        return None
    if not all(isinstance(v, int) and not isinstance(v, bool) and v >= 1 for v in value):
        return None
    return tuple(value)


# How a log is read (docs/log-format.md): part of every pipeline's job.
READING = (
    Option("joint", "text", None, "Joint to use when the log holds several."),
    Option("kt", "float", None, "Motor torque constant [Nm/A] when the log has i_m instead of tau_m.", unit="Nm/A"),
    Option("cutoff", "float", DEFAULT_CUTOFF_HZ, "Low-pass cut-off [Hz] used when qd/qdd are derived from q.",
           unit="Hz", low=0, low_open=True),
    Option("drop_invalid", "flag", False,
           "Drop invalid rows (NaN, infinite or missing values; with a warning) instead of refusing the log."),
    Option("no_gravity", "flag", False, "When the log has no tau_g column, take tau_g as 0: the joint carries no "
                                        "gravity load."),
    Option("no_dynamics", "flag", False, "When the log has no tau_dyn column, take tau_dyn (inertia and Coriolis "
                                         "torque) as 0."),
)
# the flags that declare a robot-model column zero (docs/log-format.md) -> that column
ZERO_FLAGS = {"no_gravity": "tau_g", "no_dynamics": "tau_dyn"}

IDENTIFY = (
    Option("hold", "float", 0.2, "Steady state: the velocity must have been constant for at least this long [s].",
           unit="s", low=0, low_open=True),
    Option("travel", "float", 0.002,
           "Steady state: ... and over at least this distance [rad or m] (longer holds at slow speeds).",
           unit="rad or m", low=0),
    Option("samples", "choice", "auto",
           "Rows for the static curve: constant-velocity holds, every row --settle past a reversal (continuous "
           "excitation), or settled when holds cover under half of the motion and the log has tau_dyn.",
           choices=("auto", "steady", "settled")),
    Option("settle", "float", 0.01, "Settled rows: travel since the last velocity reversal [rad or m].",
           unit="rad or m", low=0),
    Option("refine", "flag", False, "Finally fit all parameters jointly on the whole log."),
    Option("kind", "choice", "lugre",
           "lugre, or the linear model Fv*qd + Fc*sign(qd) + offset (linear-asymmetric: Fv, Fc per direction) "
           "fitted by least squares on the rows in motion (docs/tutorial.md), or gms: the Generalized "
           "Maxwell-slip model, hysteresis with memory (docs/gms.md).",
           choices=("lugre", "linear", "linear-asymmetric", "gms")),
    Option("coupling", "flag", False,
           "Fit each group of joints that share motors (the log's transmission, docs/drives.md) as one model of "
           "friction per motor (kind coupled); the other joints as before."),
    Option("motor_stribeck", "flag", False, "With --coupling: each motor's friction with the Stribeck curve (fs, vs) "
                                            "as well."),
)
# options a fleet job (one joint per job) cannot take, in any pipeline: a coupled group's model needs
# every joint of the group
WHOLE_LOG = {"coupling", "motor_stribeck"}

TRAIN_BASE = (
    Option("arch", "choice", learning.DEFAULT_ARCH,
           "dissipative: a non-negative magnitude of (speed, direction) and |tau_g| times a smooth sign of qd, "
           "never along the motion (docs/neural-models.md); mlp: the paper's NN_base NN(tau_g, qd); selmic: "
           "Selmic & Lewis (sigmoid and jump units); nnacm: Ciliz & Tomizuka (network plus learned Coulomb "
           "terms per direction).", choices=tuple(learning.ARCHS)),
    Option("hidden", "sizes", None,
           "Hidden layer sizes [default: dissipative and mlp 30,30; selmic 30 (10 of them jump units); nnacm 50].",
           metavar="N[,N...]"),
    Option("schedule", "choice", "cosine",
           "cosine: Adam's learning rate falls from --lr to 0 along a cosine over the steps; paper: the paper's "
           "constant learning rate for 50,000 steps.", choices=tuple(learning.SCHEDULES)),
    Option("steps", "int", None,
           f"Adam steps [default: cosine {learning.COSINE_STEPS['dissipative']:,} for dissipative, "
           f"{learning.SCHEDULES['cosine'][1]:,} for the others; paper {learning.SCHEDULES['paper'][1]:,}].", low=1),
    Option("patience", "int", None,
           "Stop early when the validation loss has not improved by 0.1 % for STEPS steps [a log without levels: "
           "each held-out probe's, by default after a quarter of --steps].", low=1, metavar="STEPS"),
    Option("lr", "float", 0.01, "Adam learning rate.", low=0, low_open=True),
    Option("batch_size", "int", 0, "Samples per step; 0 = full batch.", low=0),
    Option("seed", "int", 0, "Seed for the row selection, the initial weights and the batches.", low=0),
    Option("val_fraction", "float", 0.2,
           "Share of every constant-velocity stretch held out for validation, in whole pieces (a log without "
           "velocity levels: whole blocks of time, a fold of --ensemble; the default network's choices are made on "
           "halves of the blocks; 0: nothing held out).", low=0, high=0.9),
    Option("ensemble", "int", 1,
           "On a log without velocity levels: the mean of N networks, one per fold of time blocks, each validated "
           "on its fold (dissipative; N at most 1 / --val-fraction; trained two at a time). 1: one network "
           "trained on every row, at the step, prior share and pre-sliding choice that two networks, each trained "
           "on half of the time blocks, showed best on the other half.",
           low=1, metavar="N"),
    Option("no_balance", "flag", False,
           "Train on every row instead of the same number of rows per velocity level."),
    Option("max_samples", "int", learning.DEFAULT_MAX_SAMPLES,
           "Rows kept after velocity balancing (training plus validation).", low=10),
    Option("velocity_input", "choice", "asinh",
           "asinh: the network sees asinh(qd / v0), which spreads the slow speeds apart; linear: qd itself (the "
           "paper's input; not for --arch dissipative).", choices=tuple(learning.VELOCITY_INPUTS)),
    Option("velocity_scale", "float", None,
           "v0 of --velocity-input asinh [rad/s or m/s]; default the 5 % quantile of the training rows' speeds.",
           unit="rad/s or m/s", low=0, low_open=True, metavar="V0"),
    Option("bristles", "choice", "on",
           "The dissipative network's pre-sliding (bristle) state, LuGre's with the learned curve as its steady "
           "state (docs/neural-models.md): on; auto: only where it lowers the held-out error by 1 %; off: the "
           "static network.",
           choices=learning.BRISTLES),
    Option("no_prior", "flag", False,
           "The dissipative network alone, not blended with the LuGre model's static curve fitted on the same rows "
           "(by default the network's share of the blend is chosen on the held-out rows; docs/neural-models.md)."),
    Option("memory", "choice", "auto",
           "On a log without velocity levels, friction with memory: Maxwell-slip elements (hysteresis) on top of the "
           "trained network. auto: added when, on held-out blocks of time, they lower the network's residual "
           "significantly more than a change of level or a smooth correction in speed (fricli diagnose's hysteresis "
           "test); on: always; off: the network alone. Elements that would give energy back are never added "
           "(docs/neural-models.md, Memory).", choices=learning.MEMORY),
    Option("coupling", "flag", False,
           "Train each group of joints that share motors (the log's transmission, docs/drives.md) as one model "
           "with a dissipative network per motor of the motor's velocity (kind coupled); the other joints as "
           "before. The motors' networks have no pre-sliding state (--bristles does not apply)."),
)

ADAPT = (
    Option("hidden", "sizes", (30,), "Hidden layer widths of NN_add (ELU), e.g. 30 or 30,30.",
           metavar="N[,N...]"),
    Option("epochs", "int", 200, "Passes over the training rows, in random mini-batches.", low=1),
    Option("batch_size", "int", 64, "Rows per mini-batch (an epoch is floor(rows / batch size) steps).", low=1),
    Option("lr", "float", 0.01, "Adam learning rate.", low=0, low_open=True),
    Option("seed", "int", 0, "Seed for the split, weights and batches.", low=0),
    Option("val_fraction", "float", 0.2,
           "Share of every stretch of motion (a log without velocity levels: of the log's time) held out for "
           "validation, in whole pieces; 0 also skips the held-out decision (NN_add kept unchecked).",
           low=0, high=0.9),
    Option("max_seconds", "float", None, "Use only the first S seconds of LOG.", unit="s", low=0, low_open=True),
    Option("min_speed", "float", None,
           "Leave out rows slower than this [rad/s or m/s]; default: the rows not in motion (slower than 2 % of the "
           "log's top speed).",
           unit="rad/s or m/s", low=0),
)

PIPELINES = {"identify": IDENTIFY, "train-base": TRAIN_BASE, "adapt": ADAPT}


def diagnose_options() -> tuple[Option, ...]:
    """diagnose's options that shape what it finds and what --fix adds (its reading options are
    ``READING``): those of ``fricli diagnose`` and of ``fricli.Diagnosis``."""
    from fricli.fitting.diagnosis import driver

    return (
        Option("folds", "int", driver.DEFAULT_FOLDS, "Contiguous folds over time for the held-out scores.",
               low=3, high=100),
        Option("min_gain", "float", driver.DEFAULT_MIN_GAIN,
               "Share of the remaining held-out squared residual an effect must remove.", low=0, low_open=True, high=1),
        Option("alpha", "float", driver.DEFAULT_ALPHA, "Significance level of the held-out improvement.",
               low=0, low_open=True, high=0.5),
        Option("effects", "text", None, "Comma-separated candidate effects to test (default: all).", metavar="NAMES"),
        Option("max_effects", "int", None, "Add at most this many effects.", low=0),
        Option("no_carry", "flag", False,
               "With --fix, keep every effect as an added term even when a LuGre base could carry it."),
        Option("accept_implausible", "flag", False,
               "Add effects whose fitted parameters are out of plausible range (e.g. a gravity scale beyond +-30 %) "
               "instead of reporting them as suspicious."),
    )


def options_of(pipeline: str) -> dict[str, Option]:
    """{name: Option} of a pipeline, the reading options included."""
    return {o.name: o for o in (*READING, *PIPELINES[pipeline])}


def defaults(pipeline: str) -> dict:
    """Every option of ``pipeline`` at its default."""
    return {name: o.default for name, o in options_of(pipeline).items()}


def check(pipeline: str, given: dict) -> dict:
    """``given`` (names with - or _) over the defaults, each value checked; OptionError naming
    the first unknown option or wrong value and what it expects."""
    return defaults(pipeline) | check_values(given, options_of(pipeline), pipeline)


def check_values(given: dict, spec: dict[str, Option], who: str) -> dict:
    """``given`` ({name: value}, names with - or _) with each value checked against ``spec``
    ({name: Option}); OptionError naming the first unknown option or wrong value, as an option of
    ``who`` (a pipeline, an estimator)."""
    out = {}
    for key, value in given.items():
        name = key.replace("-", "_")
        if name not in spec:
            raise OptionError(f"unknown {who} option {key!r} (known: {', '.join(sorted(spec))})", name)
        try:
            out[name] = spec[name].check(value)
        except ValueError as exc:
            raise OptionError(f"{who} option {exc}", name) from None
    return out
