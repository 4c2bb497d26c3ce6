"""Process pools that behave on Ctrl-C, how many processes this machine gives us, and linear
algebra kept to one thread inside them.

A terminal's Ctrl-C sends SIGINT to every process of the foreground group: the workers of a
pool too.  Left alone, each worker prints its own KeyboardInterrupt traceback and the pool
then reports itself broken.  :func:`process_pool` starts its workers with SIGINT ignored (the
signal is blocked while they are forked, so none can receive it before it ignores it), and when
the body of the ``with`` block is left by an exception (the main process's KeyboardInterrupt,
or any error) it cancels what is queued and stops the workers instead of waiting for them, so
the main process alone reports, once.
"""

from __future__ import annotations

import contextlib
import multiprocessing
import os
import signal
import sys
from collections.abc import Callable, Iterator
from concurrent.futures import Executor, ProcessPoolExecutor
from typing import Any

from wholearm_tools import _interrupt

#: seconds to wait for a terminated worker before killing it
_STOP_TIMEOUT = 2.0


def available_cores() -> int:
    """CPU cores this process may run on (its affinity mask where the platform has one)."""
    try:
        return len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        return os.cpu_count() or 1


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Linear algebra (the BLAS library numpy and scipy call) on one thread within the block.

    The toolkit's parallelism is its own: a pool of processes (:func:`worker_pool`), or one
    reconstruction per worker of a Dask cluster.  BLAS threads on top of it compete for the
    same cores, and on the small and middling products of a reconstruction they spend more CPU
    busy-waiting than they save in time, even with one worker.  Processes forked inside the block
    inherit the setting."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1, user_api="blas"):
        yield


def _worker_init(initializer: Callable[..., Any] | None, initargs: tuple[Any, ...]) -> None:
    """First thing a worker does: ignore SIGINT (the main process handles Ctrl-C), then let
    the signal through again (it was blocked while the worker was forked)."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    if hasattr(signal, "pthread_sigmask"):
        signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})
    if initializer is not None:
        initializer(*initargs)


def _noop() -> None:
    return None


@contextlib.contextmanager
def _sigint_blocked() -> Iterator[None]:
    """SIGINT held back in this thread (and in processes forked meanwhile) within the block; a
    Ctrl-C pressed meanwhile is delivered when the block ends."""
    if not hasattr(signal, "pthread_sigmask"):
        yield
        return
    old = signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, old)


def _stop(pool: ProcessPoolExecutor) -> None:
    """Cancel queued work and stop the workers now (running tasks are abandoned)."""
    # ProcessPoolExecutor has no public way to stop running workers before Python 3.14; its
    # process table is dropped by shutdown, so it is read first
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for proc in processes:
        with contextlib.suppress(Exception):
            proc.terminate()
    for proc in processes:
        with contextlib.suppress(Exception):
            proc.join(_STOP_TIMEOUT)
            if proc.is_alive():
                proc.kill()
                proc.join(_STOP_TIMEOUT)


@contextlib.contextmanager
def process_pool(max_workers: int, *, mp_context: Any = None,
                 initializer: Callable[..., Any] | None = None,
                 initargs: tuple[Any, ...] = ()) -> Iterator[ProcessPoolExecutor]:
    """A :class:`~concurrent.futures.ProcessPoolExecutor` whose workers ignore SIGINT.

    On a normal exit the pool is shut down after its work is done; when the block raises
    (KeyboardInterrupt included), queued work is cancelled and the workers are stopped at
    once, and the exception propagates.
    """
    pool = ProcessPoolExecutor(max_workers=max_workers, mp_context=mp_context,
                               initializer=_worker_init, initargs=(initializer, initargs))
    try:
        with _sigint_blocked():
            pool.submit(_noop)  # starts the workers (a forking pool starts all of them here)
    except BaseException:
        _stop(pool)
        raise
    try:
        yield pool
    except BaseException:
        _stop(pool)
        raise
    pool.shutdown(wait=True)


@contextlib.contextmanager
def worker_pool(workers: int | None = None) -> Iterator[Executor | None]:
    """A pool for independent fits, shut down on exit; ``None`` (work in this process) for one
    worker or inside a daemonic process (a Dask or multiprocessing worker, which may not start
    children).

    ``workers`` None: every core this process may use, at most 8, or one in a process that is
    itself a worker of a pool (``wholearm compare`` runs one reconstruction per core already).
    Workers are forked where the platform can (they start in milliseconds, with the CasADi
    solvers already built), else spawned."""
    from wholearm_tools.errors import InputError

    if workers is None:
        nested = multiprocessing.parent_process() is not None
        n = 1 if nested else min(available_cores(), 8)
    else:
        n = int(workers)
    if n < 1:
        raise InputError(f"workers must be at least 1, got {workers!r}")
    if n == 1 or multiprocessing.current_process().daemon:
        yield None
        return
    methods = multiprocessing.get_all_start_methods()
    ctx = multiprocessing.get_context("fork" if "fork" in methods else None)
    with process_pool(n, mp_context=ctx) as pool:
        yield pool


def interruptible_import(name: str) -> Any:
    """Import module ``name`` so that a Ctrl-C during the import interrupts the command.

    Some libraries guard their optional imports with ``except BaseException`` (trimesh, and
    yourdfpy through it), which swallows the KeyboardInterrupt raised inside them: the command
    would then carry on as if nothing had been pressed.  The interrupt is held while the module
    is imported and raised after it."""
    import importlib
    import threading

    if name in sys.modules or threading.current_thread() is not threading.main_thread():
        return importlib.import_module(name)
    pressed: list[int] = []
    previous = signal.signal(signal.SIGINT, lambda signum, frame: pressed.append(signum))
    try:
        module = importlib.import_module(name)
    finally:
        signal.signal(signal.SIGINT, previous)
    if pressed:
        _interrupt.remember()
        raise KeyboardInterrupt
    return module
