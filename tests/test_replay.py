"""fricli thresholds, fricli replay and the arm header of fricli export --observer: the replay is
causal, its C code gives the same numbers, and the URDF form's rigid-body terms are the log's."""

import functools
import shutil
import subprocess
import sys

import numpy as np
import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq
import pytest

from conftest import ROOT, invoke, shared_data
from fricli import models
from fricli.applying import observer
from fricli.core import logs
from fricli.models.lugre import LuGreModel
from fricli.robot import replay

sys.path.insert(0, str(ROOT / "tests"))
import observer_check  # noqa: E402

SAMPLE = "sample_data/joint2_base.parquet"
HELD_OUT = "sample_data/joint2_extended_asym.parquet"


@pytest.fixture(scope="module")
def folder(tmp_path_factory):
    """A model folder with the LuGre model of joint 2 (fitted values of the sample's simulator)."""
    out = tmp_path_factory.mktemp("models")
    log = logs.load_log(f"{ROOT}/{SAMPLE}")
    model = LuGreModel(7.0, 9.0, 0.04, 1.2, 12.0, sigma0=1.7e4, sigma1=0.5)
    models.save_for_log(str(out / "joint_2.npz"), model, log, rows_used=len(log), seed=1)
    return out


invoke = functools.partial(invoke, catch_exceptions=False)   # an exception fails the test with its traceback


def test_replay_command_with_thresholds_and_adaptation(folder, tmp_path):
    thr = tmp_path / "t.json"
    done = invoke("thresholds", folder, f"{ROOT}/{SAMPLE}", "-o", thr, "--quantile", "0.999", "--margin", "1.5")
    assert done.exit_code == 0, done.output
    out = tmp_path / "out.parquet"
    done = invoke("replay", folder, f"{ROOT}/{HELD_OUT}", "--adapt", "--thresholds", thr, "-o", out, "--json", "-q")
    assert done.exit_code == 0, done.output
    table = pq.read_table(out)
    for name in ("tau_f_pred", "tau_ext_pred", "contact"):
        assert name in table.column_names
    arm = replay.read_arm(str(folder), f"{ROOT}/{HELD_OUT}")
    settings = observer.Thresholds.read(str(thr))
    again = replay.run(arm, settings.gain, settings, observer.Adaptation())
    assert np.array_equal(table.column("tau_ext_pred").to_numpy(), again.tau_ext[:, 0])
    # the per-joint form: r is the low-pass of tau_g + tau_dyn + tau_f_pred - tau_m
    static = replay.run(arm, observer.DEFAULT_GAIN, None, None)
    direct = logs.external_torque(arm.signals[0], arm.f0[:, 0])
    assert np.corrcoef(static.tau_ext[100:, 0], direct[100:])[0, 1] > 0.9
    # the constant thresholds of before: no share of the friction, a flag on the first sample beyond
    settings = observer.Thresholds.read(str(thr))
    assert settings.persistence == observer.DEFAULT_PERSISTENCE and settings.shares[0] > 0
    before = tmp_path / "before.json"
    done = invoke("thresholds", folder, f"{ROOT}/{SAMPLE}", "-o", before, "--persistence", "1", "--no-level-share", "-q")
    assert done.exit_code == 0, done.output
    old = observer.Thresholds.read(str(before))
    assert old.persistence == 1 and old.shares[0] == 0.0 and old.threshold[0] == settings.threshold[0]
    assert invoke("thresholds", folder, f"{ROOT}/{SAMPLE}", "-o", before, "--persistence", "0").exit_code == 2
    # bad input: one line and the exit code
    assert invoke("replay", folder, f"{ROOT}/{HELD_OUT}", "--adapt", "-o", out).exit_code == 2
    thr.write_text("[1]")
    assert invoke("replay", folder, f"{ROOT}/{HELD_OUT}", "--thresholds", thr, "-o", out).exit_code == 3
    newer = observer.Thresholds.read(str(before)).as_json() | {"version": 2}
    thr.write_text(__import__("json").dumps(newer))
    refused = invoke("replay", folder, f"{ROOT}/{HELD_OUT}", "--thresholds", thr, "-o", out)
    assert refused.exit_code == 3 and "version 2" in refused.output
    missing = invoke("replay", folder, tmp_path / "none.parquet", "-o", out)
    assert missing.exit_code == 3 and missing.output.count("\n") == 1 and "Traceback" not in missing.output


@pytest.mark.slow
@pytest.mark.skipif(shutil.which("cc") is None or shutil.which("g++") is None, reason="no C and C++ compiler")
def test_the_exported_arm_header_equals_replay(folder, tmp_path):
    thr = tmp_path / "t.json"
    assert invoke("thresholds", folder, f"{ROOT}/{SAMPLE}", "-o", thr).exit_code == 0
    header = tmp_path / "arm.h"
    arm = replay.read_arm(str(folder), f"{ROOT}/{HELD_OUT}")
    paths = [str(folder / "joint_2.npz")]
    data = observer_check.rows(arm, paths)
    settings = observer.Thresholds.read(str(thr))
    for offset, cxx in ((False, False), (False, True), (True, False), (None, False)):
        if offset is None:   # the observer alone: no thresholds, no adaptation
            done = invoke("export", folder, "--observer", "--prefix", "arm", "-o", header)
            want = replay.run(arm, observer.DEFAULT_GAIN, None, None)
        else:
            done = invoke("export", folder, "--observer", "--thresholds", thr, "--adapt", "--prefix", "arm", "-o",
                          header, *(["--adapt-offset"] if offset else []))
            want = replay.run(arm, observer.DEFAULT_GAIN, settings, observer.Adaptation(offset=offset))
            assert want.contact.any() and np.ptp(want.scale) > 0   # the comparison covers flags and adaptation
            assert (np.ptp(want.offset) > 0) == offset
            at_rest = np.abs(arm.qd[:, 0]) <= settings.moving_speed
            assert (at_rest & (want.scale[:, 0] != 1.0)).any()      # and the static band at an adapted level
        assert done.exit_code == 0, done.output
        exe = observer_check.build(str(header), "arm", paths, str(tmp_path), cxx=cxx)
        got = observer_check.run(exe, data, 1, str(tmp_path))
        assert np.max(np.abs(got[:, 0] - want.tau_f[:, 0])) < 1e-9
        assert np.max(np.abs(got[:, 1] - want.tau_ext[:, 0])) < 1e-9
        assert np.array_equal(got[:, 2].astype(bool), want.contact[:, 0])


def imported_jointwise(tmp_path, joint: int):
    """(the imported log, the URDF, its table) of the UR10e jointwise run of ``joint``, with the URDF's terms."""
    data = shared_data(f"ur10e/jointwise_motion/ur-20_01_22-joint_{joint}.csv")
    urdf = shared_data("ur10e/ur10e.urdf")
    log = tmp_path / f"j{joint}.parquet"
    done = invoke("import", data, "--mapping", f"{ROOT}/docs/ur10e-mapping.toml", "--urdf", urdf, "--cutoff", "10",
                  "-o", log, "-q")
    assert done.exit_code == 0, done.output
    return log, urdf, pq.read_table(log)


def lugre_per_joint(table, folder):
    """A folder of one LuGre model per joint 1..6 of ``table`` (fixed parameters, saved for that joint's rows)."""
    folder.mkdir()
    for j in range(1, 7):
        part = logs.from_table(table, name="x", joint=j)
        models.save_for_log(str(folder / f"joint_{j}.npz"), LuGreModel(2.0, 3.0, 0.05, 1.0, 5.0, sigma0=1e4,
                                                                       sigma1=1.0), part, rows_used=len(part))
    return folder


def test_urdf_momentum_terms_agree_with_the_logs_rigid_body_torques(tmp_path):
    log, urdf, table = imported_jointwise(tmp_path, 2)
    sig = {j: logs.from_table(table, name="x", joint=j).signals for j in range(1, 7)}
    p, w = replay.momentum_terms(str(urdf), table.schema, list(range(1, 7)), sig, "x")
    t = sig[1]["t"]
    pdot = np.gradient(p, t, axis=0)
    rigid = np.column_stack([sig[j]["tau_g"] + sig[j]["tau_dyn"] for j in range(1, 7)])
    # dp/dt + g - C^T qd = M qdd + C qd + g: the log's tau_g + tau_dyn; both low-passed alike (the
    # log's qdd is the measured velocity filtered at 10 Hz and differentiated, pdot is not filtered)
    smooth = lambda x: np.column_stack([logs.lowpass(x[:, k], t, 5.0) for k in range(6)])   # noqa: E731
    scale = np.sqrt(np.mean(rigid ** 2, axis=0))
    err = np.sqrt(np.mean((smooth(pdot + w) - smooth(rigid))[50:-50] ** 2, axis=0))
    assert np.all(err < 0.02 * scale + 0.05), (err, scale)
    # a wrong sign of the Coriolis term or the momentum would not agree
    assert np.sqrt(np.mean((smooth(-pdot + w) - smooth(rigid))[50:-50, 1] ** 2)) > 10 * err[1]


def test_simulated_contacts_at_twice_the_threshold_are_flagged_within_20_ms(tmp_path):
    from fricli.sim import simulator

    p = simulator.true_params(2, "adapt", "base")
    model = LuGreModel(*(p[k] for k in ("fc", "fs", "vs", "delta", "fv", "kc", "ks", "sigma0", "sigma1")))
    folder = tmp_path / "m"
    folder.mkdir()
    free = tmp_path / "free.parquet"
    simulator.write(simulator.simulate("adapt", 2, seed=1, rate=1000.0, friction_state="base"), str(free))
    models.save_for_log(str(folder / "joint_2.npz"), model, logs.load_log(str(free)), rows_used=1, seed=1)
    thr_path = tmp_path / "t.json"
    assert invoke("thresholds", folder, free, "-o", thr_path, "-q").exit_code == 0
    thr = observer.Thresholds.read(str(thr_path))
    assert thr.persistence == observer.DEFAULT_PERSISTENCE and thr.shares[0] > 0
    probe = simulator.simulate("adapt", 2, seed=2, rate=1000.0, friction_state="base")
    simulator.write(probe, str(tmp_path / "probe.parquet"))
    f0 = replay.read_arm(str(folder), str(tmp_path / "probe.parquet")).f0
    # twice the largest threshold in force in motion on the probe: base + share x |the model's friction|
    size = 2.0 * float(thr.threshold[0] + thr.shares[0] * np.max(np.abs(f0)))
    t, qd = probe.column("t").to_numpy(), probe.column("qd").to_numpy()
    moving = np.flatnonzero((np.abs(qd) > 0.1) & (t > 5.0))
    starts = [float(t[moving[i]]) for i in np.linspace(0, len(moving) - 1, 4, endpoint=False).astype(int)]
    contacts = [(s, size if k % 2 else -size, 0.3) for k, s in enumerate(starts)]
    pushed = tmp_path / "pushed.parquet"
    args = [a for c in contacts for a in ("--contact", f"{c[0]!r},{c[1]!r},{c[2]!r}")]
    done = invoke("simulate", "--scenario", "adapt", "--seed", "2", "--rate", "1000", "--friction-state", "base",
                  *args, "-o", pushed, "-q")
    assert done.exit_code == 0, done.output
    table = pq.read_table(pushed)
    assert np.max(np.abs(table.column("tau_ext").to_numpy())) == pytest.approx(size)
    arm = replay.read_arm(str(folder), str(pushed))
    out = replay.run(arm, thr.gain, thr, None)
    for start, torque, length in contacts:
        i = np.searchsorted(arm.t, start)
        flagged = np.flatnonzero(out.contact[i:, 0])
        assert len(flagged) and arm.t[i + flagged[0]] - start <= 0.020
        assert np.sign(out.tau_ext[i + flagged[0], 0]) == np.sign(torque)
    free_run = replay.run(replay.read_arm(str(folder), str(free)), thr.gain, thr, None)
    assert free_run.contact.sum() <= 0.002 * len(free_run.contact)   # the quantile's share, at most


@pytest.mark.skipif(shutil.which("cc") is None or shutil.which("g++") is None, reason="no C and C++ compiler")
def test_the_example_in_the_contact_detection_doc_compiles(folder, tmp_path):
    import re

    text = (ROOT / "docs" / "contact-detection.md").read_text()
    blocks = re.findall(r"```c\n(.*?)```", text, flags=re.S)
    assert len(blocks) == 1 and "arm_arm_step" in blocks[0]
    thr = tmp_path / "t.json"
    assert invoke("thresholds", folder, f"{ROOT}/{SAMPLE}", "-o", thr, "-q").exit_code == 0
    assert invoke("export", folder, "--observer", "--thresholds", thr, "--adapt", "--prefix", "arm", "-o",
                  tmp_path / "arm.h").exit_code == 0
    src = tmp_path / "example.c"
    src.write_text(blocks[0])
    for compiler, flags in (("cc", observer_check.C_FLAGS), ("g++", observer_check.CXX_FLAGS)):
        done = subprocess.run([compiler, *flags, "-c", str(src), "-o", str(tmp_path / "example.o")],
                              capture_output=True, text=True)
        assert done.returncode == 0 and done.stderr == "", done.stderr


def test_a_log_without_robot_model_columns_replays_with_them_declared_zero(folder, tmp_path):
    """A horizontal axis records no tau_g or tau_dyn: replay and thresholds refuse the log (exit 6)
    and name --no-gravity, which they take, as the commands that fit models do."""
    table = pq.read_table(f"{ROOT}/{SAMPLE}")
    bare = tmp_path / "bare.parquet"
    pq.write_table(table.drop_columns(["tau_g", "tau_dyn"]), bare)
    out, thr = tmp_path / "out.parquet", tmp_path / "t.json"
    refused = invoke("replay", folder, bare, "-o", out)
    assert refused.exit_code == 6 and "--no-gravity" in refused.output and not out.exists()
    flags = ("--no-gravity", "--no-dynamics", "-q")
    assert invoke("thresholds", folder, bare, "-o", thr, *flags).exit_code == 0
    done = invoke("replay", folder, bare, "-o", out, "--adapt", "--thresholds", thr, *flags)
    assert done.exit_code == 0, done.output
    zero = logs.load_log(f"{ROOT}/{SAMPLE}", zero=("tau_g", "tau_dyn"))
    assert len(pq.read_table(out)) == len(zero.signals["t"])


def test_a_pause_far_longer_than_the_adaptation_memory_forgets_without_failing(folder, tmp_path):
    """Time stamps 1e7 times too far apart (steps of a day): the forgetting factor exp(-dt/T)
    underflows to 0; the adaptation forgets down to its covariance cap instead of dividing by 0."""
    table = pq.read_table(f"{ROOT}/{SAMPLE}")
    t = table.column("t").to_numpy() * 1e7
    paused = tmp_path / "paused.parquet"
    pq.write_table(table.set_column(table.column_names.index("t"), table.schema.field("t"), [t]), paused)
    thr, out = tmp_path / "t.json", tmp_path / "out.parquet"
    assert invoke("thresholds", folder, paused, "-o", thr, "-q").exit_code == 0
    assert invoke("replay", folder, paused, "-o", out, "--adapt", "--thresholds", thr, "-q").exit_code == 0
    assert np.isfinite(pq.read_table(out).column("tau_ext_pred").to_numpy()).all()


def _two_joints():
    """The sample log's first 400 rows as joints 2 and 3, their rows alternating."""
    table = pq.read_table(f"{ROOT}/{SAMPLE}").slice(0, 400)
    table = table.drop_columns(["joint"])
    two = []
    for j in (2, 3):
        part = table.append_column("joint", pa.array(np.full(len(table), j, dtype=np.int64)))
        two.append(part.append_column("order", pa.array(2 * np.arange(len(table)) + (j - 2))))
    arm = pa.concat_tables(two)
    return arm.take(pc.sort_indices(arm.column("order"))).drop_columns(["order"])


def test_models_that_do_not_match_the_logs_joints_are_refused_without_advising_joint(folder, tmp_path):
    """replay and thresholds take no --joint: a model of no joint on an arm's log, or a folder without a
    model of one of its joints, is refused naming what to give instead."""
    log = tmp_path / "arm.parquet"
    pq.write_table(_two_joints(), log)
    model, _ = models.load(str(folder / "joint_2.npz"))
    unnamed = tmp_path / "unnamed.npz"
    part = logs.from_table(pq.read_table(f"{ROOT}/{SAMPLE}").drop_columns(["joint"]), name="x")
    models.save_for_log(str(unnamed), model, part, rows_used=400)
    for source in (unnamed, folder):
        for args in (("replay", source, log, "-o", tmp_path / "out.parquet"),
                     ("thresholds", source, log, "-o", tmp_path / "t.json")):
            refused = invoke(*args)
            assert refused.exit_code in (3, 4) and refused.output.count("\n") == 1, refused.output
            assert "--joint" not in refused.output and "model" in refused.output, refused.output


def test_invalid_rows_of_one_joint_are_named_by_their_row_in_the_file(folder, tmp_path):
    """A NaN motor torque of one joint of an arm's log: replay and thresholds name its row in the
    file (the joints' rows interleave) and do not advise --drop-invalid, which they do not take."""
    arm = _two_joints()
    tau = arm.column("tau_m").to_numpy().copy()
    tau[11] = np.nan                      # joint 3's row 5
    arm = arm.set_column(arm.column_names.index("tau_m"), arm.schema.field("tau_m"), pa.array(tau))
    log, models_dir = tmp_path / "arm.parquet", tmp_path / "models"
    pq.write_table(arm, log)
    models_dir.mkdir()
    model, _ = models.load(str(folder / "joint_2.npz"))
    for j in (2, 3):
        part = logs.from_table(pq.read_table(f"{ROOT}/{SAMPLE}").drop_columns(["joint"]), name="x")
        part.joint = j
        models.save_for_log(str(models_dir / f"joint_{j}.npz"), model, part, rows_used=400, seed=1)
    for args in (("replay", models_dir, log, "-o", tmp_path / "out.parquet"),
                 ("thresholds", models_dir, log, "-o", tmp_path / "t.json")):
        refused = invoke(*args)
        assert refused.exit_code == 3 and refused.output.count("\n") == 1, refused.output
        assert "first at row 11," in refused.output and "--drop-invalid" not in refused.output


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_the_arm_header_of_a_folder_with_a_coupled_group_equals_replay(tmp_path):
    """A folder of per-joint models and a coupled wrist's model (identify --coupling): replay applies
    the group to each of its joints through its member; the arm header does the same (each member
    reads its partners' velocities) and gives replay's numbers."""
    from fricli.sim.coupled import simulate_coupled

    run = simulate_coupled(duration=4.0, rate_hz=500.0, rng=np.random.default_rng(3))
    log = tmp_path / "arm.parquet"
    logs.write_table(run.table, str(log))
    folder, thr, header = tmp_path / "models", tmp_path / "t.json", tmp_path / "arm.h"
    assert invoke("identify", log, "--coupling", "--kind", "linear", "-o", f"{folder}/", "-q").exit_code == 0
    assert (folder / "joints_5_6.npz").exists()
    assert invoke("thresholds", folder, log, "-o", thr, "-q").exit_code == 0
    done = invoke("export", folder, "--observer", "--thresholds", thr, "--adapt", "--prefix", "arm", "-o", header)
    assert done.exit_code == 0, done.output
    arm = replay.read_arm(str(folder), str(log))
    settings = observer.Thresholds.read(str(thr))
    want = replay.run(arm, settings.gain, settings, observer.Adaptation())
    assert np.ptp(want.scale) > 0
    paths = []                         # each joint's model as the header steps it: the members apart
    for j in arm.joints:
        model, _ = models.load(str(folder / ("joints_5_6.npz" if j in (5, 6) else f"joint_{j}.npz")))
        paths.append(str(tmp_path / f"m{j}.npz"))
        sig = logs.from_table(run.table, name="x", joint=j)
        models.save_for_log(paths[-1], model.member(j) if hasattr(model, "member") else model, sig, rows_used=1)
    text = header.read_text()
    assert "Joints, in the order of every array below: 1, 2, 3, 4, 5, 6." in text
    assert "arm_joints_5_6_joint_6_step_parts_array(&s->friction_5" in text
    exe = observer_check.build(str(header), "arm", paths, str(tmp_path))
    got = observer_check.run(exe, observer_check.rows(arm, paths), len(arm.joints), str(tmp_path))
    n = len(arm.joints)
    assert np.max(np.abs(got[:, :n] - want.tau_f)) < 1e-9
    assert np.max(np.abs(got[:, n:2 * n] - want.tau_ext)) < 1e-9
    assert np.array_equal(got[:, 2 * n:].astype(bool), want.contact)


def test_one_joints_model_replays_with_the_urdf_terms_of_the_whole_arm(tmp_path):
    """The URDF form for some joints of an arm's log: M(q), C and g depend on every joint's position,
    which the log holds; the joints replayed get the terms of the whole arm (it was refused as a
    log without the other joints' positions, advising --hold, which replay does not take)."""
    log, urdf, table = imported_jointwise(tmp_path, 2)
    folder = lugre_per_joint(table, tmp_path / "models")
    whole = replay.read_arm(str(folder), str(log), str(urdf))
    one = replay.read_arm(str(folder / "joint_3.npz"), str(log), str(urdf))
    assert one.joints == [3]
    np.testing.assert_array_equal(one.p[:, 0], whole.p[:, 2])
    np.testing.assert_array_equal(one.w[:, 0], whole.w[:, 2])
    done = invoke("replay", folder / "joint_3.npz", log, "--urdf", urdf, "-o", tmp_path / "out.parquet", "-q")
    assert done.exit_code == 0, done.output


def test_the_rotors_cross_inertia_the_import_recorded_is_in_the_momentum(tmp_path):
    """A coupled wrist imported with its motors' inertias: the import adds their cross-inertia
    (off the diagonal, joints x joints) to tau_dyn and records it; the observer's momentum p = M(q) qd
    must hold it too, or the residual carries its torque J qdd."""
    import json

    log, urdf, table = imported_jointwise(tmp_path, 5)
    meta = dict(table.schema.metadata)
    record = json.loads(meta[b"fricli.import"])
    cross = np.zeros((6, 6))
    cross[4, 5] = cross[5, 4] = 0.05                  # joints 5 and 6 (kg m^2), in the import's joint order
    record["robot"]["cross_inertia"] = cross.tolist()
    meta[b"fricli.import"] = json.dumps(record).encode()
    coupled_log = tmp_path / "coupled.parquet"
    pq.write_table(table.replace_schema_metadata(meta), coupled_log)
    folder = lugre_per_joint(table, tmp_path / "models")
    plain = replay.read_arm(str(folder), str(log), str(urdf))
    coupled = replay.read_arm(str(folder), str(coupled_log), str(urdf))
    np.testing.assert_allclose(coupled.p - plain.p, plain.qd @ cross.T, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(coupled.w, plain.w)


def test_thresholds_on_logs_that_list_the_same_joints_in_another_order(folder, tmp_path):
    """Calibration logs with the same joints whose rows come in another order (joint 3's rows first):
    the same thresholds as from the logs in one order, instead of a refusal."""
    arm = _two_joints()
    tau = arm.column("tau_m").to_numpy() + np.where(arm.column("joint").to_numpy() == 3, 0.7, 0.0)   # joints differ
    arm = arm.set_column(arm.column_names.index("tau_m"), arm.schema.field("tau_m"), pa.array(tau))
    log, other = tmp_path / "arm.parquet", tmp_path / "other.parquet"
    pq.write_table(arm, log)
    swapped = np.arange(len(arm)).reshape(-1, 2)[:, ::-1].ravel()       # each time: joint 3, then joint 2
    pq.write_table(arm.take(pa.array(swapped)), other)
    models_dir = tmp_path / "models"
    models_dir.mkdir()
    model, _ = models.load(str(folder / "joint_2.npz"))
    for j in (2, 3):
        part = logs.from_table(arm, name="x", joint=j)
        models.save_for_log(str(models_dir / f"joint_{j}.npz"), model, part, rows_used=400, seed=1)
    want = replay.calibrate(str(models_dir), [str(log), str(log)])
    got = replay.calibrate(str(models_dir), [str(log), str(other)])
    assert [str(j) for j in got.joints] == ["2", "3"]
    assert got.as_json()["joints"] == want.as_json()["joints"]
    assert want.threshold[0] != want.threshold[1]


def test_a_joint_missing_a_sample_is_named_with_the_time(folder, tmp_path):
    """One joint of an arm's log without its row at one time: the refusal says where."""
    arm = _two_joints()
    log = tmp_path / "arm.parquet"
    pq.write_table(arm.take(pa.array([i for i in range(len(arm)) if i != 21])), log)   # joint 3's 11th sample
    models_dir = tmp_path / "models"
    models_dir.mkdir()
    model, _ = models.load(str(folder / "joint_2.npz"))
    for j in (2, 3):
        models.save_for_log(str(models_dir / f"joint_{j}.npz"), model, logs.from_table(arm, name="x", joint=j),
                            rows_used=400)
    t = pq.read_table(f"{ROOT}/{SAMPLE}").column("t").to_numpy()
    refused = invoke("replay", models_dir, log, "-o", tmp_path / "out.parquet")
    assert refused.exit_code == 3 and refused.output.count("\n") == 1
    assert f"joint 3 has other time stamps than joint 2 (sample 11: t = {t[11]:.15g} s against {t[10]:.15g} s)" \
        in refused.output, refused.output


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler")
def test_the_adapted_level_scales_the_friction_and_not_the_robot_model_error(tmp_path):
    """A model of diagnose --fix with a robot-model error term (the logged gravity torque 15 % low):
    the online adaptation learns the friction's level, so a scales the friction part alone; the error
    part is the robot model's (it stays as fitted), in replay and in the arm header alike."""
    from fricli.models.augmented import AugmentedModel
    from fricli.models.base import predict_parts

    log = logs.load_log(f"{ROOT}/{SAMPLE}")
    base = LuGreModel(7.0 * 1.3, 9.0 * 1.3, 0.04, 1.2, 12.0 * 1.3, sigma0=1.7e4, sigma1=0.5)   # 30 % too high
    gravity = [{"name": "tau_g", "factors": [{"f": "signal", "name": "tau_g"}]}]
    model = AugmentedModel(base, [], np.zeros(0), error_terms=gravity, error_coef=np.array([0.15]),
                           errors=["gravity"])
    folder = tmp_path / "models"
    folder.mkdir()
    models.save_for_log(str(folder / "joint_2.npz"), model, log, rows_used=len(log))
    thr = tmp_path / "t.json"
    assert invoke("thresholds", folder, f"{ROOT}/{SAMPLE}", "-o", thr, "-q").exit_code == 0
    arm = replay.read_arm(str(folder), f"{ROOT}/{HELD_OUT}")
    settings = observer.Thresholds.read(str(thr))
    out = replay.run(arm, settings.gain, settings, observer.Adaptation())
    friction, error, _ = predict_parts(models.set_precision(model, "double"), arm.signals[0])
    assert np.ptp(out.scale) > 0.05 and np.abs(error).max() > 1.0
    np.testing.assert_allclose(out.tau_f[:, 0], out.scale[:, 0] * friction + out.offset[:, 0] + error,
                               rtol=0, atol=1e-9)
    header = tmp_path / "arm.h"
    assert invoke("export", folder, "--observer", "--thresholds", thr, "--adapt", "--prefix", "arm", "-o",
                  header).exit_code == 0
    paths = [str(folder / "joint_2.npz")]
    exe = observer_check.build(str(header), "arm", paths, str(tmp_path))
    got = observer_check.run(exe, observer_check.rows(arm, paths), 1, str(tmp_path))
    assert np.max(np.abs(got[:, 0] - out.tau_f[:, 0])) < 1e-9
    assert np.max(np.abs(got[:, 1] - out.tau_ext[:, 0])) < 1e-9
    assert np.array_equal(got[:, 2].astype(bool), out.contact[:, 0])


def test_the_python_calls_are_the_commands(folder, tmp_path):
    """``fricli.calibrate_thresholds`` and ``fricli.replay_log`` write the commands' files, give what
    ``--json`` prints, and refuse what they refuse (OptionError naming the option)."""
    import json

    import fricli
    from fricli.fitting.optionspec import OptionError

    done = invoke("thresholds", folder, f"{ROOT}/{SAMPLE}", "-o", tmp_path / "cmd.json", "--margin", "2", "-q")
    assert done.exit_code == 0, done.output
    thr = fricli.calibrate_thresholds(str(folder), f"{ROOT}/{SAMPLE}", str(tmp_path / "call.json"), margin=2.0)
    assert (tmp_path / "call.json").read_bytes() == (tmp_path / "cmd.json").read_bytes()
    assert thr.as_json() == json.loads((tmp_path / "cmd.json").read_text())
    done = invoke("replay", folder, f"{ROOT}/{HELD_OUT}", "--adapt", "--thresholds", tmp_path / "cmd.json",
                  "-o", tmp_path / "cmd.parquet", "--json", "-q")
    assert done.exit_code == 0, done.output
    run = fricli.replay_log(str(folder), f"{ROOT}/{HELD_OUT}", str(tmp_path / "call.parquet"), adapt=True,
                            thresholds=str(tmp_path / "call.json"))
    assert pq.read_table(tmp_path / "call.parquet").equals(pq.read_table(tmp_path / "cmd.parquet"), check_metadata=True)
    printed = json.loads(done.stdout)
    assert {k: printed[k] for k in run.figures} == json.loads(json.dumps(run.figures)) and printed["gain"] == run.gain
    for kwargs, option in (({"adapt": True}, "thresholds"), ({"adapt_offset": True}, "adapt_offset"),
                           ({"thresholds": str(tmp_path / "call.json"), "gain": 10.0}, "gain")):
        with pytest.raises(OptionError) as err:
            fricli.replay_log(str(folder), f"{ROOT}/{HELD_OUT}", str(tmp_path / "refused.parquet"), **kwargs)
        assert err.value.option == option
    assert not (tmp_path / "refused.parquet").exists()


def test_a_log_without_a_joint_column_is_not_called_joint_none(folder, tmp_path):
    """A one-joint log without a joint column replays with a model of one joint; stderr names its
    joint plainly, never "None"."""
    table = pq.read_table(f"{ROOT}/{SAMPLE}")
    plain = tmp_path / "plain.parquet"
    pq.write_table(table.drop_columns(["joint"]) if "joint" in table.column_names else table, plain)
    thr, out = tmp_path / "t.json", tmp_path / "out.parquet"
    done = invoke("thresholds", folder / "joint_2.npz", plain, "-o", thr)
    assert done.exit_code == 0, done.output
    assert "the joint: threshold" in done.stderr and "None" not in done.stderr
    done = invoke("replay", folder / "joint_2.npz", plain, "-o", out, "--thresholds", thr)
    assert done.exit_code == 0, done.output
    assert "rows of the log's joint" in done.stderr and "None" not in done.stderr


@pytest.mark.parametrize("rate, gain", [(1000.0, observer.FAST_GAIN), (200.0, observer.FAST_GAIN),
                                        (100.0, observer.DEFAULT_GAIN)])
def test_thresholds_choose_the_gain_by_the_sample_rate(tmp_path, rate, gain):
    """K dt at most 0.5 at the fast gain (a wrong sample moves the residual by a third of its error at
    most): the fast gain from 200 Hz on, the default below; --gain overrides it."""
    log = tmp_path / "log.parquet"
    assert invoke("simulate", "--scenario", "adapt", "--rate", rate, "-o", log, "-q").exit_code == 0
    assert invoke("identify", log, "--kind", "linear", "-o", tmp_path / "m.npz", "-q").exit_code == 0
    done = invoke("thresholds", tmp_path / "m.npz", log, "-o", tmp_path / "t.json")
    assert done.exit_code == 0, done.output
    assert observer.Thresholds.read(str(tmp_path / "t.json")).gain == gain
    assert f"observer gain {gain:g} 1/s" in done.output
    assert invoke("thresholds", tmp_path / "m.npz", log, "--gain", 70, "-o", tmp_path / "t.json", "-q").exit_code == 0
    assert observer.Thresholds.read(str(tmp_path / "t.json")).gain == 70.0


def test_a_log_without_acceleration_is_given_one_only_for_a_model_that_reads_it(tmp_path):
    """The observer reads no acceleration: a log without one is replayed without deriving it (no
    zero-phase filter over the log) for a model that reads none, and with it for one that reads it."""
    from conftest import make_table
    from fricli.models import register
    from fricli.models.base import FrictionModel

    @register
    class ReadsAcceleration(FrictionModel):
        kind = "test-replay-inertial"

        def predict(self, signals, state=None):
            return 0.01 * signals["qdd"], None

        def required_inputs(self):
            return {"qd", "qdd"}

        @classmethod
        def from_parts(cls, params, arrays, children):
            return cls()

    log = tmp_path / "no_qdd.parquet"
    pq.write_table(make_table(n=1500), log)
    zero = ("tau_dyn",)
    for model, reads in ((LuGreModel(fc=5.0, fs=6.0, vs=0.05, delta=1.0, fv=10.0, sigma0=1e4, sigma1=5.0), False),
                         (ReadsAcceleration(), True)):
        path = str(tmp_path / f"{model.kind}.npz")
        models.save(path, model, joint=None, axis="rotary", units={}, provenance={})
        arm = replay.read_arm(path, str(log), zero=zero)
        assert ("qdd" in arm.signals[0]) == reads, model.kind
        if reads:
            np.testing.assert_allclose(arm.f0[:, 0], 0.01 * logs.from_table(make_table(n=1500), name="x",
                                                                            zero=zero).signals["qdd"])
