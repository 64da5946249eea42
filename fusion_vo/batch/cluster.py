"""The Dask cluster a batch runs on: a LocalCluster by default, or a running scheduler by address."""

from __future__ import annotations

import contextlib
import logging
import os
import signal
import threading
from typing import Callable, Iterator

from fusion_vo.errors import InputError

log = logging.getLogger(__name__)

#: seconds to wait for a scheduler given by address before giving up
CONNECT_TIMEOUT_S = 5.0

EXTRA_HINT = "install the batch extra: pip install 'fusion-vo[batch]'"


def require_dask() -> None:
    """Raise :class:`InputError` (one line) when Dask distributed or pandas is not installed."""
    try:
        import distributed  # noqa: F401
        import pandas  # noqa: F401
    except ImportError as exc:
        raise InputError(f"batches and sweeps need {exc.name}; {EXTRA_HINT}") from None


@contextlib.contextmanager
def _workers_ignore_ctrl_c() -> Iterator[None]:
    """Start worker processes with SIGINT ignored (kept across their start-up), so that Ctrl-C on a
    terminal, which reaches the whole process group, stops the command, and the command stops them."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


def _quiet_worker_log() -> None:
    """In a worker process: its ``distributed.worker`` log only at CRITICAL. A worker whose heartbeat meets the
    scheduler as the cluster shuts down logs the closed stream as an ERROR with a traceback, on the command's
    standard error; a task's own error reaches the batch through its future. Set once, on the workers the cluster
    starts with (one its nanny restarts logs as Dask does)."""
    logging.getLogger("distributed.worker").setLevel(logging.CRITICAL)


#: Dask's own default for its worker processes' ``MALLOC_TRIM_THRESHOLD_`` (``distributed.nanny.pre-spawn-environ``)
DASK_MALLOC_TRIM = "65536"


@contextlib.contextmanager
def _worker_environment() -> Iterator[None]:
    """Start worker processes with glibc's own memory thresholds, and leave the caller's environment as it was.

    Dask's nanny sets ``MALLOC_TRIM_THRESHOLD_=65536`` for its workers, which turns off glibc's dynamic mmap
    threshold: every image-sized array is then mapped and unmapped again and its pages faulted in anew
    (docs/decisions/0040). Unless the environment or the Dask configuration sets another value, the workers run
    without it. The nanny also writes its worker variables (single-threaded BLAS, a fixed ``PYTHONHASHSEED``)
    into the calling process's ``os.environ``, where every subprocess the caller starts later would inherit
    them; the environment is put back once the workers have started. (A worker the nanny restarts later writes
    them again.)
    """
    import dask

    key = "distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_"
    dasks_default = (str(dask.config.get(key, default=None)) == DASK_MALLOC_TRIM
                     and "MALLOC_TRIM_THRESHOLD_" not in os.environ)
    before = dict(os.environ)
    try:
        with dask.config.set({key: None} if dasks_default else {}):
            yield
    finally:
        for name in set(os.environ) - set(before):
            del os.environ[name]
        os.environ.update(before)


@contextlib.contextmanager
def open_client(workers: int | None = None, scheduler: str | None = None, dashboard: bool = True,
                announce: Callable[[str], None] | None = None) -> Iterator:
    """A ``distributed.Client``: connected to ``scheduler``, or to a new LocalCluster of ``workers``.

    The LocalCluster has one single-threaded worker process per core (or ``workers``), so that each
    task has a core of its own; it is closed on exit. Its workers keep glibc's memory thresholds and the
    caller's environment is left unchanged (:func:`_worker_environment`).

    Parameters
    ----------
    workers : int, optional
        Worker processes of the LocalCluster (default: the number of cores).
    scheduler : str, optional
        Address of a running scheduler (``tcp://host:8786``); excludes ``workers``.
    dashboard : bool
        Serve the Dask dashboard of the LocalCluster (needs bokeh).
    announce : callable, optional
        Receives one line with the dashboard address when a LocalCluster starts.

    Raises
    ------
    InputError
        When the scheduler cannot be reached within :data:`CONNECT_TIMEOUT_S`.
    """
    require_dask()
    from distributed import Client, LocalCluster

    if scheduler and workers:
        raise InputError("give either --workers (a local cluster) or --scheduler (a running one), not both")
    if scheduler:
        try:
            client = Client(scheduler, timeout=CONNECT_TIMEOUT_S)
        except Exception as exc:  # noqa: BLE001 - refused, timed out, malformed, or not a Dask scheduler
            reason = " ".join(str(exc).split())[:200] or type(exc).__name__
            raise InputError(f"cannot reach the Dask scheduler at {scheduler} (waited at most "
                             f"{CONNECT_TIMEOUT_S:.0f} s): {reason}") from None
        try:
            yield client
        finally:
            client.close()
        return
    n = workers or os.cpu_count() or 1
    if n < 1:
        raise InputError(f"--workers must be at least 1, not {n}")
    address = ":0" if dashboard else None
    with contextlib.ExitStack() as stack:
        if dashboard:
            try:
                import bokeh  # noqa: F401
            except ImportError:
                address = None
        with _workers_ignore_ctrl_c(), _worker_environment():
            cluster = stack.enter_context(LocalCluster(n_workers=n, threads_per_worker=1, processes=True,
                                                       dashboard_address=address, silence_logs=logging.ERROR))
        client = stack.enter_context(Client(cluster))
        client.run(_quiet_worker_log)
        if announce:
            link = client.dashboard_link if address else "off (the dashboard needs bokeh)"
            announce(f"Dask LocalCluster: {n} workers, dashboard {link}")
        yield client
