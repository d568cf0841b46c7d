"""Set-up of a fleet worker process (a Dask preload, ``fricli.fleet.run.client``).

Ctrl-C in the terminal reaches every process of its group, the local cluster's workers among
them. The command itself handles it (``fricli: interrupted``, exit 130) and closes the cluster;
a worker that took it too would print the traceback of the task it was in. The workers log
errors only, as the client does: their shutdown warnings are not ours to show.
"""

from __future__ import annotations

import logging
import signal


def dask_setup(worker) -> None:  # noqa: ARG001 (Dask's preload hook)
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed").setLevel(logging.ERROR)
