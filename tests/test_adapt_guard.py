"""adapt's held-out decision: NN_add is scored on the half of the log's pieces it was not trained on.

Another run of a joint lies on one side in time of the log NN_add learned from; a real joint's
residual drifts (its friction level moves as it warms), so held-out pieces between training
pieces would show a gain that another run does not.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import pytest

from fricli.core import logs
from fricli.fitting import learning, training_data
from fricli.models.linear import LinearFriction

N = 2000


def test_each_half_is_held_out_once_and_predicted_by_the_other():
    blocks = training_data.time_block(N)
    blocks[:7] = -1                      # rows not used (at rest)
    trained_on = []

    def fit_predict(train):
        trained_on.append(train)
        return np.full(N, float(len(trained_on)))

    held = learning.cross_validate(fit_predict, blocks, np.zeros(N), np.zeros(N))
    half = training_data.PIECES // 2
    assert held["folds"] == learning.FOLDS == 2 and len(trained_on) == 2
    np.testing.assert_array_equal(np.unique(blocks[trained_on[0]]), np.arange(half))
    np.testing.assert_array_equal(np.unique(blocks[trained_on[1]]), np.arange(half, training_data.PIECES))
    assert held["pieces"] == training_data.PIECES and held["rows"] == N - 7


def test_a_network_that_helps_only_one_half_is_not_kept():
    """Trained on the first half it removes most of the second half's residual; trained on the
    second it removes 0.5 % of the first's, in every piece: pooled, that is a large and
    significant gain, but one that depends on which side in time the network is used."""
    rng = np.random.default_rng(3)
    blocks = training_data.time_block(N)
    target = rng.normal(0.0, 1.0, N)
    second = blocks >= training_data.PIECES // 2

    def fit_predict(train):
        first_trained = not second[train].any()
        return np.where(second, 0.8 * target, 0.0) if first_trained else np.where(second, 0.0, 0.005 * target)

    held = learning.cross_validate(fit_predict, blocks, target, np.zeros(N))
    assert held["adapted_rmse"] < 0.8 * held["base_rmse"] and held["gain_mean"] > 2 * held["gain_se"]
    np.testing.assert_allclose(sorted(held["half_ratios"]), [0.2, 0.995], rtol=1e-3)
    assert not held["helps"]

    def helps_both(train):
        return 0.5 * target
    both = learning.cross_validate(helps_both, blocks, target, np.zeros(N))
    np.testing.assert_allclose(both["half_ratios"], [0.5, 0.5])
    assert both["helps"]


def test_pieces_in_one_half_only_are_not_a_held_out_check():
    blocks = training_data.time_block(N)
    blocks[blocks >= training_data.PIECES // 2] = -1      # the second half's rows are not used
    held = learning.cross_validate(lambda train: np.zeros(N), blocks, np.ones(N), np.zeros(N))
    assert held["half_ratios"] == [] and not held["helps"]


def drifting_log(seconds: float, shift: float, until: float, rng: np.random.Generator) -> logs.Log:
    """A harmonic motion whose friction is the base's plus a Coulomb level of ``shift`` [Nm] over
    the first ``until`` share of the log and none after (a level that settles as the joint warms
    up), with 0.05 Nm of noise."""
    t = np.arange(0.0, seconds, 0.01)
    qd = 0.6 * np.sin(2 * np.pi * t / 4.0) + 0.3 * np.sin(2 * np.pi * t / 1.7 + 1.0)
    q = np.cumsum(qd) * 0.01
    tau_g = 20.0 * np.cos(q)
    base = LinearFriction(2.0, 1.5)
    level = np.where(t < until * t[-1], shift, 0.0)
    tau_f = base.predict({"qd": qd})[0] + level * np.sign(qd) + rng.normal(0.0, 0.05, t.size)
    cols = {"t": t, "q": q, "qd": qd, "qdd": np.gradient(qd, t), "tau_g": tau_g, "tau_dyn": np.zeros_like(t),
            "tau_m": tau_f + tau_g}
    return as_log(cols)


def as_log(cols: dict[str, np.ndarray]) -> logs.Log:
    """A log of one rotary joint with the signals ``cols`` (canonical units)."""
    return logs.Log(table=pa.table(cols), signals=cols, axis="rotary", joint=None, sha256="0" * 64, name="drift",
                    derived={})


@pytest.mark.parametrize("seed", [1, 2])
def test_a_residual_gone_from_the_last_quarter_of_the_log_is_not_kept(seed):
    """Held-out pieces interleaved with training pieces show a gain in three quarters of the
    pieces (five random folds of pieces keep NN_add on these logs); trained on the first half,
    NN_add is wrong on half of the second, and trained on the second it is too weak on the first."""
    log = drifting_log(40.0, 0.5, 0.75, np.random.default_rng(seed))
    adapted, summary = learning.adapt(LinearFriction(2.0, 1.5), log, epochs=30, seed=seed)
    assert summary["held_out"]["folds"] == 2
    assert summary["adapted"] is False and adapted.kind == "linear"


def test_a_residual_that_holds_along_the_log_is_kept():
    log = drifting_log(40.0, 0.0, 1.0, np.random.default_rng(2))
    sig = dict(log.signals)
    sig["tau_m"] = sig["tau_m"] + 0.8 * np.sign(sig["qd"])     # a steady shift of the friction level
    log = as_log(sig)
    adapted, summary = learning.adapt(LinearFriction(2.0, 1.5), log, epochs=30, seed=0)
    held = summary["held_out"]
    assert summary["adapted"] is True and adapted.kind == "residual"
    assert held["adapted_rmse"] < 0.5 * held["base_rmse"]


def test_a_robot_model_error_of_the_base_is_not_held_against_the_motion():
    """A base fixed by diagnose with a missing inertia (a robot-model error term, which need not
    oppose the motion) plus a steady shift of the friction level: NN_add learns the shift, and the
    inertia term passes by the dissipative combination, which holds friction alone against the motion."""
    from fricli.models import terms as T
    from fricli.models.augmented import AugmentedModel
    from fricli.models.base import predict_parts

    sig = dict(drifting_log(40.0, 0.0, 1.0, np.random.default_rng(3)).signals)
    inertia = 5.0                                   # kg m^2: up to 5 Nm along or against qd, friction 2-4 Nm
    sig["tau_m"] = sig["tau_m"] + inertia * sig["qdd"] + 0.8 * np.sign(sig["qd"])
    log = as_log(sig)
    base = AugmentedModel(LinearFriction(2.0, 1.5), [], [], error_terms=[T.term("qdd", T.sig_("qdd"))],
                          error_coef=[inertia], effects=["acceleration"], errors=["acceleration"])
    adapted, summary = learning.adapt(base, log, epochs=30, seed=0)
    assert summary["adapted"] is True and adapted.kind == "residual"
    assert summary["moving"]["mae"] < 0.1 * summary["base_moving"]["mae"]       # down to the 0.05 Nm noise
    friction, error, _ = predict_parts(adapted, sig)
    np.testing.assert_array_equal(error, inertia * sig["qdd"])
    moving = np.abs(sig["qd"]) >= summary["min_speed"]
    assert np.all(friction[moving] * sig["qd"][moving] > 0)      # friction alone opposes the motion


def speed_dependent_log(seed: int, scale: float) -> logs.Log:
    """The harmonic motion of ``drifting_log`` with its velocity times ``scale``, whose friction is
    the base's plus (qd - 0.3 sign(qd)) [Nm]: a base with too little viscous friction and too much
    Coulomb friction, whose residual grows with speed through zero at 0.3 rad/s."""
    rng = np.random.default_rng(seed)
    sig = dict(drifting_log(40.0, 0.0, 1.0, rng).signals)
    sig["qd"] = scale * sig["qd"]
    residual = sig["qd"] - 0.3 * np.sign(sig["qd"])
    sig["tau_m"] = sig["tau_g"] + LinearFriction(2.0, 1.5).predict(sig)[0] + residual + rng.normal(0.0, 0.05, sig["qd"].size)
    return as_log(sig)


def test_a_gain_at_high_speed_only_is_not_kept():
    """NN_add sees no velocity: on this log it learns the residual's mean level per direction,
    which helps the fast rows of both halves in time and harms the slow ones. On a slower run of
    the same joint that network is worse than the base, so adapt keeps the base."""
    log = speed_dependent_log(0, 1.0)
    kept, summary = learning.adapt(LinearFriction(2.0, 1.5), log, epochs=30, seed=0)
    held = summary["held_out"]
    assert max(held["half_ratios"]) < 0.9 and held["gain_mean"] > 2 * held["gain_se"]   # the rules in time pass
    slow, fast = held["speed_ratios"]
    assert fast < 0.8 and slow > 1.0
    assert summary["adapted"] is False and kept.kind == "linear"

    unchecked, _ = learning.adapt(LinearFriction(2.0, 1.5), log, epochs=30, seed=0, val_fraction=0.0)
    slower = speed_dependent_log(1, 0.5).signals
    target, moving = logs.friction_target(slower), np.abs(slower["qd"]) > 0.05
    rms = [float(np.sqrt(np.mean((target - m.predict(slower)[0])[moving] ** 2))) for m in (kept, unchecked)]
    assert rms[1] > 1.3 * rms[0]


def test_a_log_at_one_speed_has_no_speed_halves():
    blocks = training_data.time_block(N)
    held = learning.cross_validate(lambda train: np.full(N, 0.5), blocks, np.ones(N), np.zeros(N),
                                   speed=np.full(N, 0.4))
    assert held["speed_ratios"] == [] and held["helps"]
