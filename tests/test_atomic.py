"""Atomic writes (fricli/core/atomic.py): writers of one output never remove each other's temporary
files, a dead writer's leftover is removed, and the process umask is never touched."""

from __future__ import annotations

import fcntl
import os
import stat
import subprocess
import sys
import threading
import time
import types

import pytest

from conftest import ROOT
from fricli.core import atomic
from fricli.core.errors import OutputError

# Writer A in its own process: creates its temporary file, writes half of its content, says so,
# waits for the word "go" on stdin, then writes the rest and renames.
WRITER = """
import sys
from fricli.core.atomic import atomic_open
with atomic_open(sys.argv[1]) as fh:
    fh.write(b"A" * 50_000)
    fh.flush()
    print("writing", flush=True)
    sys.stdin.readline()
    fh.write(b"A" * 50_000)
print("done", flush=True)
"""


def temps(folder, name):
    return sorted(p.name for p in folder.iterdir() if p.name.startswith(f".{name}.") and p.name.endswith(".tmp"))


def start_writer(path):
    env = dict(os.environ, PYTHONPATH=os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")]))
    proc = subprocess.Popen([sys.executable, "-c", WRITER, str(path)], env=env, text=True,
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    assert proc.stdout.readline() == "writing\n", proc.stderr.read()
    return proc


def test_a_second_writer_leaves_the_live_writers_temporary_file_alone(tmp_path):
    out = tmp_path / "pred.parquet"
    out.write_bytes(b"previous")
    first = start_writer(out)
    [live] = temps(tmp_path, out.name)
    atomic.atomic_write_bytes(str(out), b"B" * 70_000)  # starts and ends while the first is live
    assert out.read_bytes() == b"B" * 70_000
    assert temps(tmp_path, out.name) == [live]  # not taken for a leftover
    out_, err = first.communicate("go\n", timeout=30)
    assert first.returncode == 0 and out_ == "done\n", err
    assert out.read_bytes() == b"A" * 100_000  # the complete file of the writer that renamed last
    assert sorted(p.name for p in tmp_path.iterdir()) == [out.name]


def test_the_leftover_of_a_dead_writer_is_removed_and_a_held_one_kept(tmp_path):
    out = tmp_path / "m.npz"
    dead = tmp_path / ".m.npz.0badf00d.tmp"  # as a writer killed with SIGKILL leaves it: no lock held
    dead.write_bytes(b"half")
    held = tmp_path / ".m.npz.5afe5afe.tmp"
    held.write_bytes(b"being written")
    fd = os.open(held, os.O_RDONLY)
    try:
        fcntl.flock(fd, fcntl.LOCK_EX)  # a live writer's lock (another open file, as another process)
        atomic.atomic_write_bytes(str(out), b"new")
        assert out.read_bytes() == b"new"
        assert temps(tmp_path, "m.npz") == [held.name]
    finally:
        os.close(fd)
    atomic.atomic_write_bytes(str(out), b"newer")  # its writer is gone now
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz"]


def test_a_temporary_file_taken_for_a_leftover_before_it_is_locked_is_made_again(tmp_path, monkeypatch):
    """Another writer finds our new file in the instant between its creation and our flock and
    removes it: we notice, write under a new name, and the output is complete."""
    out = tmp_path / "out.bin"
    removed = []

    def flock(fd, op):
        if op == fcntl.LOCK_EX and not removed:  # our blocking lock, not a probe
            removed.extend(atomic.remove_stale_temps(str(out)))
        return fcntl.flock(fd, op)

    monkeypatch.setattr(atomic, "fcntl", types.SimpleNamespace(
        flock=flock, LOCK_EX=fcntl.LOCK_EX, LOCK_NB=fcntl.LOCK_NB))
    atomic.atomic_write_bytes(str(out), b"x" * 1000)
    assert len(removed) == 1
    assert out.read_bytes() == b"x" * 1000
    assert sorted(p.name for p in tmp_path.iterdir()) == ["out.bin"]


def proc_umask() -> int | None:
    """The umask as /proc reports it (Linux), read without setting it."""
    try:
        with open("/proc/self/status") as fh:
            for line in fh:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except OSError:
        pass
    return None


@pytest.fixture
def umask_027():
    old = os.umask(0o027)
    yield 0o027
    os.umask(old)


def test_writes_never_change_the_umask(tmp_path, monkeypatch, umask_027):
    """A thread watches the umask while another writes; nothing sets it, and outputs get
    0o666 minus the umask."""
    def no_umask(mask):
        raise AssertionError("os.umask called: it sets the umask of every thread")

    monkeypatch.setattr(os, "umask", no_umask)
    seen, stop = set(), threading.Event()

    def watch():
        while not stop.is_set():
            seen.add(proc_umask())
            time.sleep(0)

    watcher = threading.Thread(target=watch)
    watcher.start()
    failed = []

    def write():
        try:
            for i in range(200):
                atomic.atomic_write_bytes(str(tmp_path / f"out{i % 3}.bin"), b"x" * i)
        except BaseException as exc:  # noqa: BLE001 - reported below
            failed.append(exc)

    writer = threading.Thread(target=write)
    writer.start()
    writer.join()
    stop.set()
    watcher.join()
    monkeypatch.undo()
    assert failed == []
    assert seen <= {umask_027, None} and seen
    for i in range(3):
        assert (tmp_path / f"out{i}.bin").stat().st_mode & 0o777 == 0o666 & ~umask_027


def test_a_failed_write_leaves_the_previous_file_and_no_temporary_file(tmp_path):
    out = tmp_path / "m.npz"
    out.write_bytes(b"previous")
    with pytest.raises(ValueError):
        with atomic.atomic_open(str(out)) as fh:
            fh.write(b"half")
            raise ValueError("the writer failed")
    assert out.read_bytes() == b"previous"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["m.npz"]
    with pytest.raises(OutputError, match="does not exist"):
        atomic.atomic_write_bytes(str(tmp_path / "nope" / "m.npz"), b"")


def test_a_fifo_is_written_as_it_is_not_replaced(tmp_path):
    """A FIFO or a device (/dev/null) named as the output stays what it is."""
    fifo = tmp_path / "fifo"
    os.mkfifo(fifo)
    got = []
    reader = threading.Thread(target=lambda: got.append(open(fifo, "rb").read()))
    reader.start()
    atomic.atomic_write_bytes(str(fifo), b"x" * 100_000)
    reader.join(timeout=30)
    assert got == [b"x" * 100_000]
    assert stat.S_ISFIFO(os.stat(fifo).st_mode) and sorted(p.name for p in tmp_path.iterdir()) == ["fifo"]


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="no /dev/full on this system")
def test_a_full_device_is_an_output_error():
    with pytest.raises(OutputError, match="cannot write /dev/full: No space left on device"):
        atomic.atomic_write_bytes("/dev/full", b"x" * 100_000)
    assert stat.S_ISCHR(os.stat("/dev/full").st_mode)


def test_an_output_that_is_a_symbolic_link_stays_one(tmp_path):
    """-o onto a link writes the file it points to (atomically, beside it); the link is kept."""
    data = tmp_path / "data"
    data.mkdir()
    target = data / "model.npz"
    target.write_bytes(b"before")
    link = tmp_path / "current.npz"
    link.symlink_to(target)
    atomic.atomic_write_bytes(str(link), b"after")
    assert link.is_symlink() and os.readlink(link) == str(target)
    assert target.read_bytes() == b"after"
    assert sorted(p.name for p in data.iterdir()) == ["model.npz"]
    dangling = tmp_path / "next.npz"
    dangling.symlink_to(data / "new.npz")
    atomic.atomic_write_bytes(str(dangling), b"new")
    assert dangling.is_symlink() and (data / "new.npz").read_bytes() == b"new"
    (tmp_path / "gone").symlink_to(tmp_path / "nope" / "x.npz")
    with pytest.raises(OutputError, match="cannot write .*gone: folder .*nope does not exist"):
        atomic.atomic_write_bytes(str(tmp_path / "gone"), b"")
