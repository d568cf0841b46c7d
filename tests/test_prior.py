"""The dissipative network blended with the LuGre model's static curve (the prior): the
network's share chosen on held-out rows of the training log (``learning.blend_prior``)."""

import copy
import json

import numpy as np
import pytest
from click.testing import CliRunner

from conftest import no_inertia, write
from fricli import models
from fricli.cli import cli
from fricli.core import logs, metrics
from fricli.core.logs import table_from_arrays
from fricli.fitting import learning
from fricli.models.dissipative import PRIOR_KEYS, DissipativeFriction
from test_dissipative import assert_dissipative, grid
from test_export import _compare, needs_cc
from test_neural import UNITS, harmonic_log, harmonic_motion


def bump_log(seed: int, seconds: float = 30.0, rate: float = 100.0):
    """A sum of harmonics whose friction magnitude has a bump at 0.3 rad/s, which no Stribeck plus
    viscous curve has; noise 0.2 Nm."""
    rng, sig = harmonic_motion(seed, rate, seconds)
    qd, g = sig["qd"], sig["tau_g"]
    f = np.sign(qd) * (5 + 3 * np.exp(-((np.abs(qd) - 0.3) / 0.08) ** 2) + 2 * np.abs(qd))
    cols = {**sig, "tau_m": g + f + rng.normal(0, 0.2, qd.size), "tau_f_true": f}
    return no_inertia(table_from_arrays(cols, UNITS))


def moving_error(model, log) -> float:
    """RMS [Nm] of the true friction minus the prediction over the rows in motion."""
    sig = log.signals
    e = (sig["tau_f_true"] - model.predict(sig)[0])[metrics.in_motion(sig["qd"])]
    return float(np.sqrt(np.mean(e ** 2)))


@pytest.fixture(scope="module")
def lugre_form(tmp_path_factory):
    """Friction of the LuGre static form (``test_neural.static_friction``): trained with and
    without the prior, and another log of the same joint."""
    d = tmp_path_factory.mktemp("prior")
    train = logs.load_log(str(write(harmonic_log(seed=8, seconds=30.0), d / "train.parquet")))
    other = logs.load_log(str(write(harmonic_log(seed=9, seconds=30.0), d / "other.parquet")))
    with_prior, summary = learning.train_base(train, steps=150, seed=1)
    alone, _ = learning.train_base(train, steps=150, seed=1, prior=False)
    return {"train": train, "other": other, "model": with_prior, "summary": summary, "alone": alone, "dir": d}


def test_blend_weight_is_the_least_squares_share_within_0_and_1():
    rng = np.random.default_rng(0)
    prior, network = rng.normal(size=200), rng.normal(size=200)
    y = prior + 0.3 * (network - prior)
    assert learning.blend_weight(y, network, prior) == pytest.approx(0.3)
    assert learning.blend_weight(network + (network - prior), network, prior) == 1.0   # clipped
    assert learning.blend_weight(prior - (network - prior), network, prior) == 0.0
    assert learning.blend_weight(y, prior, prior) == 1.0                               # nothing to choose


def test_held_out_rows_choose_the_prior_where_the_network_does_not_help(lugre_form):
    """A network of 150 steps has not learned the curve that the prior has exactly: held out, the
    blend keeps little of it, and on another log the model errs less than the network alone."""
    model, held = lugre_form["model"], lugre_form["summary"]["prior"]
    assert 0.0 <= model.blend_ == held["blend"] <= 1.0
    assert held["blend_rmse"] <= min(held["prior_rmse"], held["network_rmse"])
    assert held["prior_rmse"] < held["network_rmse"]
    assert set(held["prior"]) == set(PRIOR_KEYS) and model.prior_ == held["prior"]
    assert lugre_form["alone"].prior_ is None
    assert moving_error(model, lugre_form["other"]) < moving_error(lugre_form["alone"], lugre_form["other"])


def test_held_out_rows_keep_the_network_where_it_beats_the_prior(tmp_path):
    """A bump in the friction curve that the prior cannot follow: the network's share is the larger."""
    log = logs.load_log(str(write(bump_log(seed=3), tmp_path / "bump.parquet")))
    model, summary = learning.train_base(log, steps=600, seed=0, bristles="off")
    held = summary["prior"]
    assert held["network_rmse"] < held["prior_rmse"] and model.blend_ > 0.5
    assert held["blend_rmse"] <= held["network_rmse"]
    other = logs.load_log(str(write(bump_log(seed=4), tmp_path / "other.parquet")))
    prior_only = copy.copy(model)
    prior_only.blend_ = 0.0
    assert moving_error(model, other) < moving_error(prior_only, other)


def test_the_blend_is_the_prior_plus_a_share_of_the_network(lugre_form):
    model, sig = copy.deepcopy(lugre_form["model"]), lugre_form["other"].signals
    model.sigma0_ = None                                   # the static map: tanh(qd / v_ps) * magnitude
    blend, prior = model.blend_, model.prior_
    network = copy.copy(model)
    network.set_prior(None)
    p = model.prior_magnitude(sig)
    np.testing.assert_allclose(model.magnitude(sig), blend * network.magnitude(sig) + (1 - blend) * p, rtol=1e-9)
    fc, fs = prior["fc"] + prior["kc"] * np.abs(sig["tau_g"]), prior["fs"] + prior["ks"] * np.abs(sig["tau_g"])
    curve = fc + (fs - fc) * np.exp(-np.abs(sig["qd"] / prior["vs"]) ** prior["delta"]) + prior["fv"] * np.abs(sig["qd"])
    np.testing.assert_allclose(p, curve, rtol=1e-12)
    np.testing.assert_allclose(model.predict(sig)[0], np.tanh(sig["qd"] / model.v_ps_) * model.magnitude(sig),
                               rtol=1e-6, atol=1e-9)


def test_dissipative_for_any_weights_prior_and_blend(lugre_form):
    rng = np.random.default_rng(4)
    sig = grid(lugre_form["train"].signals, scale=1.5)
    for _ in range(5):
        model = copy.deepcopy(lugre_form["model"])
        model.sigma0_ = None
        for net in model.nets_:
            net.theta[~net.frozen] = rng.normal(0, 2, (~net.frozen).sum())
        model.set_prior({**{k: float(rng.uniform(0, 5)) for k in PRIOR_KEYS}, "vs": 0.05}, float(rng.uniform()))
        assert_dissipative(model, sig, model.v_ps_)
        assert (model.magnitude(sig) >= 0).all()


def test_the_prior_round_trips_and_damaged_ones_are_refused(lugre_form, tmp_path):
    model, sig = lugre_form["model"], lugre_form["other"].signals
    path = str(tmp_path / "m.npz")
    models.save_for_log(path, model, lugre_form["train"], rows_used=1)
    loaded, meta = models.load(path)
    assert meta["model"]["params"]["prior"] == {**model.prior_, "blend": model.blend_}
    assert np.array_equal(loaded.predict(sig)[0], model.predict(sig)[0])
    assert "LuGre static curve" in loaded.describe() and "LuGre static curve" not in lugre_form["alone"].describe()
    assert "prior" not in models.to_parts(lugre_form["alone"])[0]["params"]   # files without it stay as they were
    spec, arrays = models.to_parts(model)
    good = spec["params"]["prior"]
    for key, bad in (("blend", 1.5), ("blend", -0.1), ("fv", -1.0), ("vs", 0.0), ("delta", float("nan")),
                     ("fc", "x"), ("ks", None)):
        spec["params"]["prior"] = {**good, key: bad}
        with pytest.raises(ValueError, match="prior"):
            DissipativeFriction.from_parts(spec["params"], arrays, {})


def test_no_prior_option(lugre_form):
    d = lugre_form["dir"]
    for flag, has in (([], True), (["--no-prior"], False)):
        out = d / f"cli{len(flag)}.npz"
        res = CliRunner().invoke(cli, ["train-base", str(d / "train.parquet"), "--steps", "20", *flag,
                                       "-o", str(out), "--json", "-q"])
        assert res.exit_code == 0, res.output
        assert (models.load(str(out))[0].prior_ is not None) == has == ("prior" in json.loads(res.stdout))


@needs_cc
def test_export_with_the_prior_matches_predict(lugre_form, tmp_path):
    """The exported C code blends the prior as predict --precision double does (1e-9), for a share
    strictly between 0 and 1 (both terms show)."""
    model = copy.deepcopy(lugre_form["model"])
    model.blend_ = 0.4
    path = str(tmp_path / "blend.npz")
    models.save_for_log(path, model, lugre_form["train"], rows_used=1)
    assert _compare(path, str(lugre_form["dir"] / "other.parquet"), tmp_path) <= 1.0


def test_a_prior_that_cannot_be_fitted_leaves_the_network_alone(lugre_form, monkeypatch):
    calls = []

    def failing(*args):
        calls.append(1)
        return None if len(calls) == 2 else real(*args)       # the second fold's prior fails

    real = learning.fit_prior
    monkeypatch.setattr(learning, "fit_prior", failing)
    model, summary = learning.train_base(lugre_form["train"], steps=20, seed=1, bristles="off")
    assert summary["prior"] == {"blend": 1.0} and model.prior_ is None and len(calls) == 2
    alone, _ = learning.train_base(lugre_form["train"], steps=20, seed=1, bristles="off", prior=False)
    sig = lugre_form["other"].signals
    np.testing.assert_array_equal(model.predict(sig)[0], alone.predict(sig)[0])
