"""Learning friction from logs: train a base network (``train_base``) and adapt any model to
new dynamics by learning its residual (``adapt``). Both return the model and a summary of
figures; the command line saves and prints them."""

from __future__ import annotations

from typing import Callable

import numpy as np

from fricli.core import logs, metrics
from fricli.fitting import training_data
# held-out scoring, importable from here as before
from fricli.fitting.heldout import (FOLDS, MIN_GAIN, PATIENCE_SHARE, SIGNIFICANCE, WORKERS,  # noqa: F401
                                    chosen_on_held_out,
                                    cross_validate, cross_validated_steps, rms_ratio, run_parallel,
                                    shared_progress, subset)
from fricli.fitting.steady import steady_state_mask
from fricli.core.envelope import share_outside
from fricli.core.errors import DataError, FitError
from fricli.models.base import FrictionModel, predict_parts
from fricli.models.dissipative import PRIOR_KEYS, DissipativeFriction
from fricli.models.neural import ARCHS as _PAPER_ARCHS
from fricli.models.residual import ResidualFriction
from fricli.numerics.threads import pinned

LONG_ADAPT_S = 300.0     # s: adapt says that a minute would do when it is given more than this

ARCHS = {"dissipative": DissipativeFriction, **_PAPER_ARCHS}
DEFAULT_ARCH = "dissipative"
DEFAULT_HIDDEN = {"dissipative": (30, 30), "mlp": (30, 30), "selmic": (30,), "nnacm": (50,)}
DEFAULT_MAX_SAMPLES = 2500
# the default network on a log without velocity levels: its step, prior share and pre-sliding
# state are chosen by two probes, each trained on half of the time blocks and scored on the
# other half, so that every block scores a choice (two blocks alone decided it badly: the
# friction level of a real joint moves from block to block)
PROBE_SHARE = 0.5
#: fewer velocity levels than this (both directions counted: three speeds each way) leave a network
#: no velocity dependence to learn (train-base warns)
MIN_VELOCITY_LEVELS = 6
# train-base: how the optimiser runs. "cosine" lowers Adam's learning rate from lr to 0 along a
# cosine over its steps, which reaches the paper's error in fewer steps; "paper" is the
# paper's constant learning rate for 50,000 steps. Both keep the weights of the best
# validation loss.
SCHEDULES = {"cosine": ("cosine", 30_000), "paper": ("constant", 50_000)}   # name -> (Trainer schedule, steps)
# The dissipative network reaches its held-out error in fewer cosine steps than the paper's
# (docs/neural-models.md, "Schedule"; python benchmarks/schedules.py).
COSINE_STEPS = {"dissipative": 7_000}


def default_steps(arch: str, schedule: str = "cosine") -> int:
    """Adam steps of ``train-base`` when --steps is not given."""
    if schedule == "cosine" and arch in COSINE_STEPS:
        return COSINE_STEPS[arch]
    return SCHEDULES[schedule][1]


VELOCITY_INPUTS = ("asinh", "linear")   # train-base: how the network sees qd (see models.neural)
BRISTLES = ("off", "on", "auto")   # train-base: the dissipative network's pre-sliding state (bristle_check)
MEMORY = ("auto", "on", "off")     # train-base: Maxwell-slip elements on a log without levels (memory.with_memory)
MIN_ROWS_PER_DIRECTION = 20   # moving rows a network needs in each direction at the least


def _errors(y: np.ndarray, pred: np.ndarray, rows: np.ndarray) -> dict:
    return metrics.errors(y[rows], pred[rows])


def check_motion(name: str, qd: np.ndarray, moving: np.ndarray, job: str) -> None:
    """DataError saying what is missing unless the moving rows (bool (n,)) of velocity qd (n,)
    hold at least MIN_ROWS_PER_DIRECTION samples in each direction."""
    for direction, count in (("positive", int((qd[moving] > 0).sum())), ("negative", int((qd[moving] < 0).sum()))):
        if count < MIN_ROWS_PER_DIRECTION:
            what = "no samples" if count == 0 else f"only {count} samples"
            raise DataError(f"{name}: {what} with {direction} velocity; {job} needs at least "
                            f"{MIN_ROWS_PER_DIRECTION} moving samples in each direction (a movement out and back)")


def train_base(log: logs.Log, *, arch: str = DEFAULT_ARCH, hidden: tuple[int, ...] | None = None,
               steps: int | None = None, schedule: str = "cosine", patience: int | None = None, lr: float = 0.01,
               batch_size: int = 0, seed: int = 0, val_fraction: float = 0.2,
               balance: bool = True, max_samples: int | None = DEFAULT_MAX_SAMPLES,
               velocity_input: str = "asinh", velocity_scale: float | None = None,
               ensemble: int = 1, bristles: str = "on", prior: bool = True, memory: str = "auto",
               on_eval: Callable | None = None) -> tuple[FrictionModel, dict]:
    """Train a network (``arch``) on the friction target of ``log``: ``train`` on the log's
    signals with the generator of ``seed``.

    On a log without velocity levels (summary "velocity_groups" "moving") ``memory`` (a key of
    ``MEMORY``) adds Maxwell-slip elements to the trained network: "auto" when the
    diagnosis's hysteresis test on held-out blocks chooses them, "on" always (both only where
    they stay physical), "off" never (``memory.with_memory``; summary "memory", not given for
    "off"); the model is then ``augmented``. A log with velocity levels trains as before."""
    if memory not in MEMORY:
        raise ValueError(f"unknown memory choice {memory!r}")
    model, summary = train(log.signals, logs.friction_target(log.signals), name=log.name, units=log.units,
                           arch=arch, hidden=hidden, steps=steps, schedule=schedule, patience=patience, lr=lr,
                           batch_size=batch_size, rng=np.random.default_rng(seed), val_fraction=val_fraction,
                           balance=balance, max_samples=max_samples, velocity_input=velocity_input,
                           velocity_scale=velocity_scale, ensemble=ensemble, bristles=bristles, prior=prior,
                           on_eval=on_eval)
    if summary["velocity_groups"] == "moving" and memory != "off":
        from fricli.fitting import memory as mem

        model, summary["memory"] = mem.with_memory(model, log, memory)
    return model, summary


def train(sig: dict[str, np.ndarray], target: np.ndarray, *, name: str, units: dict, rng: np.random.Generator,
          arch: str = DEFAULT_ARCH, hidden: tuple[int, ...] | None = None, steps: int | None = None,
          schedule: str = "cosine", patience: int | None = None, lr: float = 0.01, batch_size: int = 0,
          val_fraction: float = 0.2, balance: bool = True, max_samples: int | None = DEFAULT_MAX_SAMPLES,
          velocity_input: str = "asinh", velocity_scale: float | None = None, ensemble: int = 1,
          bristles: str = "on", prior: bool = True, on_eval: Callable | None = None) -> tuple[FrictionModel, dict]:
    """Train a network (``arch`` dissipative, mlp, selmic or nnacm) on signals ``sig`` (n,) each
    against the friction target ``target`` (n,) [Nm] (``name``: the log's name for messages;
    ``units``: the log's units; ``rng``: the generator of the row selection, weights and batches).

    A log of constant-velocity sweeps trains on its velocity levels (``training_data``), rows
    slower than 0.1 % of the top speed left out; a log without levels (continuous excitation)
    trains on its rows in motion (``metrics.in_motion``) and validates on whole blocks of time
    (summary "velocity_groups": "moving"). There the dissipative network is one network trained
    on every row in motion, at the step, prior share and pre-sliding choice that two probe
    networks, each trained on half of the time blocks (PROBE_SHARE), showed best on the other
    half (``chosen_on_held_out``, ``held_out_choices``; summary "held_out_choice"); with
    ``ensemble`` N > 1 it is the mean of one network per fold of ``training_data.time_folds`` (the
    first N folds), every one stopped at the step of the least validation loss pooled over the
    folds (``cross_validated_steps``; summary "cross_validation"). The other networks validate
    on one fold. At rest the friction
    is held by the bristles and depends on the motion before, not on (tau_g, qd). ``velocity_input``
    "asinh" feeds the network asinh(qd / v0) with v0 = ``velocity_scale`` or, for None, a low
    quantile of the training speeds; "linear" feeds qd itself (not for ``dissipative``, which
    always sees asinh(|qd| / v0)). Returns (model,
    summary); summary holds the row selection and the MAE/RMSE/max [Nm] on the training rows,
    the validation rows, the moving rows and the whole log. ``schedule`` is a key of SCHEDULES;
    ``steps`` None takes its number of steps; ``patience`` stops training after that many
    steps without improvement of the validation loss (see ``fricli.numerics.nn.Trainer``).
    ``bristles`` (dissipative only, a key of BRISTLES): "on" gives the model its pre-sliding state
    (``DissipativeFriction.fit_bristles``), "auto" only when it lowers the held-out error
    (``bristle_check``; summary "bristles"), "off" never. ``prior`` (dissipative, with held-out
    rows): blend the network with the LuGre model's static curve by the share that the held-out
    rows give it (``blend_prior``; summary "prior"), before the pre-sliding state is fitted.
    """
    if bristles not in BRISTLES:
        raise ValueError(f"unknown bristles choice {bristles!r}")
    if schedule not in SCHEDULES:
        raise ValueError(f"unknown schedule {schedule!r}")
    trainer_schedule = SCHEDULES[schedule][0]
    steps = default_steps(arch, schedule) if steps is None else steps
    if arch not in ARCHS:
        raise ValueError(f"unknown architecture {arch!r}")
    if velocity_input not in VELOCITY_INPUTS:
        raise ValueError(f"unknown velocity input {velocity_input!r}")
    if arch == "dissipative" and velocity_input != "asinh":
        raise ValueError("the dissipative network always sees asinh(|qd| / v0): --velocity-input linear "
                         "applies to the paper's networks (mlp, selmic, nnacm)")
    # velocity levels are looked for down to LOW of the top speed (a sweep's slowest levels lie
    # below the in-motion share); without levels the rows in motion are the training rows
    sweeping = metrics.in_motion(sig["qd"], training_data.LOW)
    moving = metrics.in_motion(sig["qd"])
    if not sweeping.any():
        raise DataError(f"{name}: the log holds no motion (qd is zero everywhere)")
    check_motion(name, sig["qd"], sweeping, "train-base")
    # velocity plateaus too many or too close together to tell apart by speed (a long stepped
    # log): without levels, train on the plateaus, not on the ramps between them
    # rows of slow motion (a reversal passes there): they decide the bristle stiffness when the rows
    # in motion, where the state has settled, do not (fit_bristles)
    slow = np.flatnonzero(metrics.slow_motion(sig["qd"]))
    steady = moving & steady_state_mask(sig["t"], sig["qd"])
    plateaus = bool(steady.sum() >= training_data.PLATEAU_SHARE * moving.sum())
    sel = training_data.select(sig["qd"], val_fraction=val_fraction, max_samples=max_samples, balance=balance,
                               rng=rng, keep=sweeping, moving=steady if plateaus else moving)
    if sel.mode == "moving":
        check_motion(name, sig["qd"], moving, "train-base")

    def new_model(n_steps: int) -> FrictionModel:
        return ARCHS[arch](hidden_sizes=tuple(hidden or DEFAULT_HIDDEN[arch]), steps=n_steps, lr=lr,
                           batch_size=batch_size, units=units, schedule=trainer_schedule, patience=patience,
                           velocity_scale=None if velocity_input == "linear" else (velocity_scale or "auto"))

    cv = prior_summary = choice = None
    if ensemble < 1:
        raise ValueError("ensemble must be at least 1")
    probing = bool(sel.mode == "moving" and sel.val.size and ensemble == 1 and arch == "dissipative")
    if probing:
        # continuous excitation, one network: two probes, each trained on one half of the time
        # blocks and scored on the other, choose what it needs; a half with (almost) no motion
        # trains or scores nothing
        rows = np.union1d(sel.train, sel.val)
        held = training_data.time_folds(PROBE_SHARE, rng)
        block = training_data.time_block(moving.size)[rows]
        splits = [(rows[~np.isin(block, h)], rows[np.isin(block, h)]) for h in held]
        kept = [k for k, (train, val) in enumerate(splits) if min(train.size, val.size) >= training_data.MIN_RUN]
        held, splits = [held[k] for k in kept], [splits[k] for k in kept]
        if not kept:   # the motion within one half of the blocks: one network on every row, unchecked
            probing = False
            sel = training_data.Selection(train=rows, val=rows[:0], blocks=sel.blocks, mode=sel.mode, groups=0)
    if sel.mode == "moving" and sel.val.size and ensemble > 1 and arch == "dissipative":
        # continuous excitation, an ensemble asked for: one network per fold of time blocks, all
        # stopped at the step of the least mean validation loss, and the model their mean
        rows = np.union1d(sel.train, sel.val)
        folds = training_data.time_folds(val_fraction, rng)
        if ensemble > len(folds):
            raise DataError(f"{name}: an ensemble of {ensemble} networks needs {ensemble} folds of time blocks; "
                            f"--val-fraction {val_fraction:g} gives {len(folds)}")
        model = new_model(steps)
        model.set_scales(subset(sig, rows), target[rows])
        cv = cross_validated_steps(new_model, steps, sig, target, rows, sel.blocks, folds[:ensemble], rng, on_eval,
                                   scales_from=model, snapshots=True)
        members, held = cv.pop("models"), cv.pop("held")
        for fold in members:
            fold.net_.theta[...] = fold.snapshots_[cv["record"]]
            fold.snapshots_ = None
        model.set_members([fold.net_ for fold in members], sig["qd"][rows])
        length = min(fold.history_train_.size for fold in members)
        model.history_train_ = np.mean([fold.history_train_[:length] for fold in members], axis=0)
        model.history_val_ = cv.pop("curve") / model.y_scale_ ** 2
        model.best_step_, model.steps_ = cv["step"], max(fold.steps_ for fold in members)
        model.eval_every_, model.n_train_, model.n_val_ = members[0].eval_every_, rows.size, 0
        sel = training_data.Selection(train=rows, val=rows[:0], blocks=sel.blocks, mode=sel.mode, groups=sel.groups)
        prior_summary, check = held_out_choices(model, members, held, rows, sig, target, moving, slow, units,
                                                prior, bristles)
    elif probing:
        # continuous excitation: one network on every row, with what it needs chosen on held-out blocks
        model, probes, choice = chosen_on_held_out(new_model, steps, sig, target, splits, rng, on_eval,
                                                   meanwhile=load_prior_fit if prior else None)
        sel = training_data.Selection(train=rows, val=rows[:0], blocks=sel.blocks, mode=sel.mode,
                                      groups=int(held[0].size))
        prior_summary, check = held_out_choices(model, probes, held, rows, sig, target, moving, slow, units,
                                                prior, bristles)
    else:
        model = new_model(steps)
        model.fit(subset(sig, sel.train), target[sel.train], subset(sig, sel.val), target[sel.val], rng=rng,
                  on_eval=on_eval)
        if prior and arch == "dissipative" and sel.val.size:
            prior_summary = blend_prior(model, [model], [sel.train], [sel.val], sig, target, sel.train, units)
        if bristles != "off" and arch == "dissipative":
            check = bristle_check([model], [(sel.train, sel.val, slow)], sig, target)
            if bristles == "on" or check["helps"]:
                model.fit_bristles(sig, target, sel.train, slow, MIN_GAIN)
            else:
                model.sigma0_ = None   # the check left its state on the model itself
    pred = model.predict(sig)[0]
    summary = {"arch": arch, **sel.summary(), "plateaus": plateaus and sel.mode == "moving",
               "best_step": int(model.best_step_), "steps": int(model.steps_),
               "schedule": schedule, "max_steps": int(steps),
               "velocity_input": velocity_input, "v0": model.v0_,
               "train": _errors(target, pred, sel.train), "moving": _errors(target, pred, np.flatnonzero(moving)),
               "log": metrics.errors(target, pred)}
    if cv is not None:
        summary["cross_validation"] = cv
    if choice is not None:
        summary["held_out_choice"] = choice
    if sel.val.size:
        summary["val"] = _errors(target, pred, sel.val)
    if getattr(model, "v_ps_", None) is not None:
        summary["presliding_speed"] = model.v_ps_
    if bristles != "off" and arch == "dissipative":
        summary["bristles"] = {**check, "kept": model.sigma0_ is not None, "sigma0": model.sigma0_}
    if prior_summary is not None:
        summary["prior"] = prior_summary
    return model, summary


def held_out_choices(model: DissipativeFriction, fitted: list[DissipativeFriction], held: list[np.ndarray],
                     rows: np.ndarray, sig: dict[str, np.ndarray], target: np.ndarray, moving: np.ndarray,
                     slow: np.ndarray, units: dict, prior: bool, bristles: str) -> tuple[dict | None, dict | None]:
    """The prior's share and the pre-sliding state of ``model`` (trained on ``rows``), chosen on the
    time blocks ``held[k]`` that network ``fitted[k]`` did not train on: each network gets its prior
    from the rows it trained on and is scored on the rows in motion of its blocks (``blend_prior``,
    with ``prior``); ``bristle_check`` scores the pre-sliding state the same way, and the model
    gets it where ``bristles`` is "on" or the check finds it helps ("off": not checked). ``slow``:
    the log's rows of slow motion. Returns the summaries ("prior", "bristles"), None where not made."""
    block = training_data.time_block(moving.size)
    splits = [(np.flatnonzero(moving & ~np.isin(block, h)), np.flatnonzero(moving & np.isin(block, h))) for h in held]
    prior_summary = check = None
    if prior:
        prior_summary = blend_prior(model, fitted, [np.setdiff1d(rows, val) for _, val in splits],
                                    [val for _, val in splits], sig, target, rows, units)
    if bristles != "off":
        check = bristle_check(fitted, [(*split, slow[~np.isin(block[slow], h)]) for split, h in zip(splits, held)],
                              sig, target)
        if bristles == "on" or check["helps"]:
            model.fit_bristles(sig, target, np.flatnonzero(moving), slow, MIN_GAIN)
    return prior_summary, check


def load_prior_fit() -> None:
    """Import what ``fit_prior`` needs (identify, scipy's optimisers: about 0.3 s the first time)."""
    import scipy.linalg  # noqa: F401
    import scipy.optimize  # noqa: F401

    import fricli.fitting.identify  # noqa: F401


@pinned
def fit_prior(sig: dict[str, np.ndarray], target: np.ndarray, rows: np.ndarray, units: dict) -> dict | None:
    """The static curve of the LuGre model (``identify``'s static stage: Stribeck, viscous and load
    terms, symmetric) fitted by least squares to ``target`` (n,) [Nm] over ``rows`` (indices);
    its parameters (``dissipative.PRIOR_KEYS``), or None when the fit fails."""
    from fricli.fitting.identify import LuGreIdentifier

    tau_g = sig.get("tau_g")
    try:
        params = LuGreIdentifier().fit_static(sig["qd"][rows], target[rows], None if tau_g is None else tau_g[rows],
                                              units.get("qd", "rad/s"))
    except FitError:
        return None
    return {k: float(params[k]) for k in PRIOR_KEYS}


def blend_weight(y: np.ndarray, network: np.ndarray, prior: np.ndarray) -> float:
    """lambda in [0, 1] of least squares of y - (prior + lambda (network - prior)) (each (n,) [Nm]);
    1 when the two predictions do not differ."""
    d = network - prior
    den = float(d @ d)
    return 1.0 if not den > 0 else float(np.clip(float((y - prior) @ d) / den, 0.0, 1.0))


def blend_prior(model: DissipativeFriction, fitted: list[DissipativeFriction], train_rows: list[np.ndarray],
                held_rows: list[np.ndarray], sig: dict[str, np.ndarray], target: np.ndarray, rows: np.ndarray,
                units: dict) -> dict:
    """Make ``model`` the blend of its network and the LuGre static curve (``fit_prior`` on ``rows``),
    the network's share chosen on held-out rows.

    Each of the ``fitted`` networks (static, as trained) gets the prior fitted on its training
    rows ``train_rows[k]``; over their held-out rows ``held_rows[k]`` (indices into ``sig`` and
    ``target`` (n,) [Nm]) the prediction prior + lambda (network - prior) is least squares for
    ``blend_weight``'s lambda, pooled over the networks, which then keep their prior and that
    lambda (for ``bristle_check``). Returns lambda ("blend") and the held-out RMS [Nm] of the
    network, the prior and the blend; {"blend": 1.0} (the network alone) when a prior cannot be fitted.
    """
    ys, nets, priors, kept = [], [], [], []
    failed = False
    for net, train, held in zip(fitted, train_rows, held_rows):
        if not train.size or not held.size:
            continue
        p = fit_prior(sig, target, train, units)
        if p is None:
            failed = True
            break
        net.set_prior(None)
        nets.append(net.predict(sig)[0][held])
        net.set_prior(p, 0.0)
        priors.append(net.predict(sig)[0][held])
        ys.append(target[held])
        kept.append((net, p))
    final = None if failed or not kept else fit_prior(sig, target, rows, units)
    if final is None:
        for net in fitted:
            net.set_prior(None)
        return {"blend": 1.0}
    y, a, b = (np.concatenate(x) for x in (ys, nets, priors))
    blend = blend_weight(y, a, b)
    for net, p in kept:
        net.set_prior(p, blend)
    model.set_prior(final, blend)
    rms = {name: float(np.sqrt(np.mean((y - pred) ** 2)))
           for name, pred in (("network_rmse", a), ("prior_rmse", b), ("blend_rmse", b + blend * (a - b)))}
    return {"blend": blend, **rms, "prior": dict(final)}


def train_group(datas: list, transmission, *, seed: int = 0, progress: Callable | None = None,
                **options) -> tuple[FrictionModel, dict]:
    """One network per motor of a coupled group (``fricli.models.coupled``): ``datas`` the logs of
    the group's joints (rows at the same times, in the order of ``transmission``'s joints).

    Motor i trains with ``train`` (``options``: its keyword arguments; the networks stay static
    maps, without the pre-sliding state: ``predict_group`` holds no state) on its velocity
    w_i = (R qd)_i [rad/s] (no load input: ``coupled.motor_signals``) against its share of the
    friction, y = R^-T tau_f (n, k) [Nm]; one generator from ``seed`` runs through the motors in
    order. ``progress(i)``: the trainer's progress callback for motor i (0-based), with ``close()``,
    or None. Returns the coupled model and a summary: each motor's train summary ("motors") and
    the figures per joint (MAE, RMSE, max [Nm]) over the log's rows ("joints") and over the rows
    where the joint is in motion ("moving")."""
    from fricli.models import coupled

    data = datas[0]
    qd = coupled.stack(datas, "qd")
    tau_f = np.column_stack([logs.friction_target(d.signals) for d in datas])
    w = transmission.motor_velocities(qd)
    y = transmission.motor_torques(tau_f)
    rng = np.random.default_rng(seed)
    options = {**options, "bristles": "off", "prior": False}
    group = ", ".join(map(str, transmission.joints))
    motors, summaries = [], []
    for i in range(len(transmission.joints)):
        sig = {"t": data.signals["t"], **coupled.motor_signals(w[:, i])}
        on_eval = progress(i) if progress else None
        try:
            model, summary = train(sig, y[:, i], name=f"{data.name}, motor {i + 1} of joints {group}",
                                   units=data.units, rng=rng, on_eval=on_eval, **options)
        finally:
            if on_eval is not None:
                on_eval.close()
        motors.append(model)
        summaries.append(summary)
    model = coupled.CoupledModel(transmission.joints, transmission.ratio, motors=motors)
    err = model.predict_group(qd) - tau_f
    moving = {str(j): coupled.figures(err[metrics.in_motion(qd[:, c]), c]) for c, j in enumerate(transmission.joints)}
    return model, {"motors": summaries, "rows": int(len(qd)), "moving": moving,
                   "joints": {str(j): coupled.figures(err[:, c]) for c, j in enumerate(transmission.joints)}}


def bristle_check(fitted: list[DissipativeFriction], splits: list[tuple[np.ndarray, np.ndarray, np.ndarray]],
                  sig: dict[str, np.ndarray], target: np.ndarray) -> dict:
    """Whether the pre-sliding state lowers the error on rows the networks did not train on.

    ``splits`` gives, for each of the ``fitted`` models, its training rows, its held-out rows and
    the rows of slow motion outside the held-out ones (indices into ``sig`` and ``target`` (n,)
    [Nm]). Each model gets the state with sigma0 fitted on its training rows (and those slow rows
    where the training rows do not determine it: ``fit_bristles``; left on it); both predictions
    run over the whole log. Returns the RMS
    [Nm] over all held-out rows without and with the state, and "helps": the state lowers it by
    MIN_GAIN at least (False when no rows are held out).
    """
    e_static, e_state = [], []
    for model, (train, held, slow) in zip(fitted, splits):
        if not train.size or not held.size:
            continue
        model.sigma0_ = None
        e_static.append(target[held] - model.predict(sig)[0][held])
        model.fit_bristles(sig, target, train, slow, MIN_GAIN)
        e_state.append(target[held] - model.predict(sig)[0][held])
    if not e_static:
        return {"helps": False}
    static, state = (float(np.sqrt(np.mean(np.concatenate(e) ** 2))) for e in (e_static, e_state))
    return {"static_rmse": static, "bristles_rmse": state, "helps": bool(state <= (1.0 - MIN_GAIN) * static)}


def first_seconds(log: logs.Log, seconds: float | None) -> dict[str, np.ndarray]:
    """The log's signals over its first ``seconds`` (all of it for None)."""
    sig = log.signals
    if seconds is None:
        return sig
    t = sig["t"]
    keep = int(np.searchsorted(t, t[0] + seconds, side="right"))
    if keep < 2:
        raise DataError(f"{log.name}: --max-seconds {seconds:g} leaves fewer than 2 rows")
    return {k: v[:keep] for k, v in sig.items()}


def adapt(base: FrictionModel, log: logs.Log, *, hidden: int | tuple[int, ...] = (30,), epochs: int = 200,
          batch_size: int = 64, lr: float = 0.01, seed: int = 0, val_fraction: float = 0.2, max_seconds: float | None = None,
          min_speed: float | None = None, on_eval: Callable | None = None,
          base_envelope=None) -> tuple[FrictionModel, dict]:
    """NN_add on the residual of ``base`` over ``log`` (paper, L_add); returns (model, summary).

    The model is the adapted ``ResidualFriction`` when NN_add helps on rows it was not trained
    on (``cross_validate`` over whole pieces of the log's stretches of motion, or for a log
    without velocity levels whole blocks of time), else ``base`` itself; summary["adapted"] says
    which and summary["held_out"] gives the figures. ``val_fraction`` 0 skips the check (the
    residual model is returned).

    Rows slower than ``min_speed`` (default: the rows not in motion, ``metrics.in_motion``) are left out: at rest
    the bristles hold a friction torque set by the motion before (the residual there says
    nothing about (tau_g, direction)), and sign(qd) flips with noise. When the log moves at
    discrete velocities (the paper's one velocity out and back), only the rows at those
    velocities are used, not the accelerations between them. When predicting, rows at rest get
    sign(qd) = 0, between the network's two directions. ``base_envelope`` (the base's training
    envelope, ``fricli.core.envelope.Envelope``): the summary gives the share of the log outside it.
    """
    sig = first_seconds(log, max_seconds)
    qd = sig["qd"]
    top = float(np.max(np.abs(qd)))
    if not top > 0:
        raise DataError(f"{log.name}: the log holds no motion (qd is zero everywhere)")
    if min_speed is None:
        min_speed = metrics.REST_SHARE * top
        moving = metrics.in_motion(qd)
    else:
        moving = np.abs(qd) >= min_speed
    if not (qd[moving] > 0).any() or not (qd[moving] < 0).any():
        direction = "positive" if (qd[moving] > 0).any() else "negative"
        raise DataError(f"{log.name}: the log moves only in the {direction} direction; "
                        "the residual network needs both (a movement out and back)")
    check_motion(log.name, qd, moving, "adapt")
    target = logs.friction_target(sig)
    rng = np.random.default_rng(seed)
    sel = training_data.select(qd, val_fraction=val_fraction, max_samples=None, rng=rng, keep=moving)
    hidden = (hidden,) if isinstance(hidden, int) else tuple(hidden)   # NN_add's layer widths
    model = ResidualFriction(base, hidden_sizes=hidden, epochs=epochs, batch_size=batch_size, lr=lr,
                             min_speed=float(min_speed), units=log.units)
    base_friction, base_error, _ = predict_parts(base, sig)   # robot-model errors are not held against the motion
    base_pred = base_friction + base_error
    model.fit(sig, target, sel.train, sel.val, rng=rng, on_eval=on_eval, base_pred=base_pred)
    pred = model.on_base(sig, base_friction) + base_error
    moving_rows = np.flatnonzero(moving)
    summary = {**sel.summary(), "rows_used": int(len(qd)), "seconds_used": float(sig["t"][-1] - sig["t"][0]),
               "min_speed": float(min_speed), "epochs": epochs, "batch_size": batch_size,
               "steps": int(model.add.steps_), "best_step": int(model.add.best_step_),
               "train": _errors(target, pred, sel.train),
               "base_train": _errors(target, base_pred, sel.train),
               "moving": _errors(target, pred, moving_rows), "base_moving": _errors(target, base_pred, moving_rows)}
    if sel.val.size:
        summary["val"] = _errors(target, pred, sel.val)
        summary["base_val"] = _errors(target, base_pred, sel.val)
    if val_fraction > 0:
        def fit_predict(train: np.ndarray) -> np.ndarray:
            fold = ResidualFriction(base, hidden_sizes=hidden, epochs=epochs, batch_size=batch_size, lr=lr,
                                    min_speed=float(min_speed), units=log.units)
            fold.fit(sig, target, train, train[:0], rng=rng, base_pred=base_pred)
            return fold.on_base(sig, base_friction) + base_error

        held = cross_validate(fit_predict, sel.blocks, target, base_pred, speed=np.abs(qd))
        summary["held_out"] = held
        summary["adapted"] = held["helps"]
    else:
        summary["adapted"] = True
    if base_envelope is not None:
        summary["outside_base_envelope"] = share_outside(base_envelope, sig)
    return (model if summary["adapted"] else base), summary


