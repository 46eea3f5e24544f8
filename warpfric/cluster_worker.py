"""The worker processes of a local Dask cluster that a sweep starts (``warpfric run --local-cluster``,
warpfric.runner.local_cluster); imported only there, where distributed is installed.

Such workers belong to the command: it stops them in order when it ends or is interrupted
(warpfric.runner.close_local_cluster). A Ctrl-C in a terminal, or a batch system's SIGTERM, reaches
every process of the job, the workers too: each worker then died on its own, with a traceback of
its event loop (about 30 lines a worker) or a nanny restarting it, before the command's one line.
"""

from __future__ import annotations

import logging
import signal
import threading

from distributed import WorkerPlugin
from distributed.core import Status

CLOSING = (Status.closing, Status.closing_gracefully, Status.closed)


# warpfric's own faults, each told by the command in one line naming the chunk (runner.run_on_client):
# the worker's "Compute Failed" record of such a task (six lines and a traceback) repeats it
OWN_FAULTS = ("RunError(", "OutputWriteError(")


def own_fault(record: logging.LogRecord) -> bool:
    """True for distributed's "Compute Failed" record of a task that raised one of warpfric's own
    faults (OWN_FAULTS); any other exception keeps its record, whose traceback tells where it came from."""
    if record.name != "distributed.worker" or not str(record.msg).startswith("Compute Failed"):
        return False
    args = record.args if isinstance(record.args, tuple) else ()
    return len(args) >= 4 and str(args[3]).lstrip("'\"").startswith(OWN_FAULTS)


class LocalClusterWorker(WorkerPlugin):
    """In each worker process of the command's local cluster: SIGINT and SIGTERM ignored (the command
    gets them too, and stops its workers through their nannies: a stop message, then SIGKILL after
    distributed's close timeout), and distributed's log lines dropped once the worker is closing.
    The command closes its workers only at its end; a worker closing with a chunk still running
    logs one warning per cancelled task ("Async instruction ... ended with CancelledError") about a
    shutdown that was asked for. While the worker runs, its log lines (memory warnings, a task's
    error) are shown as before, but for the failures of warpfric's own faults (own_fault), which
    the command reports in one line each."""

    idempotent = True  # one per worker, restarted workers included

    def setup(self, worker) -> None:
        if threading.current_thread() is threading.main_thread():  # a nanny's worker process: always
            signal.signal(signal.SIGINT, signal.SIG_IGN)
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
        for handler in logging.getLogger("distributed").handlers:
            handler.addFilter(lambda record: worker.status not in CLOSING and not own_fault(record))
