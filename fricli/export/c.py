"""C99 code for fricli models: one header, parameters baked in, <math.h> only, no heap, no globals.

Every model node becomes a ``Part``: C definitions under a symbol prefix, with a ``_step``
function (and, for stateful parts, a ``_state`` struct and an ``_init`` function). An emitter
per model kind (registered with ``@emitter``) builds a node's part, composing its children's
parts; ``header`` wraps the root part in the public API

    typedef ... PREFIX_state;
    static inline void PREFIX_init(PREFIX_state *s);
    static inline double PREFIX_step(PREFIX_state *s, double <signal>, ...);   [Nm]
    static inline double PREFIX_step_array(PREFIX_state *s, const double *x); x: PREFIX_N_SIGNALS
    static inline double PREFIX_step_parts(PREFIX_state *s, double <signal>, ..., double *model_error);
                                           friction [Nm]; *model_error: the robot-model error [Nm]
    static inline double PREFIX_step_parts_array(PREFIX_state *s, const double *x, double *model_error);

and puts the model file's meta (provenance, units, parameters) in a comment at the top. Numbers
are written with 17 significant digits, so they read back as the same doubles; the same model
always gives the same bytes.
"""

from __future__ import annotations

import dataclasses
import json
import math
import os
import re
from typing import Callable

import numpy as np

from fricli import __version__
from fricli.core.errors import ModelFileError
from fricli.core.logs import REFERENCES
from fricli.models.base import FrictionModel

# signals in the order the step function takes them; other columns follow in name order
# (inputs only: a reference column such as tau_ext is never a signal, ``Context.signal``)
SIGNAL_ORDER = ("t", "q", "qd", "qdd", "tau_m", "tau_g", "tau_dyn", "temp")
SIGNAL_INFO = {"t": ("s", "time"), "q": ("q", "position"), "qd": ("qd", "velocity"),
               "qdd": ("qdd", "acceleration"), "tau_m": ("tau", "motor torque"), "tau_g": ("tau", "gravity torque"),
               "tau_dyn": ("tau", "rigid-body dynamics torque"), "temp": ("degC", "temperature")}
_C_KEYWORDS = set("""auto break case char const continue default do double else enum extern float for goto if
inline int long register restrict return short signed sizeof static struct switch typedef union unsigned void
volatile while bool class delete new operator private protected public template this throw try virtual
and and_eq bitand bitor compl not not_eq or or_eq xor xor_eq asm catch const_cast dynamic_cast explicit export
false friend mutable namespace reinterpret_cast static_cast true typeid typename using wchar_t alignas alignof
char8_t char16_t char32_t concept consteval constexpr constinit co_await co_return co_yield decltype noexcept
nullptr requires static_assert thread_local""".split())
# names <math.h> (and <errno.h>, which it may include) defines as macros
_C_MACROS = set("""HUGE_VAL HUGE_VALF HUGE_VALL INFINITY NAN FP_INFINITE FP_NAN FP_NORMAL FP_SUBNORMAL FP_ZERO
FP_FAST_FMA FP_FAST_FMAF FP_FAST_FMAL FP_ILOGB0 FP_ILOGBNAN MATH_ERRNO MATH_ERREXCEPT math_errhandling errno EDOM
ERANGE EILSEQ""".split())
# the names a public step function gives its state, its locals and its output (model_code)
_STEP_NAMES = {"s", "in", "in_", "model_error"}


AVX2 = "FRICLI_AVX2"   # macro: 1 when the networks' AVX2 and FMA copies are built (see PRELUDE)

PRELUDE = f"""\
/* With GCC or Clang on x86-64, each network also has a copy compiled for AVX2 and FMA (a GNU
 * target attribute), its multiply-adds fused, which runs when the CPU has both
 * (__builtin_cpu_supports); it agrees with the portable C99 copy to rounding (a few 1e-16
 * relative). Define FRICLI_PORTABLE to build the portable copy only. */
#ifndef {AVX2}
#if defined(__GNUC__) && defined(__x86_64__) && !defined(__AVX2__) && !defined(FRICLI_PORTABLE)
#define {AVX2} 1
#else
#define {AVX2} 0
#endif
#endif
"""


def position_step(dq: str) -> str:
    """C statements that take a position step in the variable ``dq`` beyond half a turn as a wrap at
    a turn, as ``fricli.numerics.physics.position_steps`` does."""
    from fricli.core.logs_motion import HALF_TURN

    half, turn = num(HALF_TURN), num(2 * HALF_TURN)
    return f"if ({dq} > {half}) {dq} -= {turn}; else if ({dq} < -{half}) {dq} += {turn};"


def num(x: float) -> str:
    """A C double literal that reads back as exactly ``x`` ("%.17g")."""
    x = float(x)
    if not math.isfinite(x):
        raise ModelFileError(f"cannot export the non-finite number {x}")
    s = "%.17g" % x
    return s if any(c in s for c in ".en") else s + ".0"


def array(values, per_line: int = 4) -> str:
    """A brace initialiser of doubles, ``per_line`` to a line."""
    flat = [num(v) for v in np.asarray(values, dtype=np.float64).reshape(-1)]
    lines = [", ".join(flat[i:i + per_line]) for i in range(0, len(flat), per_line)]
    return "{\n        " + ",\n        ".join(lines) + "}"


def identifier(text: str) -> str:
    """``text`` as a C identifier: other characters become '_', never a C or C++ keyword, a macro of
    <math.h>, a reserved name (__x, _X) or a leading digit."""
    out = re.sub(r"[^A-Za-z0-9_]", "_", str(text))
    if (not out or out[0].isdigit() or out in _C_KEYWORDS or out in _C_MACROS or out.startswith("__")
            or re.match(r"_[A-Z]", out)):
        out = "x_" + out
    return out


def check_prefix(prefix: str) -> str:
    if not isinstance(prefix, str) or not re.fullmatch(r"[A-Za-z_][A-Za-z0-9_]*", prefix) or prefix in _C_KEYWORDS:
        raise ValueError(f"the prefix {prefix!r} is not a C identifier (or is a keyword)")
    return prefix


def comment(text: str) -> str:
    """Text safe inside a C block comment, ASCII only."""
    return text.encode("ascii", "backslashreplace").decode("ascii").replace("*/", "* /").replace("/*", "/ *")


class Context:
    """What emitters share while building one model's code: the input struct, the signals read
    (collected as emitters ask for them) and the header's sign function."""

    def __init__(self, prefix: str, sgn: str):
        self.prefix = prefix
        self.fields: dict[str, str] = {}     # signal name -> C field name
        self.in_type = f"{prefix}_in"
        self.sgn = sgn

    def signal(self, name: str) -> str:
        """The C expression of signal ``name`` inside a step function (argument ``in``); a
        reference column (``fricli.core.logs.REFERENCES``) is refused."""
        if name in REFERENCES:
            raise ModelFileError(f"the model reads the reference column {name!r}, which a controller does not have")
        if name not in self.fields:
            field = identifier(name)
            # a parameter of the public step function: none of its own names nor the header's
            if field in _STEP_NAMES or field.startswith((self.sgn[:-3], "FRICLI_")):
                field = "x_" + field
            if field in self.fields.values():
                raise ModelFileError(f"two of the model's signal names give the C name {field!r}")
            self.fields[name] = field
        return f"in->{self.fields[name]}"

    def signals(self) -> list[str]:
        """The signals read, in the order of the step function's arguments."""
        return ([s for s in SIGNAL_ORDER if s in self.fields]
                + sorted(s for s in self.fields if s not in SIGNAL_ORDER))


@dataclasses.dataclass
class Part:
    """C code of one model node: definitions of ``<name>_step`` (and ``_state``, ``_init``; with
    ``parts``, ``<name>_step_parts(..., double *error)`` returning friction and the robot-model
    error apart, whose sum ``_step`` returns)."""

    name: str
    code: str
    stateful: bool
    parts: bool = False

    def step(self, state: str = "") -> str:
        """The call of the step function; ``state`` a pointer expression to its state."""
        return f"{self.name}_step({state + ', ' if self.stateful else ''}in)"

    def step_parts(self, state: str, error: str) -> str:
        """The call of ``_step_parts``; ``error`` a pointer expression to the error's double."""
        return f"{self.name}_step_parts({state + ', ' if self.stateful else ''}in, {error})"

    def init(self, state: str) -> str:
        return f"{self.name}_init({state});" if self.stateful else ""


EMITTERS: dict[str, Callable[[FrictionModel, str, Context], Part]] = {}


def emitter(*kinds: str):
    """Register a function (model, name, context) -> Part for the model kinds given."""
    def register(fn):
        for kind in kinds:
            EMITTERS[kind] = fn
        return fn
    return register


#: model kinds whose code is not one part with a per-joint step function (a coupled group): kind ->
#: function (model, meta, prefix, sign function's name) -> the model's whole C code
WHOLE: dict[str, Callable[[FrictionModel, dict, str, str], str]] = {}


def whole_emitter(kind: str):
    """Register a function (model, meta, prefix, sgn) -> C code for a kind with a step function of its own shape."""
    def register(fn):
        WHOLE[kind] = fn
        return fn
    return register


def emit(model: FrictionModel, name: str, ctx: Context) -> Part:
    """The part of ``model`` under the symbol prefix ``name``."""
    _load_emitters()
    fn = EMITTERS.get(model.kind)
    if fn is None:
        raise ModelFileError(f"cannot export a model of kind {model.kind!r} to C (no emitter for it)")
    return fn(model, name, ctx)


EMITTER_MODULES = ("lugre", "linear", "gms", "neural", "composite", "coupled")   # modules under fricli.export that register emitters


def _load_emitters() -> None:
    import importlib

    for name in EMITTER_MODULES:
        importlib.import_module(f"fricli.export.{name}")


def signals_of(model: FrictionModel) -> list[str]:
    """The signals the exported step function of ``model`` takes, in their order."""
    ctx = Context("x", "x_sgn")
    emit(model, "x_m", ctx)
    return ctx.signals()


def _signal_doc(name: str, units: dict) -> str:
    if name.startswith("qd@"):   # a coupled group's member reads its partners' velocities
        return f"{name} [{units.get('qd', 'qd')}] velocity of joint {name[3:]} (shares motors with this joint)"
    unit_key, meaning = SIGNAL_INFO.get(name, ("", "log column"))
    unit = units.get(unit_key, unit_key) if unit_key in ("q", "qd", "qdd", "tau") else unit_key
    return f"{name} [{unit or '-'}] {meaning}"


def model_code(model: FrictionModel, meta: dict, prefix: str, sgn: str) -> str:
    """The public API (state, init, step) of one model under ``prefix``, with its parts; ``sgn``
    names the header's sign function."""
    ctx = Context(prefix, sgn)
    root = emit(model, f"{prefix}_m", ctx)
    signals = ctx.signals()
    if not signals:
        raise ModelFileError("cannot export a model that reads no signal")
    units = meta.get("units", {})
    tau = units.get("tau", "Nm")
    has_error = bool(root.parts and _has_model_error(model))
    args = ", ".join(f"double {ctx.fields[s]}" for s in signals)
    out = [f"/* Signals of {prefix}_step, in this order (what the controller has):"]
    out += [f" *   {i}. {comment(_signal_doc(s, units))}" for i, s in enumerate(signals)]
    out += [f" * Returns the friction torque tau_f [{tau}], positive along the motion. */",
            f"enum {{ {prefix}_N_SIGNALS = {len(signals)} }};",
            f"enum {{ {prefix}_HAS_MODEL_ERROR = {int(has_error)} }};   /* 1: the model corrects robot-model errors */",
            "typedef struct {", *[f"    double {ctx.fields[s]};" for s in signals], f"}} {ctx.in_type};", "",
            root.code.rstrip(), ""]
    if root.stateful:
        out += [f"typedef {root.name}_state {prefix}_state;", "",
                "/* Start a run: state before the first sample (call again after a pause in the samples). */",
                f"static inline void {prefix}_init({prefix}_state *s) {{ {root.init('s')} }}"]
    else:
        out += [f"typedef struct {{ int unused; }} {prefix}_state;  /* the model has no state */", "",
                "/* Start a run (the model has no state: kept so that every kind has the same calls). */",
                f"static inline void {prefix}_init({prefix}_state *s) {{ s->unused = 0; }}"]
    body = [f"    {ctx.in_type} in_;", f"    const {ctx.in_type} *in = &in_;"]
    body += [f"    in_.{ctx.fields[s]} = {ctx.fields[s]};" for s in signals]
    if not root.stateful:
        body.append("    (void)s;")
    parts = list(body)
    body.append(f"    return {root.step('s')};")
    if root.parts:
        parts.append(f"    return {root.step_parts('s', 'model_error')};")
    else:
        parts += ["    *model_error = 0.0;", f"    return {root.step('s')};"]
    out += ["", f"/* One sample: friction torque [{tau}] for the signals above (with the robot-model error",
            f" * corrections when {prefix}_HAS_MODEL_ERROR, as fricli predict); updates the state. */",
            f"static inline double {prefix}_step({prefix}_state *s, {args}) {{", *body, "}", "",
            f"/* {prefix}_step with the signals as an array x[{prefix}_N_SIGNALS], in the order above. */",
            f"static inline double {prefix}_step_array({prefix}_state *s, const double *x) {{",
            f"    return {prefix}_step(s, {', '.join(f'x[{i}]' for i in range(len(signals)))});", "}", "",
            f"/* {prefix}_step with its two parts apart: returns the friction torque [{tau}] alone (the part that",
             " * resists the motion: use it for friction compensation) and writes to *model_error the correction of the",
            f" * robot model's errors [{tau}] (0 when {prefix}_HAS_MODEL_ERROR is 0); their sum is {prefix}_step. */",
            f"static inline double {prefix}_step_parts({prefix}_state *s, {args}, double *model_error) {{", *parts,
            "}", "",
            f"/* {prefix}_step_parts with the signals as an array x[{prefix}_N_SIGNALS], in the order above. */",
            f"static inline double {prefix}_step_parts_array({prefix}_state *s, const double *x, double *model_error) {{",
            f"    return {prefix}_step_parts(s, {', '.join(f'x[{i}]' for i in range(len(signals)))}, model_error);",
            "}"]
    return "\n".join(out) + "\n"


def _has_model_error(model: FrictionModel) -> bool:
    """Whether the model or a model it is made of corrects robot-model errors (error terms)."""
    return (bool(getattr(model, "error_terms", None)) or bool(getattr(model, "has_model_error", False))
            or any(_has_model_error(c) for c in model.children().values()))


def _meta_block(meta: dict, model: FrictionModel, prefix: str, source: str, sha256: str) -> list[str]:
    keep = {k: meta.get(k) for k in ("kind", "joint", "axis", "units", "inputs", "fricli_version",
                                     "format_version", "provenance")}
    if meta.get("joints"):
        keep["joints"] = meta["joints"]
    lines = [f"model {source} (sha256 {sha256}) as {prefix}_*"]
    lines += ["  " + line for line in json.dumps(keep, indent=1, sort_keys=True, ensure_ascii=True).splitlines()]
    lines += ["  " + line for line in model.describe().splitlines()]
    return [comment(line) for line in lines]


@dataclasses.dataclass
class Entry:
    """One model to export: the model, its file meta, its symbol prefix, its file name and hash."""

    model: FrictionModel
    meta: dict
    prefix: str
    source: str
    sha256: str


def _code(entry: Entry, sgn: str) -> str:
    _load_emitters()
    whole = WHOLE.get(entry.model.kind)   # a group of joints: a step function of its own shape
    if whole is not None:
        return whole(entry.model, entry.meta, entry.prefix, sgn)
    return model_code(entry.model, entry.meta, entry.prefix, sgn)


def names_of(prefix: str, code: str) -> set[str]:
    """The C names ``code`` uses under ``prefix`` (PREFIX_*): those it defines, since each model's code
    refers to no other model's."""
    return set(re.findall(rf"\b{re.escape(prefix)}_\w+", code))


def check_names(parts: list[tuple[str, str, str]]) -> None:
    """ModelFileError when two of the (source, prefix, code) ``parts`` use one C name (a file named like
    another's part: joint_1_m beside joint_1), which would be defined twice."""
    seen: dict[str, str] = {}
    for source, prefix, code in parts:
        for name in names_of(prefix, code) | {prefix}:
            other = seen.setdefault(name, source)
            if other != source:
                raise ModelFileError(f"{other} and {source} give the same C name {name}: rename one of the files")


def header(entries: list[Entry], guard: str) -> str:
    """The whole header for one or several models (one per joint)."""
    for entry in entries:
        check_prefix(entry.prefix)
    top = [f"/* Friction model code generated by fricli {__version__} (fricli export): C99, <math.h> only,",
           " * no heap, no global state. Include it wherever it is needed; every function is static inline.",
           " * Usage (see docs/deploy.md): PREFIX_state s; PREFIX_init(&s); then once per sample, in time order,",
           " *   tau_f = PREFIX_step(&s, signals...);",
           " * Link with -lm (the math library: exp, log, fabs), e.g. cc -std=c99 -O2 main.c -o main -lm",
           " *"]
    for entry in entries:
        top += [" * " + line for line in _meta_block(entry.meta, entry.model, entry.prefix, entry.source,
                                                   entry.sha256)]
        top.append(" *")
    top[-1] = " */"
    sgn = f"{guard}_sgn"
    out = top + [f"#ifndef FRICLI_{guard.upper()}_H", f"#define FRICLI_{guard.upper()}_H", "", "#include <math.h>", "",
                 "/* sign(v): -1, 0 or 1 */",
                 f"static inline double {sgn}(double v) {{ return v > 0.0 ? 1.0 : (v < 0.0 ? -1.0 : 0.0); }}", ""]
    codes = [_code(entry, sgn) for entry in entries]
    check_names([(entry.source, entry.prefix, code) for entry, code in zip(entries, codes)])
    if any(AVX2 in code for code in codes):
        out.append(PRELUDE)
    for entry, code in zip(entries, codes):
        out.append(f"/* ---------------------------------------------------------------- {entry.prefix} */")
        out.append(code)
    out += [f"#endif /* FRICLI_{guard.upper()}_H */", ""]
    return "\n".join(out)


def entries_for(paths: list[str], prefix: str, *, per_joint: bool) -> list[Entry]:
    """Load the model files; with ``per_joint`` each gets the prefix ``<prefix>_<file name stem>``."""
    import hashlib

    from fricli import models

    out, seen = [], {}
    for path in paths:
        model, meta = models.load(path)
        with open(path, "rb") as fh:
            digest = hashlib.sha256(fh.read()).hexdigest()
        stem = os.path.splitext(os.path.basename(path))[0]
        name = f"{prefix}_{identifier(stem)}" if per_joint else prefix
        if name in seen:
            raise ModelFileError(f"{path} and {seen[name]} give the same C names ({name}_*)")
        seen[name] = path
        out.append(Entry(model, meta, name, os.path.basename(path), digest))
    return out


def model_paths(source: str) -> tuple[list[str], bool]:
    """(model files, one per joint?) for a model file or a folder of them (one .npz per joint)."""
    if os.path.isdir(source):
        paths = sorted(os.path.join(source, f) for f in os.listdir(source) if f.endswith(".npz")
                       and not f.startswith("."))   # hidden files (a copy's ._NAME.npz) as a model set skips them
        if not paths:
            raise ModelFileError(f"{source}: no .npz model files in the folder")
        return paths, True
    return [source], False


def export(source: str, prefix: str = "friction") -> str:
    """C header text for the model file or folder of per-joint model files ``source``."""
    check_prefix(prefix)
    paths, per_joint = model_paths(source)
    return header(entries_for(paths, prefix, per_joint=per_joint), prefix)

