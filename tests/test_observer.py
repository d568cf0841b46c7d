"""The momentum observer, the online adaptation and contact detection (fricli.applying.observer) on a
simulated joint whose external torque, friction and inertia are known."""

import json

import numpy as np
import pytest

from fricli.applying import observer
from fricli.core.errors import DataError, LogError

DT = 0.001


def joint(seconds=40.0, scale=1.0, offset=0.0, push=None, seed=0):
    """One rigid joint of inertia J under gravity-free motion: J qdd = tau_m - tau_f + tau_ext.
    The friction model f0 = 2 qd + 1.5 tanh(qd / 0.01); the true friction scale * f0 + offset;
    ``push``: (start, end, torque) of an external torque [s, s, Nm]."""
    rng = np.random.default_rng(seed)
    t = np.arange(0.0, seconds, DT)
    qd = 0.8 * np.sin(2 * np.pi * 0.3 * t) + 0.3 * np.sin(2 * np.pi * 0.71 * t + 1.0)
    qdd = np.gradient(qd, t)
    inertia = 0.7
    f0 = 2.0 * qd + 1.5 * np.tanh(qd / 0.01)
    ext = np.zeros_like(t)
    if push is not None:
        ext[(t >= push[0]) & (t < push[1])] = push[2]
    tau_m = inertia * qdd + scale * f0 + offset - ext + 0.01 * rng.standard_normal(len(t))
    col = lambda x: x[:, None]   # noqa: E731
    return t, col(f0), col(tau_m), col(inertia * qd), col(np.zeros_like(t)), col(qd), ext, col(inertia * qdd)


def thresholds(value=1.0, band=1.5):
    return observer.Thresholds(["2"], np.array([value]), np.array([band]), np.array([2.0]))


def test_the_residual_follows_a_step_of_external_torque_with_the_observers_time_constant():
    t, f0, tau_m, p, w, qd, ext, _ = joint(seconds=2.0, push=(1.0, 2.0, 3.0))
    out = observer.replay(t, f0, tau_m, p, w, qd, gain=50.0)
    r = out.tau_ext[:, 0]
    i = np.searchsorted(t, 1.0)
    assert np.max(np.abs(r[:i])) < 0.1                   # no push: only the noise, low-passed
    after = r[i + 20]                                     # one time constant (20 ms) later
    assert after == pytest.approx(3.0 * (1 - np.exp(-1.0)), abs=0.15)
    assert np.mean(r[i + 200:]) == pytest.approx(3.0, abs=0.02)
    # the per-joint form on tau_g + tau_dyn with the exact acceleration: the same residual
    _, _, _, _, _, _, _, tau_dyn = joint(seconds=2.0, push=(1.0, 2.0, 3.0))
    per = observer.replay(t, f0, tau_m, np.zeros_like(p), tau_dyn, qd, gain=50.0)
    assert np.max(np.abs(per.tau_ext[i + 100:, 0] - r[i + 100:])) < 0.05


def test_replay_is_causal():
    t, f0, tau_m, p, w, qd, _, _ = joint(seconds=3.0)
    a = observer.replay(t, f0, tau_m, p, w, qd, thresholds=thresholds(), adaptation=observer.Adaptation())
    tau_m2 = tau_m.copy()
    tau_m2[2000:] += 5.0
    b = observer.replay(t, f0, tau_m2, p, w, qd, thresholds=thresholds(), adaptation=observer.Adaptation())
    for x, y in ((a.tau_f, b.tau_f), (a.tau_ext, b.tau_ext), (a.contact, b.contact)):
        assert np.array_equal(x[:2000], y[:2000])
    assert not np.array_equal(a.tau_ext[2000:], b.tau_ext[2000:])


@pytest.mark.slow
def test_adaptation_finds_the_days_friction_level_within_its_bounds():
    t, f0, tau_m, p, w, qd, _, _ = joint(seconds=60.0, scale=1.3, offset=0.2)
    thr = thresholds(value=5.0)
    static = observer.replay(t, f0, tau_m, p, w, qd, thresholds=thr)
    adapted = observer.replay(t, f0, tau_m, p, w, qd, thresholds=thr, adaptation=observer.Adaptation(offset=True))
    assert adapted.scale[-1, 0] == pytest.approx(1.3, abs=0.03)
    assert adapted.offset[-1, 0] == pytest.approx(0.2, abs=0.05)
    late = t > 30
    true = 1.3 * f0[:, 0] + 0.2
    assert np.sqrt(np.mean((adapted.tau_f[late, 0] - true[late]) ** 2)) < 0.2 * np.sqrt(
        np.mean((static.tau_f[late, 0] - true[late]) ** 2))
    # the scale alone (the default): the offset stays 0, the scale takes what it can of it
    alone = observer.replay(t, f0, tau_m, p, w, qd, thresholds=thr, adaptation=observer.Adaptation())
    assert np.all(alone.offset == 0.0) and alone.scale[-1, 0] == pytest.approx(1.3, abs=0.15)
    # bounds: a level far beyond them is clipped
    t, f0, tau_m, p, w, qd, _, _ = joint(seconds=20.0, scale=4.0)
    out = observer.replay(t, f0, tau_m, p, w, qd, thresholds=thresholds(50.0), adaptation=observer.Adaptation())
    assert out.scale.max() <= observer.Adaptation().scale_bounds[1]


def test_a_contact_held_for_ten_seconds_is_not_learned_as_friction():
    t, f0, tau_m, p, w, qd, ext, _ = joint(seconds=50.0, scale=1.2, offset=0.1, push=(35.0, 45.0, 4.0))
    out = observer.replay(t, f0, tau_m, p, w, qd, thresholds=thresholds(1.0),
                          adaptation=observer.Adaptation(offset=True))
    before, after = np.searchsorted(t, 35.0) - 1, np.searchsorted(t, 45.0)
    assert abs(out.scale[after, 0] / out.scale[before, 0] - 1) < 0.05
    assert abs(out.offset[after, 0] - out.offset[before, 0]) < 0.05 * 2.0
    pushed = (t >= 35.02) & (t < 45.0)
    # flagged wherever the joint moves; at rest a push within the static friction band does not show
    assert out.contact[pushed & (np.abs(qd[:, 0]) > 0.02), 0].all() and out.contact[pushed, 0].mean() > 0.98
    assert not out.contact[(t > 1.0) & (t < 35.0), 0].any()


def test_contact_hysteresis_and_events():
    t = np.arange(0.0, 1.0, 0.01)
    r = np.where((t > 0.3) & (t < 0.6), 2.0, 0.0) + np.where((t >= 0.6) & (t < 0.7), 0.7, 0.0)
    contact = np.zeros((len(t), 1), dtype=bool)
    obs = observer.Observer(1, gain=1e9, thresholds=thresholds(1.0))
    for i in range(len(t)):   # a huge gain: r follows tau_f - tau_m at once
        _, _, contact[i] = obs.step(t[i], np.array([r[i]]), np.zeros(1), np.zeros(1), np.zeros(1), np.ones(1))
    on = np.flatnonzero(contact[:, 0])
    assert t[on[0]] == pytest.approx(0.31) and t[on[-1]] == pytest.approx(0.69)   # held at 0.7 > 0.5 x 1.0
    (ev,) = observer.events(t, contact, r[:, None], ["2"])
    assert ev.joint == "2" and ev.start == pytest.approx(0.31) and ev.end == pytest.approx(0.70)
    assert ev.peak == pytest.approx(2.0)


def test_thresholds_calibration_and_file(tmp_path):
    t, f0, tau_m, p, w, qd, _, _ = joint(seconds=5.0)
    qd[:1000] = 0.0
    band = observer.static_band([f0], [qd], observer.DEFAULT_MOVING_SPEED, ["2"])
    slow = (np.abs(qd[:, 0]) > 0.02) & (np.abs(qd[:, 0]) <= 0.1)
    assert band[0] == np.max(np.abs(f0[slow, 0])) and 1.5 < band[0] < 1.8   # Coulomb 1.5 plus a little viscous
    res = observer.replay(t, f0, tau_m, p, w, qd)
    thr = observer.calibrate([res.tau_ext], [f0], [qd], ["2"], 50.0, "urdf", band, quantile=0.99, margin=2.0)
    assert thr.threshold[0] == pytest.approx(2.0 * np.quantile(np.abs(res.tau_ext[:, 0]), 0.99))
    path = tmp_path / "t.json"
    path.write_text(json.dumps(thr.as_json()))
    back = observer.Thresholds.read(str(path))
    assert back.threshold[0] == thr.threshold[0] and back.form == "urdf" and back.joints == ["2"]
    assert back.static_friction[0] == band[0]
    path.write_text("{}")
    with pytest.raises(LogError):
        observer.Thresholds.read(str(path))
    with pytest.raises(DataError):
        observer.Observer(1, adaptation=observer.Adaptation())   # no thresholds: no adaptation


def test_at_rest_the_estimate_is_the_torque_outside_the_static_friction_band():
    t = np.arange(0.0, 2.0, 0.001)
    tau_m = np.where(t < 1.0, 1.0, 3.0)[:, None]     # held: 1 Nm of friction, then 3 Nm (a push of 2 Nm beyond it)
    zero = np.zeros((len(t), 1))
    thr = observer.Thresholds(["2"], np.array([0.5]), np.array([1.5]), np.array([1.0]))
    out = observer.replay(t, zero, tau_m, zero, zero, zero, thresholds=thr)
    assert np.max(np.abs(out.tau_ext[(t > 0.1) & (t < 1.0), 0])) == 0.0
    assert out.tau_ext[-1, 0] == pytest.approx(-1.5, abs=1e-6)    # clip(3, -1.5, 1.5) - 3
    assert out.contact[-1, 0] and not out.contact[t < 1.0, 0].any()


def test_at_rest_the_static_band_is_at_the_adapted_level():
    """A joint whose friction is 1.3 times its model's holds up to 1.3 F_s at rest: once --adapt has
    learned the scale in motion, a held friction of 1.25 F_s is no external torque; the static
    observer reports what lies beyond F_s."""
    t, f0, tau_m, p, w, qd, _, _ = joint(seconds=30.0, scale=1.3)
    stop = np.flatnonzero((qd[:-1, 0] > 0) & (qd[1:, 0] <= 0))[-1] + 1   # rest from the last reversal on
    band, held = 1.5, 1.25 * 1.5
    rest = np.arange(len(t)) >= stop
    for x in (f0, p, qd):
        x[rest] = 0.0
    tau_m[rest] = held
    thr = thresholds(value=5.0, band=band)
    static = observer.replay(t, f0, tau_m, p, w, qd, thresholds=thr)
    adapted = observer.replay(t, f0, tau_m, p, w, qd, thresholds=thr, adaptation=observer.Adaptation())
    late = rest & (t > t[stop] + 0.5)
    assert adapted.scale[stop, 0] == pytest.approx(1.3, abs=0.05)
    assert static.tau_ext[late, 0] == pytest.approx(band - held, abs=1e-6)    # clip(y, -F_s, F_s) - y
    assert np.max(np.abs(adapted.tau_ext[late, 0])) == 0.0                     # within a F_s


def test_persistence_leaves_out_a_single_wrong_sample_and_flags_a_lasting_contact():
    t = np.arange(0.0, 1.0, 0.01)
    r = np.zeros_like(t)
    r[20] = 5.0                                    # one wrong sample, far beyond the threshold
    r[(t > 0.5) & (t < 0.8)] = 2.0                 # a contact that lasts
    flags = {}
    for persistence in (1, 3):
        thr = observer.Thresholds(["2"], np.array([1.0]), np.array([1.5]), np.array([1.0]), persistence=persistence)
        out = observer.replay(t, r[:, None], np.zeros((len(t), 1)), np.zeros((len(t), 1)), np.zeros((len(t), 1)),
                              np.ones((len(t), 1)), gain=1e9, thresholds=thr)
        flags[persistence] = np.flatnonzero(out.contact[:, 0])
    assert 20 in flags[1] and 20 not in flags[3]
    first = int(np.flatnonzero(r == 2.0)[0])
    assert flags[1][flags[1] > 20][0] == first and flags[3][0] == first + 2     # the third sample beyond it
    # a residual that changes sign from one sample to the next does not add up to a flag
    alternating = np.where(np.arange(len(t)) % 2 == 0, 2.0, -2.0)
    thr = observer.Thresholds(["2"], np.array([1.0]), np.array([1.5]), np.array([1.0]), persistence=3)
    out = observer.replay(t, alternating[:, None], np.zeros((len(t), 1)), np.zeros((len(t), 1)),
                          np.zeros((len(t), 1)), np.ones((len(t), 1)), gain=1e9, thresholds=thr)
    assert not out.contact.any()


def test_the_threshold_in_motion_grows_with_the_predicted_friction():
    t, f0, tau_m, p, w, qd, _, _ = joint(seconds=5.0)
    thr = observer.Thresholds(["2"], np.array([1.0]), np.array([1.5]), np.array([2.0]), share=np.array([0.25]))
    out = observer.replay(t, f0, tau_m, p, w, qd, thresholds=thr)
    level = np.zeros(len(t))                       # the observer's low-pass of the friction model (gain 50 1/s)
    level[0] = f0[0, 0]
    for i in range(1, len(t)):
        kd = observer.DEFAULT_GAIN * (t[i] - t[i - 1])
        level[i] = (level[i - 1] + kd * f0[i, 0]) / (1 + kd)
    moves = np.abs(qd[:, 0]) > observer.DEFAULT_MOVING_SPEED
    assert np.allclose(out.threshold[moves, 0], 1.0 + 0.25 * np.abs(level[moves]))
    assert np.all(out.threshold[~moves, 0] == 1.0)


def test_level_share_and_a_thresholds_file_of_before(tmp_path):
    qd = np.ones((5, 2))
    qd[0] = 0.0
    a = np.array([[1.0, 1.0], [1.1, 0.9], [1.2, 0.95], [1.05, 1.0], [1.0, 0.8]])
    a[0] = [5.0, 5.0]                              # at rest: left out
    thr = observer.Thresholds(["1", "2"], np.ones(2), np.ones(2), np.ones(2), quantile=1.0, margin=1.5)
    out = observer.level_share([a], [qd], thr)
    assert out.shares == pytest.approx([1.5 * 0.2, 1.5 * 0.2])
    data = out.as_json()
    assert data["joints"]["1"]["share"] == pytest.approx(0.3) and data["persistence"] == 1
    del data["persistence"]
    for j in data["joints"].values():
        del j["share"]
    path = tmp_path / "t.json"
    path.write_text(json.dumps(data))
    old = observer.Thresholds.read(str(path))      # written before share and persistence: as before
    assert old.persistence == 1 and np.all(old.shares == 0.0)
    for key, value in (("persistence", 0), ("persistence", observer.MAX_PERSISTENCE + 1), ("form", "banana"),
                       ("joints", [1]), ("joints", {})):
        path.write_text(json.dumps({**data, key: value}))
        with pytest.raises(LogError, match="not a thresholds file"):
            observer.Thresholds.read(str(path))
    path.write_text(json.dumps({**data, "persistence": observer.MAX_PERSISTENCE, "form": "urdf"}))
    assert observer.Thresholds.read(str(path)).persistence == observer.MAX_PERSISTENCE
