"""The Generalized Maxwell-slip kind: its fit on a joint with known Maxwell-slip elements."""

import numpy as np

from fricli.fitting import hysteresis
from fricli.models.gms import GMSModel
from fricli.sim import simulate
from fricli.core import logs


def _motion(seed):
    return logs.from_table(simulate("daily", 2, seed=seed), name="sim").signals


def test_fit_recovers_a_known_hysteresis_loop_to_the_noise_floor():
    """Friction made by a GMS model with elements off the fit's grid, plus noise: the fitted
    model, scored on another trajectory, is within 1.1x the noise floor."""
    true = GMSModel([0.002, 0.006, 0.02], [1.5, 0.9, 0.6], fc=4.0, fst=1.0, vs=0.03, fv=8.0)
    rng = np.random.default_rng(3)
    sd = 0.1
    logs_ = []
    for seed in (1, 2):
        sig = {k: _motion(seed)[k] for k in ("t", "q", "qd")}
        sig["tau_f_true"] = true.predict(sig)[0]
        sig["tau_m"] = sig["tau_f_true"] + rng.normal(0.0, sd, len(sig["t"]))
        sig["tau_g"] = sig["tau_dyn"] = np.zeros(len(sig["t"]))
        logs_.append(sig)
    model, record = hysteresis.fit({k: v for k, v in logs_[0].items() if k != "tau_f_true"})
    assert record["elements"] > 0
    test = logs_[1]
    pred = model.predict(test)[0]
    floor = np.sqrt(np.mean((test["tau_m"] - test["tau_f_true"]) ** 2))
    rms = np.sqrt(np.mean((pred - test["tau_m"]) ** 2))
    assert rms <= 1.1 * floor, (rms, floor)
    # without the elements (no memory) the same fit is far off: the test can fail
    plain, _ = hysteresis.fit({k: v for k, v in logs_[0].items() if k != "tau_f_true"}, elements=(0,))
    assert np.sqrt(np.mean((plain.predict(test)[0] - test["tau_m"]) ** 2)) > 2 * floor


def test_elements_never_generate_energy():
    """Over a random path the work the friction takes is at least the energy the elements hold."""
    model = GMSModel([0.001, 0.01], [2.0, 1.0], fc=0.5)
    rng = np.random.default_rng(0)
    q = np.cumsum(rng.normal(0, 0.003, 5000))
    qd = np.gradient(q)
    tau, state = model.predict({"q": q, "qd": qd})
    work = np.cumsum(tau[1:] * np.diff(q))
    assert work[-1] >= model.energy(state) - 1e-12
