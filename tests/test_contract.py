"""The contract every model kind keeps (every kind registered in ``fricli.models.KINDS``, each
built by a tiny fit): the file round trip is exact, batches equal the whole log, the precision
settings behave, and the joint rule holds. A new kind without a builder here fails
``test_every_registered_kind_has_a_builder``. A coupled group's model is applied to one joint's
rows through its member view (``CoupledModel.member``), as the commands apply it."""

import numpy as np
import pytest
from test_joints import write_log

from fricli import models
from fricli.applying import predicting
from fricli.core import joints, logs, modelfile, modelset
from fricli.fitting import learning


def _lugre(log):
    from fricli.fitting.identify import LuGreIdentifier

    return LuGreIdentifier().fit(log.signals, units=log.units, axis=log.axis).model_


def _linear(log):
    from fricli.models import linear

    return linear.fit(log.signals, axis=log.axis)[0]


def _gms(log):
    from fricli.fitting import hysteresis

    return hysteresis.fit(log.signals, axis=log.axis, elements=(3,), coulomb_k=(2,), error_k=(1,))[0]


def _network(arch):
    hidden = {"selmic": (12,)}.get(arch, (4,))
    return lambda log: learning.train_base(log, arch=arch, hidden=hidden, steps=5, max_samples=200, seed=1)[0]


def _residual(log):
    model, _ = learning.adapt(_linear(log), log, hidden=(3,), epochs=1, val_fraction=0, seed=1)
    assert model.kind == "residual"
    return model


def _augmented(log):
    from fricli.fitting.diagnosis import driver
    from fricli.fitting.diagnosis.fix import augment

    base = _linear(log)
    model = augment(base, driver.diagnose(base, log, only=["direction", "load"]), log, carry=False)
    assert model.kind == "augmented"
    return model


def _coupled(path: str):
    """The coupled wrist of the simulated arm (fricli.sim.coupled): (the log of the group's first
    joint, with the partner's velocity; the view that predicts that joint; the arm's log file)."""
    from fricli.models import coupled
    from fricli.core import transmission
    from fricli.sim.coupled import simulate_coupled

    table = simulate_coupled(duration=3.0, rate_hz=400.0, rng=np.random.default_rng(3)).table
    log_file = path.replace(".npz", ".parquet")
    logs.write_table(table, log_file)
    tr = transmission.of_schema(table.schema.metadata)
    group = tr.sub(tr.coupled_groups()[0])
    _, datas = coupled.group_rows(table, list(group.joints), "wrist", zero=("tau_dyn", "tau_g"))
    model, fit = coupled.fit_group(datas, group)
    coupled.save_group(path, model, datas[0], fit=fit)
    log = datas[0]
    log.signals.update(coupled.partner_signals(table, group.joints[0], "wrist", zero=("tau_dyn", "tau_g")))
    return log, lambda m: m.member(group.joints[0]), log_file


BUILDERS = {"lugre": _lugre, "linear": _linear, "gms": _gms, "residual": _residual, "augmented": _augmented,
            **{arch: _network(arch) for arch in learning.ARCHS}}
def _coupled_member(path: str):
    """The member of the coupled wrist's first joint, saved as a model of that joint."""
    log, view, log_file = _coupled(path)
    models.save_for_log(path, view(models.load(path)[0]), log, rows_used=len(log))
    return log, lambda m: m, log_file


GROUP_BUILDERS = {"coupled": _coupled,   # kinds of several joints: builder(path) -> (log, view, log file)
                  "coupled-member": _coupled_member}   # one joint of a group: reads the partners' rows of the log


def registered_kinds() -> list[str]:
    """The kinds fricli registers (not those a test registers for itself)."""
    models._load_kinds()
    return sorted(k for k, cls in models.KINDS.items() if cls.__module__.startswith("fricli."))


@pytest.fixture(scope="module")
def logs_by_joint(tmp_path_factory):
    folder = tmp_path_factory.mktemp("contract")
    return {j: write_log(folder / f"joint{j}.parquet", [j]) for j in (2, 4)}


@pytest.fixture(scope="module")
def built(logs_by_joint, tmp_path_factory):
    """kind -> (model file, the log of a joint it applies to, the view of a loaded model that
    predicts that joint's rows, the log's file)."""
    folder = tmp_path_factory.mktemp("models")
    log = logs.load_log(logs_by_joint[2])
    cache = {}

    def get(kind):
        if kind not in cache:
            path = str(folder / f"{kind}.npz")
            if kind in GROUP_BUILDERS:
                cache[kind] = (path, *GROUP_BUILDERS[kind](path))
            else:
                models.save_for_log(path, BUILDERS[kind](log), log, rows_used=len(log))
                cache[kind] = (path, log, lambda m: m, logs_by_joint[2])
        return cache[kind]

    return get


def test_every_registered_kind_has_a_builder():
    assert set(registered_kinds()) <= set(BUILDERS) | set(GROUP_BUILDERS), \
        "add a tiny fit of the new kind to BUILDERS"


@pytest.mark.parametrize("kind", registered_kinds())
def test_the_file_round_trip_is_exact(built, kind, tmp_path):
    path, log, view, _ = built(kind)
    model, meta = models.load(path)
    assert model.kind == kind == meta["kind"]
    spec, arrays = models.to_parts(model)      # what the loaded model would write
    again = str(tmp_path / "again.npz")
    modelfile.write(again, dict(meta, model=spec), arrays)
    assert open(again, "rb").read() == open(path, "rb").read()
    reloaded = models.load(again)[0]
    for precision in models.PRECISIONS:
        a = view(models.set_precision(model, precision)).predict(log.signals)[0]
        b = view(models.set_precision(reloaded, precision)).predict(log.signals)[0]
        assert np.array_equal(a, b)


@pytest.mark.parametrize("kind", registered_kinds())
def test_batches_equal_the_whole_log(built, kind):
    path, log, view, _ = built(kind)
    model = view(models.set_precision(models.load(path)[0], "double"))
    whole = model.predict(log.signals)[0]
    parts, state = [], None
    for start in range(0, len(log), 333):
        part = {k: v[start:start + 333] for k, v in log.signals.items()}
        pred, state = model.predict(part, state)
        parts.append(pred)
    scale = float(np.max(np.abs(whole)))
    np.testing.assert_allclose(np.concatenate(parts), whole, rtol=0, atol=1e-9 * scale)


@pytest.mark.parametrize("kind", registered_kinds())
def test_precision_single_is_close_and_double_is_deterministic(built, kind):
    path, log, view, _ = built(kind)
    model = models.load(path)[0]
    double = view(models.set_precision(model, "double")).predict(log.signals)[0]
    again = view(models.set_precision(models.load(path)[0], "double")).predict(log.signals)[0]
    assert double.dtype == np.float64 and np.array_equal(double, again)
    single = view(models.set_precision(model, "single")).predict(log.signals)[0]
    scale = float(np.max(np.abs(double)))
    np.testing.assert_allclose(single, double, rtol=0, atol=1e-4 * scale)
    with pytest.raises(ValueError):
        models.set_precision(model, "half")


@pytest.mark.parametrize("kind", registered_kinds())
def test_a_model_of_one_joint_refuses_rows_of_another(built, logs_by_joint, kind, tmp_path):
    path, log, _, log_file = built(kind)
    meta = models.load(path)[1]
    assert 4 not in [int(j) for j in joints.covers(meta)]
    with pytest.raises(joints.JointMismatch, match="fitted on joints? .*not on joint 4"):
        predicting.run_models(modelset.source(path), logs_by_joint[4], str(tmp_path / "out.parquet"))
    assert not (tmp_path / "out.parquet").exists()
    result = predicting.run_models(modelset.source(path), log_file, str(tmp_path / "own.parquet"),
                                   reading=predicting.Reading(joint=log.joint, zero=("tau_dyn", "tau_g")))
    assert result.rows == len(log)
