"""fricli import of ROS bags: sensor_msgs/JointState in rosbag2 (MCAP, sqlite3) and ROS 1 bags."""

import json
import re
import sys
import tomllib

import numpy as np
import pyarrow.parquet as pq
import pytest

rosbags = pytest.importorskip("rosbags")

from rosbags.rosbag1 import Writer as Writer1  # noqa: E402
from rosbags.rosbag2 import StoragePlugin, Writer as Writer2  # noqa: E402
from rosbags.typesys import Stores, get_typestore  # noqa: E402

from conftest import run_in  # noqa: E402
from fricli.core import errors  # noqa: E402
from fricli.core.errors import LogError  # noqa: E402
from fricli.robot.importing import build_log, import_recording  # noqa: E402
from fricli.robot.mapping import parse_bag_mapping, parse_mapping  # noqa: E402
from fricli.robot.rosbag import read_bag  # noqa: E402

NAMES = [f"joint_{k}" for k in range(1, 7)]
START_NS = 1_700_000_000_000_000_000
STEP_NS = 2_000_000            # 500 Hz


def states(n=120, seed=0):
    """Per message: (stamp [ns], names, position, velocity, effort) of six joints."""
    rng = np.random.default_rng(seed)
    q, qd, tau = rng.normal(size=(3, n, 6))
    return [[START_NS + k * STEP_NS, list(NAMES), q[k], qd[k], tau[k]] for k in range(n)]


def write_bag(path, msgs, kind="mcap", topic="/joint_states", extra_topics=(), first=0):
    """Write ``msgs`` (see ``states``) as JointState messages, received every 2 ms from message ``first``."""
    ros1 = kind == "ros1"
    store = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    JointState = store.types["sensor_msgs/msg/JointState"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    msgtype = "sensor_msgs/msg/JointState"
    if ros1:
        writer = Writer1(path)
    else:
        plugin = StoragePlugin.MCAP if kind == "mcap" else StoragePlugin.SQLITE3
        writer = Writer2(path, version=9, storage_plugin=plugin)
    with writer:
        conns = [writer.add_connection(t, msgtype, typestore=store) for t in (topic, *extra_topics)]
        for k, (stamp, names, q, qd, tau) in enumerate(msgs):
            stamp_time = Time(sec=stamp // 10**9, nanosec=stamp % 10**9)
            header = Header(seq=k, stamp=stamp_time, frame_id="") if ros1 else Header(stamp=stamp_time, frame_id="")
            msg = JointState(header=header, name=names, position=np.ascontiguousarray(q, dtype=np.float64),
                             velocity=np.ascontiguousarray(qd, dtype=np.float64),
                             effort=np.ascontiguousarray(tau, dtype=np.float64))
            data = store.serialize_ros1(msg, msgtype) if ros1 else store.serialize_cdr(msg, msgtype)
            received = START_NS + 1_000_000 + (first + k) * STEP_NS
            for conn in conns:
                writer.write(conn, received, data)
    return path


def csv_of(msgs):
    """The same data as a CSV import sees it: t [s] from the first stamp, then q, qd, tau per joint."""
    lines = []
    for stamp, _, q, qd, tau in msgs:
        fields = [repr((stamp - msgs[0][0]) / 1e9)] + [repr(float(v)) for v in (*q, *qd, *tau)]
        lines.append(",".join(fields))
    text = "time = 1\n" + "".join(
        f'[[joints]]\nname = "{n}"\nq = {2 + j}\nqd = {8 + j}\ntau_m = {14 + j}\n' for j, n in enumerate(NAMES))
    return ("\n".join(lines) + "\n").encode(), parse_mapping(tomllib.loads(text))


def bag_log(path, mapping=None, **kw):
    read = read_bag(str(path), mapping, **kw)
    return read, build_log(read.recording, read.mapping, str(path), read.sha256, unit="message")


@pytest.mark.parametrize("kind", ["mcap", "sqlite3", "ros1"])
def test_a_bag_imports_like_the_same_data_as_csv(tmp_path, kind):
    msgs = states()
    path = write_bag(tmp_path / ("run.bag" if kind == "ros1" else "run"), msgs, kind)
    read, log = bag_log(path)
    assert read.topic == "/joint_states" and read.stamps == "header" and read.origin_ns == START_NS
    assert read.recording.defects == {} and read.reordered is None
    data, mapping = csv_of(msgs)
    csv = import_recording(data, mapping, "run.csv").table
    assert log.table.column_names == ["t", "joint", "q", "qd", "tau_m"]
    assert log.table.replace_schema_metadata(None).equals(csv.replace_schema_metadata(None))
    assert log.table.column("joint").to_pylist()[::len(msgs)] == NAMES


def test_the_command_reads_a_bag_and_records_it(tmp_path):
    write_bag(tmp_path / "run", states())
    res = run_in(tmp_path, "import", "run", "-o", "out.parquet")
    assert res.returncode == 0, res.stderr
    assert res.stderr == "imported 120 messages x 6 joints from /joint_states in run -> out.parquet\n"
    meta = json.loads(pq.read_table(tmp_path / "out.parquet").schema.metadata[b"fricli.import"])
    assert meta["topic"] == "/joint_states" and meta["stamps"] == "header" and meta["counted_in"] == "message"
    assert meta["time_origin_ns"] == START_NS and meta["rows"] == 120 and meta["dropped"] == {}


@pytest.mark.parametrize("stamp", [0, START_NS])
def test_unset_or_constant_stamps_fall_back_to_receive_times(tmp_path, stamp):
    msgs = states(40)
    for m in msgs:
        m[0] = stamp
    read, log = bag_log(write_bag(tmp_path / "run", msgs))
    assert read.stamps == "receive" and read.recording.defects == {}
    t = log.table.column("t").to_numpy()[:40]
    np.testing.assert_array_equal(t, np.arange(40) * STEP_NS / 1e9)


def test_several_joint_state_topics_need_a_choice(tmp_path):
    path = write_bag(tmp_path / "run", states(20), extra_topics=("/arm/joint_states",))
    with pytest.raises(errors.LogError, match=r"2 JointState topics \(/arm/joint_states, /joint_states\): "
                                              "choose one with --topic"):
        read_bag(str(path))
    assert read_bag(str(path), topic="/arm/joint_states").topic == "/arm/joint_states"
    with pytest.raises(errors.LogError, match="topic /nope is not in the bag"):
        read_bag(str(path), topic="/nope")


def test_each_defect_of_a_bag_is_reported_by_message(tmp_path):
    msgs = states(100)
    clean = [list(m) for m in msgs]
    msgs[10][0], msgs[11][0] = msgs[11][0], msgs[10][0]                 # message 12 goes back
    msgs[20] = [msgs[20][0], NAMES[:5], msgs[20][2][:5], msgs[20][3][:5], msgs[20][4][:5]]   # joint 6 missing
    msgs[30][4] = msgs[30][4].copy()
    msgs[30][4][2] = np.nan                                             # NaN effort
    order = [5, 4, 3, 2, 1, 0]
    for k in (40, 41):                                                  # the same joints in reverse order
        msgs[k] = [msgs[k][0], [NAMES[i] for i in order], *(np.asarray(a)[order] for a in msgs[k][2:])]
    path = write_bag(tmp_path / "run", msgs)
    with pytest.raises(errors.LogError, match=r"time goes back at message 12 .*--drop-backward"):
        read_bag(str(path))
    read, log = bag_log(path, drop_backward=True)
    got = {k: (d.count, d.ranges) for k, d in read.recording.defects.items()}
    assert got == {"missing_joints": (1, [[21, 21]]), "non_numeric": (1, [[31, 31]]),
                   "backward_time": (1, [[12, 12]])}
    assert (read.reordered.count, read.reordered.ranges) == (2, [[41, 42]])
    q = log.table.column("q").to_numpy().reshape(6, -1)
    kept = [k for k in range(100) if k not in (11, 20, 30)]
    np.testing.assert_array_equal(q, np.array([clean[k][2] for k in kept]).T)   # reordered back by name
    res = run_in(tmp_path, "import", "run", "--drop-backward", "-o", "out.parquet")
    assert res.returncode == 0, res.stderr
    assert res.stderr.splitlines() == [
        "warning: run: dropped 1 message with joints missing (message 21: no 'joint_6' among joint_1, joint_2, joint_3, "
        "joint_4, joint_5)",
        "warning: run: dropped 1 message with non-numeric or non-finite value (message 31: effort of joint_3 is nan)",
        "warning: run: dropped 1 message with time going back (message 12)",
        "warning: run: 2 messages list the joints in another order than most messages (messages 41-42): reordered by name",
        "imported 97 messages x 6 joints from /joint_states in run -> out.parquet"]


def test_garbage_messages_at_the_start_are_dropped(tmp_path):
    msgs = states(80)
    garbage = [[0, list(NAMES), np.zeros(6), np.zeros(6), np.zeros(6)],
               [START_NS + 10**15, list(NAMES), np.full(6, 1e150), np.ones(6), np.ones(6)],
               [START_NS - 10**12, list(NAMES), np.ones(6), np.ones(6), np.ones(6)]]
    read, log = bag_log(write_bag(tmp_path / "run", garbage + msgs))
    assert {k: d.ranges for k, d in read.recording.defects.items()} == {
        "implausible": [[2, 2]], "zero_row": [[1, 1]], "time_outside": [[3, 3]]}
    assert list(read.recording.lines) == list(range(4, 84)) and read.origin_ns == START_NS


def test_a_bag_of_zero_messages_is_refused(tmp_path):
    msgs = states(40)
    for m in msgs:
        m[2:] = [np.zeros(6), np.zeros(6), np.zeros(6)]
    with pytest.raises(LogError, match=r"no usable messages on /joint_states \(40 with all values zero"):
        bag_log(write_bag(tmp_path / "run", msgs))


def test_one_odd_first_message_is_the_one_reordered(tmp_path):
    msgs = states(40)
    order = [5, 0, 1, 2, 3, 4]
    msgs[0] = [msgs[0][0], [NAMES[i] for i in order], *(a[order] for a in msgs[0][2:])]
    read, log = bag_log(write_bag(tmp_path / "run", msgs))
    assert (read.reordered.count, read.reordered.ranges) == (1, [[1, 1]])
    assert log.table.column("joint").to_pylist()[::40] == NAMES


def test_fewer_than_three_messages_are_refused(tmp_path):
    with pytest.raises(LogError, match=r"only 2 usable messages on /joint_states"):
        bag_log(write_bag(tmp_path / "run", states(2)))


def test_messages_the_metadata_lists_but_cannot_be_read_are_counted(tmp_path):
    path = write_bag(tmp_path / "run", states(40), "sqlite3")
    meta = path / "metadata.yaml"
    meta.write_text(meta.read_text().replace("message_count: 40", "message_count: 45"))
    assert read_bag(str(path)).unread == 5
    res = run_in(tmp_path, "import", "run", "-o", "out.parquet")
    assert res.returncode == 0 and res.stderr.startswith(
        "warning: run: 5 of the messages the bag's metadata lists on /joint_states could not be read"), res.stderr


def test_a_damaged_bag_is_an_input_error(tmp_path):
    path = write_bag(tmp_path / "run", states(40))
    data = next(path.glob("*.mcap"))
    raw = bytearray(data.read_bytes())
    raw[len(raw) // 3:len(raw) // 3 + 200] = b"\xff" * 200
    data.write_bytes(bytes(raw))
    with pytest.raises(LogError, match="not a readable ROS bag"):
        bag_log(path)


@pytest.mark.parametrize("kind", ["mcap", "sqlite3"])
def test_a_recording_without_metadata_reads_its_storage_files(tmp_path, kind):
    """A rosbag2 recording that did not end cleanly has no metadata.yaml: its split files are read
    as they are, in split order, and give the same log as the finished bag."""
    msgs = states(120)
    whole = write_bag(tmp_path / "whole", msgs, kind)
    suffix = ".mcap" if kind == "mcap" else ".db3"
    cut = tmp_path / "cut"
    cut.mkdir()
    for k, first in ((9, 0), (10, 60)):      # run_10 after run_9, not between run_1 and run_2
        half = write_bag(tmp_path / f"part{k}", msgs[first:first + 60], kind, first=first)
        next(half.glob("*" + suffix)).rename(cut / f"run_{k}{suffix}")
    read, log = bag_log(cut)
    assert read.standalone == [f"run_9{suffix}", f"run_10{suffix}"]
    assert log.table.equals(bag_log(whole)[1].table)
    single = next(whole.glob("*" + suffix))
    (whole / "metadata.yaml").unlink()
    read, log = bag_log(single)
    assert read.standalone == [single.name] and log.table.equals(bag_log(whole)[1].table)
    res = run_in(tmp_path, "import", "cut", "-o", "out.parquet")
    assert res.returncode == 0 and res.stderr.startswith(
        f"note: cut: no rosbag2 metadata.yaml (a recording that did not end cleanly?): read run_9{suffix}, "
        f"run_10{suffix} as they are"), res.stderr


def test_a_folder_without_storage_files_or_an_mcap_cut_short_is_refused(tmp_path):
    (tmp_path / "empty").mkdir()
    with pytest.raises(LogError, match="without a rosbag2 metadata.yaml or .mcap/.db3 storage files"):
        bag_log(tmp_path / "empty")
    data = next(write_bag(tmp_path / "run", states(400)).glob("*.mcap"))
    data.write_bytes(data.read_bytes()[:data.stat().st_size // 2])     # the recorder killed mid-write
    with pytest.raises(LogError, match=r"cut short .*`mcap recover FILE -o FIXED.mcap`"):
        bag_log(tmp_path / "run")


def test_a_refusal_names_the_joint_that_is_missing_or_not_finite(tmp_path):
    msgs = states(40)
    for m in msgs:
        m[4] = np.where(np.arange(6) == 5, np.nan, m[4])          # joint_6 publishes no effort
    with pytest.raises(LogError, match=re.escape("(first at message 1: effort of joint_6 is nan)); a joint that never has")):
        bag_log(write_bag(tmp_path / "nan", msgs))
    typo = parse_bag_mapping(tomllib.loads("".join(f'[[joints]]\nname = "{n}"\n' for n in NAMES[:5] + ["joint6"])))
    with pytest.raises(LogError, match=re.escape("joints missing (first at message 1: no 'joint6' among joint_1, joint_2")):
        bag_log(write_bag(tmp_path / "run", states(40)), typo)


def test_empty_velocities_leave_qd_to_be_derived(tmp_path):
    msgs = states(40)
    for m in msgs:
        m[3] = []
    _, log = bag_log(write_bag(tmp_path / "run", msgs))
    assert log.table.column_names == ["t", "joint", "q", "tau_m"]


def test_a_velocity_empty_in_some_messages_is_left_out_with_a_warning(tmp_path):
    msgs = states(40)
    msgs[10][3] = []
    write_bag(tmp_path / "run", msgs)
    res = run_in(tmp_path, "import", "run", "-o", "out.parquet")
    assert res.returncode == 0, res.stderr
    assert res.stderr.splitlines()[0] == (
        "warning: run: 1 message on /joint_states holds no velocity (first at message 11): the velocity of every "
        "message is left out (qd and qdd are derived from the positions)")
    assert "qd" not in pq.read_table(tmp_path / "out.parquet").column_names


def test_time_going_back_is_shown_from_the_first_message(tmp_path):
    msgs = states(40)
    msgs[20], msgs[21] = msgs[21], msgs[20]
    step = STEP_NS / 1e9          # message 22 holds the stamp of the 21st: times from the first message
    with pytest.raises(LogError, match=rf"time goes back at message 22 \(t = {20 * step:g} after {21 * step:g};"):
        bag_log(write_bag(tmp_path / "run", msgs))


def test_a_mapping_says_what_the_effort_is(tmp_path):
    path = write_bag(tmp_path / "run", states(30))
    effort = np.array([m[4] for m in states(30)])
    currents = """
[robot]
match = "order"
[[joints]]
name = "joint_2"
effort = "i_m"
kt = 4.0
urdf = "shoulder"
[[joints]]
name = "joint_5"
effort = "i_m"
kt = 8.0
"""
    read, log = bag_log(path, parse_bag_mapping(tomllib.loads(currents)))
    assert log.table.column_names == ["t", "joint", "q", "qd", "i_m", "tau_m"]
    assert log.table.column("joint").to_pylist()[::30] == ["joint_2", "joint_5"]
    np.testing.assert_array_equal(log.table.column("i_m").to_numpy(), effort[:, [1, 4]].T.ravel())
    np.testing.assert_array_equal(log.table.column("tau_m").to_numpy(), (effort[:, [1, 4]] * [4.0, 8.0]).T.ravel())
    assert read.mapping.match == "order" and read.mapping.joints[0].urdf == "shoulder"
    assert log.meta["kt"] == {"joint_2": 4.0, "joint_5": 8.0}
    motor = '[[joints]]\nname = "joint_3"\neffort = "motor_torque"\ngear_ratio = 100.0\n'
    _, log = bag_log(path, parse_bag_mapping(tomllib.loads(motor)))
    assert log.table.column_names == ["t", "joint", "q", "qd", "tau_m"]
    np.testing.assert_array_equal(log.table.column("tau_m").to_numpy(), 100.0 * effort[:, 2])
    # a current on one joint, a motor torque on the other (docs/robot-import.md's example): tau_m
    # holds both; the current is no column of one joint only
    mixed = currents.split("[[joints]]\nname = \"joint_5\"")[0] + motor
    _, log = bag_log(path, parse_bag_mapping(tomllib.loads(mixed)))
    assert log.table.column_names == ["t", "joint", "q", "qd", "tau_m"] and log.meta["i_m_left_out"] == ["joint_2"]
    np.testing.assert_array_equal(log.table.column("tau_m").to_numpy(),
                                  np.concatenate([4.0 * effort[:, 1], 100.0 * effort[:, 2]]))
    (tmp_path / "mixed.toml").write_text(mixed)
    res = run_in(tmp_path, "import", "run", "--mapping", "mixed.toml", "-o", "m.parquet")
    assert res.returncode == 0 and res.stderr.startswith("note: run: the effort of joint joint_2 is a current and of "
                                                         "the others not"), res.stderr
    with pytest.raises(errors.LogError, match="kt applies to effort"):
        parse_bag_mapping(tomllib.loads('[[joints]]\nname = "a"\nkt = 2.0\n'))
    with pytest.raises(errors.LogError, match="needs gear_ratio"):
        parse_bag_mapping(tomllib.loads('[[joints]]\nname = "a"\neffort = "motor_torque"\n'))
    with pytest.raises(errors.LogError, match="unknown key 'time'"):
        parse_bag_mapping(tomllib.loads('time = 1\n'))


def test_missing_rosbags_is_a_dependency_error(tmp_path, monkeypatch):
    path = write_bag(tmp_path / "run", states(10))
    monkeypatch.setitem(sys.modules, "rosbags.highlevel", None)
    with pytest.raises(errors.MissingDependencyError, match=r"pip install 'fricli\[ros\]'"):
        read_bag(str(path))


def test_urdf_terms_of_a_bag_match_joints_by_their_names(tmp_path):
    pytest.importorskip("pinocchio")
    from test_urdf import URDF, analytic

    rng = np.random.default_rng(3)
    n = 60
    q = rng.uniform(-np.pi, np.pi, (n, 2))
    msgs = [[START_NS + k * STEP_NS, ["elbow", "shoulder"], q[k, ::-1], [], rng.normal(size=2)] for k in range(n)]
    write_bag(tmp_path / "run", msgs)
    (tmp_path / "two_link.urdf").write_text(URDF)
    res = run_in(tmp_path, "import", "run", "--urdf", "two_link.urdf", "-o", "out.parquet")
    assert res.returncode == 0, res.stderr
    assert "joints matched by name, derived qd and qdd" in res.stderr
    table = pq.read_table(tmp_path / "out.parquet")
    assert table.column("joint").to_pylist()[::n] == ["elbow", "shoulder"]
    tau_g = table.column("tau_g").to_numpy().reshape(2, n).T[:, ::-1]        # shoulder, elbow
    expected, _ = analytic(q, np.zeros_like(q), np.zeros_like(q), (0.0, 0.0, -9.81))
    np.testing.assert_allclose(tau_g, expected, atol=1e-9)
    assert np.isfinite(table.column("tau_dyn").to_numpy()).all()


def test_a_bag_leaves_the_joints_the_urdf_holds_out(tmp_path):
    """A gripper's finger (and the finger that mimics it) in every message: --hold leaves them out of
    a bag's log, which then holds the arm's joints and their URDF terms."""
    pytest.importorskip("pinocchio")
    from test_urdf import URDF, analytic

    fingers = ('<joint name="finger" type="prismatic"><parent link="{p}"/><child link="pad"/><axis xyz="0 1 0"/>'
               '<limit lower="0" upper="0.04" effort="20" velocity="0.2"/></joint><link name="pad"/>'
               '<joint name="finger2" type="prismatic"><parent link="{p}"/><child link="pad2"/><axis xyz="0 -1 0"/>'
               '<limit lower="0" upper="0.04" effort="20" velocity="0.2"/><mimic joint="finger"/></joint>'
               '<link name="pad2"/></robot>')
    last = [line.split('"')[1] for line in URDF.splitlines() if "<link name=" in line][-1]
    (tmp_path / "grip.urdf").write_text(URDF.replace("</robot>", fingers.format(p=last)))
    rng = np.random.default_rng(3)
    n = 60
    q = rng.uniform(-np.pi, np.pi, (n, 2))
    msgs = [[START_NS + k * STEP_NS, ["shoulder", "elbow", "finger", "finger2"], np.r_[q[k], 0.02, 0.02], [],
             rng.normal(size=4)] for k in range(n)]
    write_bag(tmp_path / "run", msgs)
    run = lambda *a: run_in(tmp_path, "import", "run", "--urdf", "grip.urdf", *a, "-o", "out.parquet")  # noqa: E731
    res = run()
    assert res.returncode == errors.MODEL and "--hold finger" in res.stderr, res.stderr
    res = run("--hold", "finger")
    assert res.returncode == 0, res.stderr
    table = pq.read_table(tmp_path / "out.parquet")
    assert table.column("joint").to_pylist()[::n] == ["shoulder", "elbow"]
    expected, _ = analytic(q, np.zeros_like(q), np.zeros_like(q), (0.0, 0.0, -9.81))
    np.testing.assert_allclose(table.column("tau_g").to_numpy().reshape(2, n).T, expected, atol=1e-9)
