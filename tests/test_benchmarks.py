"""The benchmark script runs end to end on tiny sizes (no timing is checked)."""

import importlib.util
import json
import pathlib
import subprocess
import sys

import numpy as np
import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
SCRIPT = ROOT / "benchmarks" / "run.py"


def _load():
    spec = importlib.util.spec_from_file_location("fricli_benchmarks", SCRIPT)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def quick_run():
    proc = subprocess.run([sys.executable, str(SCRIPT), "--quick", "--json", "--skip-torch"], cwd=ROOT,
                          capture_output=True, text=True, timeout=600)
    assert proc.returncode == 0, proc.stderr
    return proc


@pytest.mark.slow
def test_quick_run_prints_every_measurement(quick_run):
    res = json.loads(quick_run.stdout)
    names = [r["name"] for r in res["rows"]]
    groups = {r["group"] for r in res["rows"]}
    assert groups == {"train", "startup", "limit", "lugre", "predict", "diagnose", "export"}
    for kind in ("lugre", "dissipative", "mlp", "selmic", "nnacm", "residual", "augmented"):
        assert any(n.startswith(f"{kind}: model.predict") for n in names), kind
    assert any(n.startswith("train-base default") for n in names)
    assert any(n.startswith("plain pyarrow") for n in names)
    for command in ("predict", "estimate-ext"):
        assert any(n.endswith(f"{command} / plain pyarrow") for n in names), command
    assert any(n.startswith("fricli --version") for n in names)
    assert any(n.startswith("identify") for n in names)
    assert any(n.startswith("diagnose command") for n in names)
    measured = [r for r in res["rows"] if r["value"] is not None]
    assert all(np.isfinite(r["value"]) and r["value"] > 0 for r in measured)
    skipped = [r for r in res["rows"] if r["value"] is None]
    assert [r["name"] for r in skipped if r["group"] != "export"] == ["PyTorch"] and "skipped" in skipped[0]["note"]
    for kind in ("lugre", "dissipative", "mlp", "selmic", "nnacm", "residual", "augmented"):
        assert any(n.startswith(f"{kind}: exported C step") for n in names) or "exported C step" in names, kind
    # the table goes to stderr as well
    assert "| group | measurement | value | unit | note |" in quick_run.stderr


def test_python_loop_reference_matches_the_library():
    bench = _load()
    from fricli.numerics import physics

    rng = np.random.default_rng(0)
    n = 500
    v = np.repeat(rng.uniform(-0.5, 0.5, 25), 20)
    v[::37] = 0.0
    dt = np.full(n, 1e-3)
    g = physics.stribeck(v, 10.0, 14.0, 0.05, 1.5)
    ref, _ = physics.lugre_friction(v, g, 20.0, 1e5, 30.0, dt, 0.0)
    loop = bench.lugre_loop(v, g, 20.0, 1e5, 30.0, dt, 0.0)
    np.testing.assert_allclose(loop, ref, rtol=1e-9, atol=1e-9)


def test_matmul_flops_counts_the_products():
    bench = _load()
    net = bench.mlp(30)
    # forward 2*(30*3 + 30*31 + 1*31) per sample, the same again for the weight gradients, and
    # back-propagation through the last two layers 2*(30*30 + 1*30)
    per_sample = 2 * 2 * (90 + 930 + 31) + 2 * (900 + 30)
    assert bench.matmul_flops(net, 10) == pytest.approx(10 * per_sample)


def test_predict_pairs_runs_end_to_end():
    proc = subprocess.run([sys.executable, str(ROOT / "benchmarks" / "predict_pairs.py"), "--rows", "2000",
                           "--pairs", "2", "--kind", "mlp", "--command", "estimate-ext"],
                          cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stderr
    lines = proc.stdout.splitlines()
    assert [line.split(":")[0] for line in lines[:2]] == ["pair 1", "pair 2"]
    assert lines[2].startswith("mlp estimate-ext / plain pyarrow over 2 pairs, 2,000 rows: median")


@pytest.mark.slow
def test_the_closed_loop_default_calibrates_a_stribeck_arm_better(tmp_path, fricli_in_process):
    """benchmarks/arm7_closed_loop.py on 20 s runs: with Stribeck friction in the arm, the closed
    loop's default calibration (the bump fitted with the rigid body) gives a rigid body closer to
    the true one on every joint, and a smaller friction error on average, than a linear one."""
    pytest.importorskip("pinocchio")
    spec = importlib.util.spec_from_file_location("arm7", ROOT / "benchmarks" / "arm7_closed_loop.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    results = module.study(str(tmp_path), duration=20.0)
    (fric_lin, body_lin), (fric_str, body_str) = results["linear"], results["stribeck"]
    assert (body_str < body_lin).all(), (body_str, body_lin)
    assert fric_str.mean() < fric_lin.mean(), (fric_str, fric_lin)
