"""`fricli export`: the generated C gives the numbers of `fricli predict --precision double`.

Every kind is exported, compiled with the system C compiler (warnings are errors; C99 and C++)
and run over a held-out simulated log and the EMPS log through a small driver; every row must
agree with `fricli predict` to 1e-9 Nm + 1e-9 relative. Compiling tests skip without a compiler.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

import export_check as check

from conftest import SAMPLE, invoke, shared_data
from fricli import models
from fricli.core import logs
from fricli.export import c, network
from fricli.models import terms as T
from fricli.models.augmented import AugmentedModel
from fricli.models.dissipative import DissipativeFriction
from fricli.models.lugre import LuGreModel
from fricli.models.neural import ARCHS
from fricli.models.residual import ResidualFriction

ABS, REL = 1e-9, 1e-9
needs_cc = pytest.mark.skipif(check.compiler() is None, reason="no C compiler")
needs_cxx = pytest.mark.skipif(check.compiler(cxx=True) is None, reason="no C++ compiler")


def _train(log, rng, *, lugre: LuGreModel, terms: list[dict]) -> dict:
    """Every kind, small and quickly trained on ``log`` (the numbers need not be good ones)."""
    sig = log.signals
    rows = np.arange(0, len(log), max(1, len(log) // 300))
    pick = {k: v[rows] for k, v in sig.items()}
    target = logs.friction_target(sig)
    out = {"lugre": lugre}
    for arch, cls in ARCHS.items():
        out[arch] = cls(steps=100, velocity_scale="auto").fit(pick, target[rows], rng=rng)
    moving = rows[sig["qd"][rows] != 0]
    out["dissipative"] = DissipativeFriction(steps=100).fit({k: v[moving] for k, v in sig.items()}, target[moving],
                                                           rng=rng)
    fit_residual = lambda base, **kw: ResidualFriction(base, epochs=2, **kw).fit(  # noqa: E731
        sig, target, rows[::2], rows[1::2], rng=rng)
    out["residual"] = fit_residual(lugre)
    out["residual-mlp"] = fit_residual(out["mlp"])
    out["residual-dissipative"] = fit_residual(out["dissipative"])
    out["residual-additive"] = fit_residual(lugre, combine="additive")
    out["augmented"] = AugmentedModel(lugre, terms, rng.normal(size=len(terms)))
    out["augmented-nn"] = AugmentedModel(out["nnacm"], terms[:4], rng.normal(size=4))
    out["augmented-errors"] = AugmentedModel(lugre, terms[:5], rng.normal(size=5), error_terms=ERROR_TERMS,
                                             error_coef=rng.normal(size=len(ERROR_TERMS)),
                                             effects=["a", "gravity", "offset", "acceleration"],
                                             errors=["gravity", "offset", "acceleration"])
    # Maxwell-slip elements (the hysteresis effect): their deflections are state across batches
    out["augmented-hysteresis"] = AugmentedModel(lugre, [T.term("slip@0.004", T.slip_(0.004)),
                                                         T.term("slip@0.03", T.slip_(0.03)), T.term("p", T.P)],
                                                 [0.4, 0.6, -0.1], effects=["hysteresis"])
    out["augmented-gravity"] = AugmentedModel(lugre, [T.term("sign", T.SIGN)], [0.5], error_terms=ERROR_TERMS[:1],
                                              error_coef=[0.03], effects=["quadrant", "gravity"], errors=["gravity"])
    # NN_add over a model with robot-model errors: the errors pass by the dissipative combination
    out["residual-errors"] = fit_residual(out["augmented-errors"])
    # the Maxwell-slip model with every part: elements, a Coulomb level along the travel, a load slope
    # (set by hand where the fit finds none) and a robot-model error of the position
    from fricli.fitting import hysteresis
    from fricli.models.gms import GMSModel

    gms = hysteresis.fit(sig, elements=(4,), coulomb_k=(3,), error_k=(2,))[0]
    out["gms"] = GMSModel(gms.deflection, gms.force, **dict(gms.parameters(), kc=max(gms.kc, 0.02)),
                          coulomb_pos=gms.coulomb_pos, error=gms.error)
    out["augmented-dissipative"] = AugmentedModel(out["dissipative"], terms[-4:], rng.normal(size=4),
                                                  error_terms=ERROR_TERMS[:1], error_coef=[0.03], errors=["gravity"])
    return out


SIM_TERMS = [T.term("1", T.ONE), T.term("p", T.P), T.term("qd", T.sig_("qd")), T.term("p*pos", T.P, T.POS),
             T.term("p*dtemp", T.P, T.dev("temp", 30.0)), T.term("qd*dtemp held", T.sig_("qd"), T.dev("temp", 30.0, 29.0, 31.0)),
             T.term("|tau_g|*sign", T.abs_("tau_g"), T.SIGN),
             T.term("tau_l*moving", T.OVERLOAD, T.MOVING), T.term("sat1", {"f": "sat", "scale": 0.05}),
             T.term("sin1@3", {"f": "sin", "name": "q", "w": 3.0}),
             T.term("cos1@3", {"f": "cos", "name": "q", "w": 3.0}),
             T.term("qdd", T.sig_("qdd")), T.term("|qd|", T.abs_("qd")),
             T.term("tau_g held", T.HELDGRAVITY), T.term("payload*sign", T.OVERLOAD, T.SIGN),
             T.term("sign*sin@3", T.SIGN, {"f": "sin", "name": "q", "w": 3.0})]
EMPS_TERMS = [T.term("1", T.ONE), T.term("qdd", T.sig_("qdd")), T.term("p*pos", T.P, T.POS),
              T.term("sign", T.SIGN), T.term("sat1", {"f": "sat", "scale": 0.01}),
              T.term("sin1@40", {"f": "sin", "name": "q", "w": 40.0}), T.term("tau_g held", T.HELDGRAVITY)]
# robot-model errors: the logged gravity torque off by a factor, an offset, a missing inertia
ERROR_TERMS = [T.term("tau_g", T.sig_("tau_g")), T.term("1", T.ONE), T.term("qdd", T.sig_("qdd"))]


@pytest.fixture(scope="module")
def sim_models(tmp_path_factory):
    """Model files of every kind fitted on the sample base log (joint 2)."""
    folder = tmp_path_factory.mktemp("sim_models")
    log = logs.load_log(str(SAMPLE / "joint2_base.parquet"))
    rng = np.random.default_rng(5)
    variants = {"lugre-loaded": LuGreModel(7.0, 9.0, 0.04, 1.2, 12.0, kc=0.04, ks=0.05, sigma0=1.7e4, sigma1=0.002),
                "lugre-asym-thermal": LuGreModel(7.0, 9.0, 0.04, 1.2, 12.0, kc=0.04, ks=0.05, sigma0=1.7e4,
                                                 sigma1=0.5, fc_neg=6.0, fv_neg=11.0, t_ref=30.0, alpha_c=0.004,
                                                 alpha_v=0.01),
                "lugre-plain": LuGreModel(7.0, 9.0, 0.04, 1.2, 12.0, sigma0=1.7e4)}
    trained = _train(log, rng, lugre=variants["lugre-loaded"], terms=SIM_TERMS)
    trained.update(variants)
    paths = {}
    for kind, model in trained.items():
        paths[kind] = str(folder / f"{kind}.npz")
        models.save_for_log(paths[kind], model, log, rows_used=len(log), seed=5)
    return paths


EMPS_ZERO = ("tau_g", "tau_dyn")   # a horizontal axis without a robot model


@pytest.fixture(scope="module")
def emps_models(tmp_path_factory):
    path = str(shared_data("emps/emps.parquet"))
    folder = tmp_path_factory.mktemp("emps_models")
    log = logs.load_log(path, cutoff_hz=100.0, zero=EMPS_ZERO)
    lugre = LuGreModel(21.3, 21.3, 0.01, 1.0, 195.65, sigma0=1.82e6, sigma1=1.82e4, axis="linear")
    trained = _train(log, np.random.default_rng(6), lugre=lugre, terms=EMPS_TERMS)
    paths = {}
    for kind, model in trained.items():
        paths[kind] = str(folder / f"{kind}.npz")
        models.save_for_log(paths[kind], model, log, rows_used=len(log), seed=6)
    return path, paths


def _compiled(model_path: str, folder, prefix: str = "fr") -> tuple[str, list[str]]:
    header = os.path.join(folder, f"{prefix}.h")
    res = invoke("export", model_path, "-o", header, "--prefix", prefix, "-q")
    assert res.exit_code == 0, res.output
    exe = os.path.join(folder, f"{prefix}_driver")
    assert check.build(header, prefix, exe) == ""          # no warnings (they are errors, too)
    model, _ = models.load(model_path)
    return exe, c.signals_of(model)


def _compare(model_path: str, log_path: str, tmp_path, *, cutoff: float = 50.0, batch_rows: int = 4000,
             zero: tuple = ()) -> float:
    """Worst |C - predict| / (ABS + REL |predict|) over every row of the log (``zero``: robot-model
    columns the log lacks, declared zero)."""
    out = tmp_path / "pred.parquet"
    flags = [{"tau_g": "--no-gravity", "tau_dyn": "--no-dynamics"}[c] for c in zero]
    res = invoke("predict", model_path, log_path, "-o", out, "--precision", "double", "--cutoff", cutoff,
                 "--batch-rows", batch_rows, *flags, "-q")
    assert res.exit_code == 0, res.output
    ref = pq.read_table(out).column("tau_f_pred").to_numpy()
    exe, names = _compiled(model_path, tmp_path)
    sig = logs.load_log(log_path, cutoff_hz=cutoff, zero=zero).signals
    got = check.run(exe, check.signal_matrix(sig, names))
    assert got.shape == ref.shape and np.isfinite(got).all()
    return float(np.max(np.abs(got - ref) / (ABS + REL * np.abs(ref))))


KINDS = ["lugre-plain", "lugre-loaded", "lugre-asym-thermal", "mlp", "selmic", "nnacm", "dissipative", "residual",
         "residual-mlp", "residual-dissipative", "residual-additive", "augmented", "augmented-nn",
         "augmented-errors", "augmented-dissipative", "augmented-hysteresis", "residual-errors", "gms"]


@needs_cc
@pytest.mark.parametrize("kind", KINDS)
def test_export_matches_predict_on_a_held_out_simulated_log(kind, sim_models, tmp_path):
    log = str(SAMPLE / "joint2_extended_asym.parquet")       # held out: the models saw the base log
    assert _compare(sim_models[kind], log, tmp_path) <= 1.0


@needs_cc
def test_an_augmented_model_over_one_that_adds_nothing_compiles_and_matches_predict(sim_models, tmp_path):
    """diagnose --fix that finds nothing to add over an augmented model writes one with no terms
    over it: its step reads the base's friction and error only (no unused variable)."""
    base, _ = models.load(sim_models["augmented-errors"])
    log = logs.load_log(str(SAMPLE / "joint2_base.parquet"))
    path = str(tmp_path / "nothing-added.npz")
    models.save_for_log(path, AugmentedModel(base, [], np.zeros(0)), log, rows_used=len(log))
    assert _compare(path, str(SAMPLE / "joint2_extended_asym.parquet"), tmp_path) <= 1.0


@needs_cc
@pytest.mark.parametrize("kind", ["lugre", "mlp", "selmic", "nnacm", "dissipative", "residual", "residual-mlp",
                                  "residual-dissipative", "residual-additive", "augmented", "augmented-nn",
                                  "augmented-errors", "augmented-dissipative"])
def test_export_matches_predict_on_emps(kind, emps_models, tmp_path):
    log, paths = emps_models
    assert _compare(paths[kind], log, tmp_path, cutoff=100.0, batch_rows=7000, zero=EMPS_ZERO) <= 1.0


@needs_cc
@pytest.mark.parametrize("kind", ["augmented-errors", "augmented-dissipative", "residual", "residual-errors", "gms"])
def test_step_parts_gives_friction_and_model_error_apart(kind, sim_models, tmp_path):
    """PREFIX_step_parts: friction and robot-model error as ``predict_parts`` (friction alone and
    error 0 for a model without error terms); their sum is what PREFIX_step returns."""
    from fricli.models.base import predict_parts

    model, _ = models.load(sim_models[kind])
    models.set_precision(model, "double")
    sig = logs.load_log(str(SAMPLE / "joint2_extended_asym.parquet"), cutoff_hz=50.0).signals
    friction, error, _ = predict_parts(model, sig)
    has_error = kind.endswith("errors") or kind.startswith("augmented") or kind == "gms"
    assert (np.max(np.abs(error)) > 0.01) == has_error
    exe, names = _compiled(sim_models[kind], tmp_path)
    x = check.signal_matrix(sig, names)
    got_f, got_e = check.run_parts(exe, x)
    for got, ref in ((got_f, friction), (got_e, error), (got_f + got_e, check.run(exe, x))):
        assert np.max(np.abs(got - ref) / (ABS + REL * np.abs(ref))) <= 1.0
    text = c.export(sim_models[kind], "fr")
    assert f"fr_HAS_MODEL_ERROR = {int(has_error)} }}" in text


@needs_cc
@pytest.mark.parametrize("kind", ["gms", "augmented-hysteresis"])
def test_a_position_that_wraps_at_a_turn_moves_the_slip_elements_by_its_step(kind, sim_models, tmp_path):
    """A continuous joint recorded within one turn jumps by 2 pi where it wraps. No joint moves half
    a turn in one sample: the Maxwell-slip elements take the step less the turn, in Python as in C,
    and so hold the states of the position recorded without the wrap."""
    table = pq.read_table(SAMPLE / "joint2_extended_asym.parquet")
    i = table.schema.get_field_index("q")
    q = table.column("q").to_numpy()
    turning = q + (np.pi - np.median(q))                       # half the rows beyond pi
    wrapped = np.angle(np.exp(1j * turning))                   # in (-pi, pi]
    assert (np.abs(np.diff(wrapped)) > np.pi).sum() >= 2
    paths = {}
    for name, values in (("turning", turning), ("wrapped", wrapped)):
        paths[name] = str(tmp_path / f"{name}.parquet")
        pq.write_table(table.set_column(i, table.schema.field(i), pa.array(values)), paths[name])
    assert _compare(sim_models[kind], paths["wrapped"], tmp_path) <= 1.0
    model, _ = models.load(sim_models[kind])
    sig = {name: logs.load_log(path).signals for name, path in paths.items()}
    if kind == "gms":                                          # its level and error also read q along the travel
        from fricli.models.gms import element_states

        got, want = (element_states(sig[n]["q"], sig[n]["qd"], model.deflection)[0] for n in ("wrapped", "turning"))
    else:
        got, want = (model.predict(sig[n])[0] for n in ("wrapped", "turning"))
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-9)


@needs_cc
def test_single_precision_predict_is_what_differs(sim_models, tmp_path):
    """The default float32 networks differ from the C code by far more than the tolerance,
    which is why the comparison uses --precision double."""
    log = str(SAMPLE / "joint2_extended_asym.parquet")
    out = tmp_path / "pred.parquet"
    assert invoke("predict", sim_models["mlp"], log, "-o", out, "-q").exit_code == 0
    ref = pq.read_table(out).column("tau_f_pred").to_numpy()
    exe, names = _compiled(sim_models["mlp"], tmp_path)
    got = check.run(exe, check.signal_matrix(logs.load_log(log).signals, names))
    assert np.max(np.abs(got - ref)) > 1e-8


@needs_cxx
@pytest.mark.parametrize("kind", ["lugre-asym-thermal", "selmic", "dissipative", "residual", "augmented",
                                  "augmented-errors"])
def test_header_compiles_as_cpp_without_warnings(kind, sim_models, tmp_path):
    header = tmp_path / "fr.h"
    assert invoke("export", sim_models[kind], "-o", header, "--prefix", "fr").exit_code == 0
    assert check.build(str(header), "fr", str(tmp_path / "drv"), cxx=True) == ""


@pytest.mark.parametrize("cxx", [False, True], ids=["c", "c++"])
@pytest.mark.parametrize("kind", ["mlp", "residual", "augmented-nn"])
def test_the_fma_copy_of_a_network_agrees_with_the_portable_copy(kind, cxx, sim_models, tmp_path):
    """With GCC or Clang on x86-64 a CPU with AVX2 and FMA runs the networks' fused copy: what
    the portable copy (FRICLI_PORTABLE) gives, to rounding, also as C++."""
    if check.compiler(cxx) is None:
        pytest.skip("no C++ compiler" if cxx else "no C compiler")
    header = tmp_path / "fr.h"
    assert invoke("export", sim_models[kind], "-o", header, "--prefix", "fr", "-q").exit_code == 0
    assert "#define FRICLI_AVX2 1" in header.read_text()
    fast, portable = str(tmp_path / "fast"), str(tmp_path / "portable")
    assert check.build(str(header), "fr", fast, cxx=cxx) == ""
    assert check.build(str(header), "fr", portable, cxx=cxx, flags=("-DFRICLI_PORTABLE",)) == ""
    model, _ = models.load(sim_models[kind])
    x = check.signal_matrix(logs.load_log(str(SAMPLE / "joint2_extended_asym.parquet")).signals, c.signals_of(model))
    a, b = check.run(fast, x), check.run(portable, x)
    assert np.max(np.abs(a - b)) <= 1e-14 * max(1.0, np.max(np.abs(b)))   # 1e-15 of it measured


def test_export_is_byte_identical_and_carries_the_meta(sim_models, tmp_path):
    a, b = tmp_path / "a.h", tmp_path / "b.h"
    assert invoke("export", sim_models["augmented"], "-o", a).exit_code == 0
    assert invoke("export", sim_models["augmented"], "-o", b).exit_code == 0
    text = a.read_text()
    assert a.read_bytes() == b.read_bytes()
    head = text[:text.index("*/")]
    _, meta = models.load(sim_models["augmented"])
    assert meta["provenance"]["log_sha256"] in head and "augmented.npz" in head and '"tau": "Nm"' in head
    assert "#include <math.h>" in text and text.count("#include") == 1
    assert "malloc" not in text and "float " not in text


def test_numbers_are_written_to_round_trip():
    for x in (0.1, 1.0 / 3.0, -2.5e-300, 12.0, 1e22, np.float32(0.1), np.nextafter(1.0, 2.0)):
        assert float(c.num(x)) == float(x)
    assert c.num(3.0) == "3.0" and c.num(1e22) == "1e+22"


def test_step_takes_the_signals_in_the_documented_order(sim_models):
    text = c.export(sim_models["augmented"], "fr")
    assert "static inline double fr_step(fr_state *s, double t, double q, double qd, double qdd, double tau_m, " \
           "double tau_g, double tau_dyn, double temp)" in text                  # inputs only: no tau_ext
    assert " *   0. t [s] time" in text and " *   7. temp [degC] temperature" in text


@needs_cc
def test_a_folder_gives_one_function_set_per_joint(sim_models, tmp_path):
    folder = tmp_path / "arm"
    folder.mkdir()
    for joint, kind in (("joint2", "lugre-loaded"), ("joint4", "mlp")):
        (folder / f"{joint}.npz").write_bytes(Path(sim_models[kind]).read_bytes())
    (folder / "._joint2.npz").write_bytes(b"\x00\x05\x16\x07")   # what a copy to another file system leaves
    header = tmp_path / "arm.h"
    res = invoke("export", folder, "--prefix", "arm", "-o", header)
    assert res.exit_code == 0, res.output
    text = header.read_text()
    assert "._joint2" not in text
    assert "arm_joint2_step(arm_joint2_state *s, double t, double qd, double tau_g)" in text
    assert "arm_joint4_step(arm_joint4_state *s, double qd, double tau_g)" in text
    main = tmp_path / "main.c"
    main.write_text(f'#include "{header}"\n#include <stdio.h>\nint main(void) {{\n'
                    "    arm_joint2_state a; arm_joint4_state b;\n    arm_joint2_init(&a); arm_joint4_init(&b);\n"
                    '    printf("%.17g\\n", arm_joint2_step(&a, 0.0, 0.1, 5.0) + arm_joint4_step(&b, 0.1, 5.0));\n'
                    "    return 0;\n}\n")
    import subprocess

    for compiler, flags in ((check.compiler(), check.C_FLAGS), (check.compiler(cxx=True), check.CXX_FLAGS)):
        if compiler is None:
            continue
        exe = tmp_path / "main"
        proc = subprocess.run([compiler, *flags, str(main), "-o", str(exe), "-lm"], capture_output=True, text=True)
        assert proc.returncode == 0 and proc.stderr == "", proc.stderr
        assert np.isfinite(float(subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout))


@needs_cc
def test_softplus_and_tanh_activations_compile_to_the_reference_formulas(tmp_path):
    x = np.r_[-800.0, -40.0, -1.5, -1e-9, 0.0, 1e-9, 0.7, 40.0, 800.0]
    lines = ["#include <math.h>", "#include <stdio.h>", "int main(void) {",
             f"    static const double X[{len(x)}] = {c.array(x)};", "    int i;",
             f"    for (i = 0; i < {len(x)}; ++i) {{"]
    for name in ("softplus", "tanh"):
        lines += [f"        {{ double v = X[i]; {network.ACTIVATIONS[name](None, 'i')} printf(\"%.17g\\n\", v); }}"]
    lines += ["    }", "    return 0;", "}"]
    src = tmp_path / "act.c"
    src.write_text("\n".join(lines) + "\n")
    import subprocess

    exe = tmp_path / "act"
    subprocess.run([check.compiler(), *check.C_FLAGS, str(src), "-o", str(exe), "-lm"], check=True)
    out = np.array(subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split(), dtype=float)
    np.testing.assert_allclose(out[0::2], np.logaddexp(0.0, x), rtol=1e-15, atol=0)
    np.testing.assert_allclose(out[1::2], np.tanh(x), rtol=1e-15, atol=0)


@needs_cc
def test_the_elu_without_library_calls_is_within_rounding_of_numpy(tmp_path):
    """The exported ELU computes e^u by a Pade approximant and squaring, in passes: e^u - 1
    within 2e-14 of numpy's float64 ELU (its documented error bound, 1e-14, with room for the
    platform's rounding), v itself for v >= 0, past the clamp too."""
    from fricli.numerics.nn import activations as acts

    rng = np.random.default_rng(3)
    x = np.r_[-1e3, -40.5, -40.0, -39.9, -1e-300, -0.0, 0.0, 1e-300, 2.5, 1e3, -rng.exponential(3.0, 4000),
              rng.uniform(-1e-3, 0.0, 500), rng.normal(size=500)]
    passes = network.ACTIVATIONS["elu"](None, "i")
    lines = ["#include <math.h>", "#include <stdio.h>", "int main(void) {",
             f"    static const double X[{len(x)}] = {c.array(x)};", "    int i;",
             f"    for (i = 0; i < {len(x)}; ++i) {{",
             "        double v = X[i], t;", *[f"        {step}" for step in passes],
             "        printf(\"%.17g\\n\", v);",
             "    }", "    return 0;", "}"]
    src = tmp_path / "elu.c"
    src.write_text("\n".join(lines) + "\n")
    import subprocess

    exe = tmp_path / "elu"
    subprocess.run([check.compiler(), *check.C_FLAGS, str(src), "-o", str(exe), "-lm"], check=True)
    out = np.array(subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split(), dtype=float)
    np.testing.assert_allclose(out, acts.elu(x), rtol=0, atol=2e-14)
    assert np.array_equal(out[x >= 0], x[x >= 0])


def test_errors_are_one_line_with_the_documented_codes(sim_models, tmp_path):
    res = invoke("export", sim_models["mlp"], "--prefix", "9bad", "-o", tmp_path / "x.h")
    assert res.exit_code == 2
    res = invoke("export", tmp_path / "missing.npz", "-o", tmp_path / "x.h")
    assert res.exit_code == 4 and "no such file" in res.output
    empty = tmp_path / "empty"
    empty.mkdir()
    res = invoke("export", empty, "-o", tmp_path / "x.h")
    assert res.exit_code == 4 and "no .npz" in res.output
    assert not (tmp_path / "x.h").exists()


@needs_cc
def test_the_examples_in_the_deploy_doc_compile(sim_models, tmp_path):
    import re
    import subprocess

    from conftest import ROOT

    text = (ROOT / "docs" / "deploy.md").read_text()
    blocks = re.findall(r"```(c|cpp)\n(.*?)```", text, flags=re.S)
    assert [lang for lang, _ in blocks] == ["c", "c", "cpp"]
    assert invoke("export", sim_models["lugre-loaded"], "-o", tmp_path / "friction.h").exit_code == 0
    assert invoke("export", sim_models["augmented-gravity"], "--prefix", "j2", "-o",
                  tmp_path / "j2_friction.h").exit_code == 0
    assert "j2_HAS_MODEL_ERROR = 1 }" in (tmp_path / "j2_friction.h").read_text()
    for lang, code in blocks:
        cxx = lang == "cpp"
        compiler = check.compiler(cxx=cxx)
        if compiler is None:
            continue
        src = tmp_path / f"example.{lang}"
        src.write_text(code)
        flags = ["-Wall", "-Wextra", "-pedantic", "-Werror", "-O2"] + ([] if cxx else ["-std=c99"])
        proc = subprocess.run([compiler, *flags, "-c", str(src), "-o", str(tmp_path / "example.o")],
                              capture_output=True, text=True)
        assert proc.returncode == 0 and proc.stderr == "", proc.stderr


def test_set_precision_reaches_every_network_of_a_model_tree(sim_models):
    model, _ = models.load(sim_models["residual-mlp"])
    assert {model.base.precision, model.add.precision} == {"single"}
    models.set_precision(model, "double")
    assert {model.base.precision, model.add.precision} == {"double"}
    with pytest.raises(ValueError):
        models.set_precision(model, "half")
    sig = logs.load_log(str(SAMPLE / "joint2_extended_asym.parquet")).signals
    double = model.predict(sig)[0]
    single = models.set_precision(model, "single").predict(sig)[0]
    assert 0 < np.max(np.abs(double - single)) < 1e-3
    model, _ = models.load(sim_models["residual-dissipative"])
    double = models.set_precision(model, "double").predict(sig)[0]
    assert model.base.precision == "double" and model.base.net_.dtype == np.float32   # the file's weights stay
    assert 0 < np.max(np.abs(double - models.set_precision(model, "single").predict(sig)[0])) < 1e-3


@needs_cc
@pytest.mark.parametrize("cxx", [False, True])
def test_signals_named_like_the_step_functions_own_names_compile(cxx, tmp_path):
    """Log columns a model reads by name become the step function's parameters: a column named as the
    function's state (s), its locals (in, in_), its output (model_error), a C++ keyword (and, not),
    a macro of <math.h> (HUGE_VAL), a reserved name (__x, _Y) or a name of the header's own (fr_in,
    fr_m_step, FRICLI_AVX2) still gives a header that compiles (C and C++, warnings as errors) and
    equals fricli predict."""
    import pyarrow as pa

    names = ["s", "in", "in_", "model_error", "and", "not", "HUGE_VAL", "__x", "_Y", "fr_in", "fr_m_step",
             "fr_sgn", "FRICLI_AVX2"]
    table = pq.read_table(str(SAMPLE / "joint2_extended_asym.parquet"))
    rng = np.random.default_rng(4)
    for name in names:
        table = table.append_column(name, pa.array(rng.normal(size=table.num_rows)))
    log_path = str(tmp_path / "columns.parquet")
    pq.write_table(table, log_path)
    log = logs.load_log(log_path)
    terms = [{"name": n, "factors": [{"f": "signal", "name": n}]} for n in names]
    model = AugmentedModel(LuGreModel(7.0, 9.0, 0.04, 1.2, 12.0, sigma0=1.7e4, sigma1=0.5), terms,
                           np.linspace(0.1, 0.9, len(names)), effects=[f"column:{n}" for n in names])
    path = str(tmp_path / "columns.npz")
    models.save_for_log(path, model, log, rows_used=len(log))
    header = str(tmp_path / "fr.h")
    assert invoke("export", path, "-o", header, "--prefix", "fr", "-q").exit_code == 0
    exe = str(tmp_path / "fr_driver")
    assert check.build(header, "fr", exe, cxx=cxx) == ""
    out = tmp_path / "pred.parquet"
    assert invoke("predict", path, log_path, "-o", out, "--precision", "double", "-q").exit_code == 0
    ref = pq.read_table(out).column("tau_f_pred").to_numpy()
    got = check.run(exe, check.signal_matrix(log.signals, c.signals_of(model)))
    assert np.max(np.abs(got - ref) / (ABS + REL * np.abs(ref))) <= 1.0


@pytest.mark.parametrize("files, observer", [(["joint_1.npz", "joint_1_m.npz"], False), (["arm.npz"], True)])
def test_model_files_whose_c_names_would_collide_are_refused(files, observer, tmp_path):
    """The C names of a folder's models are PREFIX_<file name>_*, each model's parts under them: a file
    named like another's part (joint_1_m beside joint_1) or like the arm's functions (arm with --observer
    --prefix arm) would define one name twice, a header that does not compile. Refused naming the files."""
    log = logs.load_log(str(SAMPLE / "joint2_base.parquet"))
    folder = tmp_path / "models"
    folder.mkdir()
    for name in files:
        models.save_for_log(str(folder / name), LuGreModel(7.0, 9.0, 0.04, 1.2, 12.0, sigma0=1.7e4, sigma1=0.5), log,
                            rows_used=len(log))
    header = tmp_path / "arm.h"
    res = invoke("export", folder, "--prefix", "arm", "-o", header, *(["--observer"] if observer else []))
    assert res.exit_code == 4 and res.output.count("\n") == 1 and not header.exists(), res.output
    assert all(name in res.output for name in files) and "rename" in res.output


def test_the_python_call_is_the_command(tmp_path):
    """``fricli.export_header`` writes the command's header and refuses what it refuses."""
    import fricli
    from fricli.fitting.optionspec import OptionError

    model = tmp_path / "lugre.npz"
    fricli.LuGre().fit(SAMPLE / "joint2_base.parquet").save(model)
    done = invoke("export", model, "--prefix", "arm", "-o", tmp_path / "cmd.h")
    assert done.exit_code == 0, done.output
    text = fricli.export_header(str(model), str(tmp_path / "call.h"), prefix="arm")
    assert (tmp_path / "call.h").read_text() == (tmp_path / "cmd.h").read_text() == text
    for kwargs, option in (({"prefix": "2arm"}, "prefix"), ({"adapt": True}, "observer")):
        with pytest.raises(OptionError) as err:
            fricli.export_header(str(model), str(tmp_path / "refused.h"), **kwargs)
        assert err.value.option == option
    assert not (tmp_path / "refused.h").exists()
    refused = invoke("export", model, "--prefix", "2arm", "-o", tmp_path / "refused.h")
    assert refused.exit_code == 2 and "--prefix" in refused.output


@pytest.mark.parametrize("prefix", ["1abc", "a-b", "int"])
def test_a_prefix_that_is_no_c_name_is_clicks_usage_error(tmp_path, prefix):
    """An option error of the Python call shows as click's on the option, as docs/exit-codes.md says
    of code 2: Usage, Try and Error lines, and no file."""
    from fricli import LuGre

    model = tmp_path / "m.npz"
    LuGre().fit(str(SAMPLE / "joint2_base.parquet")).save(model)
    res = invoke("export", model, "--prefix", prefix, "-o", tmp_path / "h.h")
    lines = res.stderr.splitlines()
    assert res.exit_code == 2 and lines[0].startswith("Usage: ") and " export " in lines[0] and lines[1].startswith("Try ")
    assert f"Error: Invalid value for '--prefix': the prefix '{prefix}' is not a C identifier" in res.stderr
    assert not (tmp_path / "h.h").exists()
