"""Where a study's scenarios run: local Dask clusters of worker processes and their
environment (thread counts, quiet logs, Ctrl-C left to the command). Used by
:mod:`brainbulge.studies.runner`, which re-exports these names."""

from __future__ import annotations

import contextlib
import logging
import os
from collections.abc import Iterator, Mapping

from brainbulge.errors import InputError

logger = logging.getLogger(__name__)

#: The thread-count variables of a worker process: BLAS/OpenMP/MKL (pypardiso), NGSolve's
#: ``TaskManager`` and Numba (closed-form tangent).
THREAD_VARIABLES = ("OMP_NUM_THREADS", "MKL_NUM_THREADS", "OPENBLAS_NUM_THREADS",
                    "NGS_NUM_THREADS", "NUMBA_NUM_THREADS")


def worker_env(n_workers: int, cores: int | None = None) -> dict[str, str]:
    """The thread counts of ``n_workers`` worker processes sharing ``cores`` cores (default:
    those this process may use): ``cores // n_workers`` threads each, at least one, so that
    the workers neither oversubscribe the cores nor leave them idle (one worker of a
    paper-sized 3D scenario uses every core)."""
    if cores is None:
        cores = len(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else (
            os.cpu_count() or 1)
    threads = str(max(1, cores // max(1, n_workers)))
    return dict.fromkeys(THREAD_VARIABLES, threads)


@contextlib.contextmanager
def _worker_environ(env: Mapping[str, str]) -> Iterator[None]:
    """Set ``env`` in ``os.environ`` while worker processes are spawned, then restore it.

    `distributed.Nanny` reads ``OMP_NUM_THREADS`` & co. from ``os.environ`` before spawning
    (they must be set before numpy loads BLAS); an inherited ``OMP_NUM_THREADS=8`` would win.
    """
    saved = {key: os.environ.get(key) for key in env}
    os.environ.update(env)
    try:
        yield
    finally:
        for key, old in saved.items():
            if old is None:
                os.environ.pop(key, None)
            else:
                os.environ[key] = old


#: the environment of local workers beyond thread counts: only their errors reach the terminal
WORKER_QUIET = {"DASK_LOGGING__DISTRIBUTED": "error"}


@contextlib.contextmanager
def _sigint_ignored() -> Iterator[None]:
    """SIGINT ignored while worker processes start: they inherit it, so a Ctrl-C in the
    terminal (sent to every process of the job) stops only this process, which ends them
    without their tracebacks."""
    import signal
    import threading

    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, previous)


@contextlib.contextmanager
def local_cluster(n_workers: int | None = None) -> Iterator[str]:
    """A `distributed.LocalCluster` of ``n_workers`` (default 2) worker processes, one
    scenario at a time each, with the thread counts of :func:`worker_env`; closed on exit;
    yields its scheduler address.

    `run_study` starts one per study when ``scheduler`` is None; a command that runs several
    studies in a row passes this address to each of them instead, so that the workers start
    (and import brainbulge and NGSolve) once. Its HTTP server takes a free port, so a second
    cluster on the machine does not clash with the first."""
    import importlib.util

    from distributed import LocalCluster

    if n_workers is not None and n_workers < 1:
        raise InputError(f"n_workers must be at least 1, not {n_workers}")
    n_workers = n_workers or 2
    env = worker_env(n_workers)
    # SIGINT ignored by the workers: a Ctrl-C stops this process, which ends them
    with _worker_environ({**env, **WORKER_QUIET}), _sigint_ignored():
        cluster = LocalCluster(n_workers=n_workers, threads_per_worker=1, processes=True,
                               dashboard_address=":0", env=env)
    distributed_log = logging.getLogger("distributed")
    level = distributed_log.level
    try:
        with cluster:
            if importlib.util.find_spec("bokeh"):
                logger.info("Dask dashboard: %s", cluster.dashboard_link)
            try:
                yield cluster.scheduler_address
            except BaseException:  # interrupted: the workers' shutdown is no news
                distributed_log.setLevel(logging.CRITICAL)
                raise
    finally:
        distributed_log.setLevel(level)


@contextlib.contextmanager
def shared_scheduler(scheduler: str | None, n_workers: int | None = None
                     ) -> Iterator[str | None]:
    """``scheduler`` for several studies in a row: a :func:`local_cluster` of ``n_workers``
    started once when it is None, otherwise ``scheduler`` itself (``"serial"`` or an
    address)."""
    if scheduler is not None:
        yield scheduler
        return
    with local_cluster(n_workers) as address:
        yield address
