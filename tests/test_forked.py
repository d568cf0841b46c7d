"""A computation in a forked child process beside this one (fricli.numerics.forked)."""

import fcntl
import os
import time

import numpy as np
import pytest

from fricli.core.errors import FitError
from fricli.numerics import forked

pytestmark = pytest.mark.skipif(not forked.AVAILABLE, reason="fricli forks on Linux only")


def test_the_child_result_and_this_process_result_come_back_together():
    (params, arrays), here = forked.beside(lambda: ({"pid": os.getpid(), "x": [1.5]}, {"a": np.arange(5.0)}),
                                           lambda: os.getpid())
    assert here == os.getpid() and params["pid"] != os.getpid() and params["x"] == [1.5]
    np.testing.assert_array_equal(arrays["a"], np.arange(5.0))


def test_a_fricli_error_in_the_child_keeps_its_class_and_others_say_so():
    def diverges():
        raise FitError("training diverged at step 7")

    with pytest.raises(FitError, match="diverged at step 7"):
        forked.beside(diverges, lambda: None)
    with pytest.raises(RuntimeError, match="ZeroDivisionError"):
        forked.beside(lambda: 1 / 0, lambda: None)


def test_an_error_here_ends_the_child_at_once():
    started = time.monotonic()

    def here():
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        forked.beside(lambda: time.sleep(60), here)
    assert time.monotonic() - started < 30   # the child was killed, not waited for


def test_the_child_holds_none_of_this_process_files(tmp_path):
    """A lock this process holds (a model being written) is not kept alive by the child."""
    with open(tmp_path / ".model.npz.lock", "w") as lock:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)

        def inherited():
            try:
                os.fstat(lock.fileno())
            except OSError:
                return {"open": False}, {}
            return {"open": True}, {}

        (params, _), _ = forked.beside(inherited, lambda: None)
    assert params == {"open": False}


def test_orphaned_is_set_only_once_the_parent_is_another():
    assert not forked.Orphaned(os.getppid()).is_set()
    assert forked.Orphaned(os.getpid()).is_set()
