"""The dissipative network's exported step with its constants folded in and its zero-weight terms
left out: C equals `fricli predict --precision double` to 1e-9 on every row for each variant (no
load term, no prior, no bristles, blend 0 and 1, a prior without its Stribeck shape, an ensemble,
extrapolation below v_min and above v_max with a slope, the settled Stribeck shape and bristle decay
that the step skips), and predict leaves out only terms that add 0. The networks' magnitude is
written as polynomial pieces of the speed input (``fricli.export.piecewise``) where the speed has a
top, as the layers otherwise ("no extrapolation"); the pieces agree with the networks.
"""

from __future__ import annotations

import numpy as np
import pytest

from conftest import SAMPLE
from fricli import models
from fricli.core import logs
from fricli.export import c, neural
from fricli.numerics import piecewise
from fricli.models import dissipative as D
from fricli.models.dissipative import DissipativeFriction
from test_export import _compare, needs_cc

LOG = str(SAMPLE / "joint2_base.parquet")
PRIOR = {"fc": 7.0, "fs": 9.0, "vs": 0.04, "delta": 1.2, "fv": 12.0, "kc": 0.04, "ks": 0.05}
NARROW = {"fc": 7.0, "fs": 9.0, "vs": 0.005, "delta": 2.0, "fv": 12.0, "kc": 0.04, "ks": 0.05}   # shape 0 early
FLAT = {"fc": 7.5, "fs": 7.5, "vs": 0.04, "delta": 1.2, "fv": 0.0, "kc": 0.0, "ks": 0.0}   # no shape, no load


def _fit(members: int = 1) -> DissipativeFriction:
    log = logs.load_log(LOG)
    sig = log.signals
    rows = np.arange(0, len(log), 97)
    rows = rows[sig["qd"][rows] != 0]
    target = logs.friction_target(sig)[rows]
    pick = {k: v[rows] for k, v in sig.items()}
    model = DissipativeFriction(steps=60, hidden_sizes=(12, 10)).fit(pick, target, rng=np.random.default_rng(3))
    if members > 1:
        nets = [model.net_] + [DissipativeFriction(steps=40, hidden_sizes=(12, 10)).fit(
            pick, target, rng=np.random.default_rng(4 + k), scales_from=model).net_ for k in range(members - 1)]
        model.set_members(nets, pick["qd"])
    # inputs beyond the training speeds on both sides: the clamps at v_min and v_max, a positive slope
    top = float(np.max(np.abs(sig["qd"])))
    model.v_max_, model.v_min_ = (0.5 * top, 0.4 * top), (0.05 * top, 0.04 * top)
    model.slope_ = (0.3, 0.7)
    return model


def _variant(model: DissipativeFriction, *, prior=None, blend=None, sigma0=None, load=True,
             extrapolation=True) -> DissipativeFriction:
    model.set_prior(prior, blend)
    model.sigma0_, model.load_ = sigma0, load
    if not extrapolation:
        model.v_max_ = model.v_min_ = model.slope_ = None
    return model


VARIANTS = {
    "network alone": dict(),
    "no load term": dict(load=False),
    "no extrapolation": dict(extrapolation=False),
    "bristles": dict(sigma0=2e4),
    "prior blend 0.4": dict(prior=PRIOR, blend=0.4),
    "prior blend 0.4, bristles": dict(prior=PRIOR, blend=0.4, sigma0=2e4),
    "prior blend 0, bristles": dict(prior=PRIOR, blend=0.0, sigma0=2e4),
    "prior blend 0": dict(prior=PRIOR, blend=0.0),
    "prior blend 1, bristles": dict(prior=PRIOR, blend=1.0, sigma0=2e4),
    "flat prior blend 0.5, no load": dict(prior=FLAT, blend=0.5, load=False),
    # the settled shortcuts: the Stribeck shape past v_cut, the bristle decay of stiff bristles
    "narrow prior blend 0.2, stiff bristles": dict(prior=NARROW, blend=0.2, sigma0=1e9),
}


@needs_cc
@pytest.mark.parametrize("name", list(VARIANTS))
def test_each_variant_exports_the_numbers_of_predict(name, tmp_path):
    model = _variant(_fit(), **VARIANTS[name])
    path = str(tmp_path / "m.npz")
    models.save_for_log(path, model, logs.load_log(LOG), rows_used=100, seed=0)
    assert _compare(path, LOG, tmp_path) <= 1.0


@needs_cc
def test_an_ensemble_over_a_prior_exports_the_numbers_of_predict(tmp_path):
    model = _variant(_fit(members=2), prior=PRIOR, blend=0.3, sigma0=2e4)
    path = str(tmp_path / "m.npz")
    models.save_for_log(path, model, logs.load_log(LOG), rows_used=100, seed=0)
    assert _compare(path, LOG, tmp_path) <= 1.0


def _header(model, tmp_path) -> str:
    path = str(tmp_path / "m.npz")
    models.save_for_log(path, model, logs.load_log(LOG), rows_used=100, seed=0)
    return c.export(path, "fr")


def test_terms_of_weight_zero_are_not_written(tmp_path):
    text = _header(_variant(_fit(), prior=PRIOR, blend=1.0, sigma0=2e4), tmp_path)
    assert "fr_m_mag(" in text and "exp(-exp(" not in text           # blend 1: no prior
    text = _header(_variant(_fit(), prior=PRIOR, blend=0.0, sigma0=2e4), tmp_path)
    assert "fr_m_mag" not in text and "exp(-exp(" in text            # blend 0: no network
    text = _header(_variant(_fit(), prior=FLAT, blend=0.5), tmp_path)
    assert "fr_m_mag(" in text and "exp(-exp(" not in text           # fs = fc, ks = kc: no Stribeck shape
    model = _variant(_fit(), load=False)
    model.slope_ = (0.0, 0.0)
    text = _header(model, tmp_path)
    assert "tau_g" not in text.split("fr_m_step")[1].split("}\n")[0] and "qd - " not in text.split("fr_m_step")[1]
    assert c.signals_of(model) == ["qd", "tau_g"]          # the step's signature does not depend on the terms


def test_the_settled_shortcuts_are_taken_on_the_sample_log():
    sig = logs.load_log(LOG).signals
    model = _variant(_fit(), prior=NARROW, blend=0.2, sigma0=1e9)
    v_cut = NARROW["vs"] * neural.SETTLED ** (1.0 / NARROW["delta"])
    speed = np.abs(sig["qd"])
    assert 0.1 < np.mean(speed >= v_cut) < 0.9          # both sides of v_cut are compared above
    g = model._bristle_curve(sig)
    decay = model.sigma0_ * speed[1:] * np.diff(sig["t"]) / g[1:]
    assert 0.1 < np.mean(decay >= neural.SETTLED) < 0.99


def test_predict_leaves_out_only_what_adds_zero():
    sig = logs.load_log(LOG).signals
    with_prior = _variant(_fit(), prior=PRIOR, blend=1.0, sigma0=2e4)
    alone = _variant(_fit(), sigma0=2e4)
    assert np.array_equal(with_prior.predict(sig)[0], alone.predict(sig)[0])   # blend 1: the network alone
    a = _variant(_fit(), prior=PRIOR, blend=0.0, sigma0=2e4)
    b = _variant(_fit(), prior=PRIOR, blend=0.0, sigma0=2e4)
    b.net_.set_weights([w * 3.0 for w in b.net_.weights])                   # another network
    pa, pb = a.predict(sig)[0], b.predict(sig)[0]
    assert np.array_equal(pa, pb)                                             # blend 0: the prior alone
    a.set_prior(PRIOR, 1e-9)                                                  # next to 0: the network counts
    assert np.allclose(a.predict(sig)[0], pa, rtol=1e-6, atol=1e-6) and not np.array_equal(a.predict(sig)[0], pa)


def test_the_bristle_blocks_carry_the_state(monkeypatch):
    sig = logs.load_log(LOG).signals
    model = _variant(_fit(), prior=PRIOR, blend=0.4, sigma0=2e4)
    whole, state = model.predict(sig)
    monkeypatch.setattr(D, "BRISTLE_BLOCK", 1000)
    blocks, state2 = model.predict(sig)
    assert len(sig["t"]) > 10 * 1000
    np.testing.assert_allclose(blocks, whole, rtol=1e-12, atol=1e-12)
    assert state2[1] == state[1] and abs(state2[0] - state[0]) <= 1e-12 * (1.0 + abs(state[0]))


@pytest.mark.parametrize("members", [1, 3])
def test_the_magnitude_pieces_agree_with_the_networks_between_their_check_points(members):
    """At 20,000 random speeds of each direction (not the points the pieces were checked at),
    and at qd = 0, the pieces give the networks' magnitude to piecewise.TOL."""
    model = _variant(_fit(members=members), prior=PRIOR, blend=0.5, sigma0=2e4)
    pieces = model.magnitude_pieces()
    rng = np.random.default_rng(0)
    model.blend_, model.precision = 1.0, "double"    # the networks alone, m = softplus(r0), as the C step
    for k, (side, sign) in enumerate(((pieces.pos, 1.0), (pieces.neg, -1.0))):
        speed = rng.uniform(model.v_min_[k], model.v_max_[k], 20_000)
        qd = sign * speed
        want = model.magnitude({"qd": qd, "tau_g": np.zeros_like(qd)}) / model.y_scale_
        got = side(model.speed_input(speed))
        assert np.max(np.abs(got - want) / np.maximum(1.0, want)) <= 2 * piecewise.TOL
        np.testing.assert_allclose(pieces(model.speed_input(speed), np.sign(qd)), got, rtol=1e-14, atol=1e-14)
        assert len(side.table) < piecewise.MAX_PIECES and side.error <= piecewise.TOL
    model.load_ = False
    assert pieces.at_rest == pytest.approx(model.magnitude({"qd": np.zeros(1)})[0] / model.y_scale_, rel=1e-15)


def test_without_a_top_speed_there_are_no_pieces():
    model = _variant(_fit(), extrapolation=False)
    assert model.magnitude_pieces() is None


@pytest.mark.parametrize("members", [1, 2])
def test_a_large_batch_predicts_through_the_pieces_as_the_networks_do(members):
    """From PIECES_ROWS rows on, predict takes the magnitude from the pieces: the networks' numbers in
    double precision to 1e-11 (the float32 networks' to their rounding); new weights, new pieces."""
    model = _variant(_fit(members=members), prior=PRIOR, blend=0.4, sigma0=2e4)
    sig = logs.load_log(LOG).signals
    reps = -(-D.PIECES_ROWS // len(sig["t"]))
    big = {k: np.tile(v, reps) for k, v in sig.items()}
    big["t"] = np.arange(len(big["qd"])) * 1e-3
    big["qd"][::7] = 0.0                                            # rows at rest too
    assert len(big["t"]) >= D.PIECES_ROWS
    model.precision = "double"
    fast = model.predict(big)[0]
    built = model._pieces[1]
    assert built is not None
    parts, state = [], None
    for i in range(0, len(big["t"]), 5000):                        # batches below PIECES_ROWS: the networks
        y, state = model.predict({k: v[i:i + 5000] for k, v in big.items()}, state)
        parts.append(y)
    slow = np.concatenate(parts)
    np.testing.assert_allclose(fast, slow, rtol=1e-11, atol=1e-11 * np.max(np.abs(slow)))
    model.precision = "single"
    np.testing.assert_allclose(model.predict(big)[0], slow, rtol=1e-5, atol=1e-5 * np.max(np.abs(slow)))
    model.net_.set_weights([w * 1.01 for w in model.net_.weights])
    assert model.magnitude_pieces() is not built and not np.allclose(model.predict(big)[0], fast)


def test_crossings_are_found_to_the_last_bit_and_pieces_meet_the_tolerance():
    roots = np.array([-0.7, 0.123456789, 0.5])
    pre = lambda u: [np.vstack([u - r for r in roots])]                       # noqa: E731
    found = piecewise.crossings(pre, -1.0, 1.0)
    np.testing.assert_allclose(found, roots, rtol=0, atol=4e-16)
    kinked = lambda u: np.where(u > roots[1], np.expm1(-(u - roots[1])), -(u - roots[1])) + np.sin(3 * u)  # noqa: E731
    with_breaks = piecewise.fit(kinked, -1.0, 1.0, found)
    u = np.random.default_rng(1).uniform(-1.0, 1.0, 50_000)
    assert np.max(np.abs(with_breaks(u) - kinked(u))) <= 2 * piecewise.TOL
    halved = piecewise.fit(kinked, -1.0, 1.0)                                 # the kink not given: found by halving
    assert np.max(np.abs(halved(u) - kinked(u))) <= 2 * piecewise.TOL and len(halved.table) > len(with_breaks.table)
    noise = np.random.default_rng(2).normal(size=1000)
    assert piecewise.fit(lambda v: noise[np.minimum((v + 1) * 500, 999).astype(int)], -1.0, 1.0) is None


def test_the_docs_and_the_help_give_the_batch_size_of_the_pieces():
    from click.testing import CliRunner
    from conftest import ROOT
    from fricli.cli import cli
    rows = f"{D.PIECES_ROWS:,}"
    assert f"batch of {rows} rows or more (`PIECES_ROWS`" in (ROOT / "docs" / "deploy.md").read_text()
    assert f"batches of {rows} rows or more" in (ROOT / "docs" / "neural-models.md").read_text()
    assert f"batches of {rows} rows" in " ".join(CliRunner().invoke(cli, ["predict", "--help"]).output.split())
