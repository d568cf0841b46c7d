"""The contract every model kind keeps (every kind registered in ``fricli.models.KINDS``, each
built by a tiny fit): the file round trip is exact, batches equal the whole log, the precision
settings behave, and the joint rule holds. A new kind without a builder here fails
``test_every_registered_kind_has_a_builder``."""

import numpy as np
import pytest
from test_joints import write_log

from fricli import joints, learning, logs, models, predicting


def _lugre(log):
    from fricli.identify import LuGreIdentifier

    return LuGreIdentifier().fit(log.signals, units=log.units, axis=log.axis).model_


def _linear(log):
    from fricli.models import linear

    return linear.fit(log.signals, axis=log.axis)[0]


def _network(arch):
    hidden = {"selmic": (12,)}.get(arch, (4,))
    return lambda log: learning.train_base(log, arch=arch, hidden=hidden, steps=5, max_samples=200, seed=1)[0]


def _residual(log):
    model, _ = learning.adapt(_linear(log), log, hidden=(3,), epochs=1, val_fraction=0, seed=1)
    assert model.kind == "residual"
    return model


def _augmented(log):
    from fricli.diagnosis import driver
    from fricli.diagnosis.fix import augment

    base = _linear(log)
    model = augment(base, driver.diagnose(base, log, only=["direction", "load"]), log, carry=False)
    assert model.kind == "augmented"
    return model


BUILDERS = {"lugre": _lugre, "linear": _linear, "residual": _residual, "augmented": _augmented,
            **{arch: _network(arch) for arch in learning.ARCHS}}


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
    """kind -> (model file of joint 2, its log)."""
    folder = tmp_path_factory.mktemp("models")
    log = logs.load_log(logs_by_joint[2])
    cache = {}

    def get(kind):
        if kind not in cache:
            path = str(folder / f"{kind}.npz")
            models.save_for_log(path, BUILDERS[kind](log), log, rows_used=len(log))
            cache[kind] = path
        return cache[kind], log

    return get


def test_every_registered_kind_has_a_builder():
    assert set(registered_kinds()) <= set(BUILDERS), "add a tiny fit of the new kind to BUILDERS"


@pytest.mark.parametrize("kind", registered_kinds())
def test_the_file_round_trip_is_exact(built, kind, tmp_path):
    path, log = built(kind)
    model, meta = models.load(path)
    assert model.kind == kind == meta["kind"]
    again = str(tmp_path / "again.npz")
    models.save(again, model, joint=meta["joint"], axis=meta["axis"], units=meta["units"],
                provenance=meta["provenance"], fit=meta["fit"], envelope=meta.get("envelope"))
    assert open(again, "rb").read() == open(path, "rb").read()
    reloaded = models.load(again)[0]
    for precision in models.PRECISIONS:
        a = models.set_precision(model, precision).predict(log.signals)[0]
        b = models.set_precision(reloaded, precision).predict(log.signals)[0]
        assert np.array_equal(a, b)


@pytest.mark.parametrize("kind", registered_kinds())
def test_batches_equal_the_whole_log(built, kind):
    path, log = built(kind)
    model = models.set_precision(models.load(path)[0], "double")
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
    path, log = built(kind)
    model = models.load(path)[0]
    double = models.set_precision(model, "double").predict(log.signals)[0]
    again = models.set_precision(models.load(path)[0], "double").predict(log.signals)[0]
    assert double.dtype == np.float64 and np.array_equal(double, again)
    single = models.set_precision(model, "single").predict(log.signals)[0]
    scale = float(np.max(np.abs(double)))
    np.testing.assert_allclose(single, double, rtol=0, atol=1e-4 * scale)
    with pytest.raises(ValueError):
        models.set_precision(model, "half")


@pytest.mark.parametrize("kind", registered_kinds())
def test_a_model_of_one_joint_refuses_rows_of_another(built, logs_by_joint, kind, tmp_path):
    path, _ = built(kind)
    model, meta = models.load(path)
    assert str(meta["joint"]) == "2"
    with pytest.raises(joints.JointMismatch, match="fitted on joint 2, not on joint 4"):
        predicting.run(model, meta, logs_by_joint[4], str(tmp_path / "out.parquet"))
    assert not (tmp_path / "out.parquet").exists()
    result = predicting.run(model, meta, logs_by_joint[2], str(tmp_path / "own.parquet"))
    assert result.rows == 2000 and result.joint is not None
