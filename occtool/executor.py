"""Where a model set's positions are computed: this process, local processes, or a Dask cluster.

One small interface, :class:`Executor`, with one method: :meth:`Executor.run_unordered`
takes a (lazy) iterable of ``(key, function, args)`` tasks and yields ``(key, outcome)``
as tasks finish, where ``outcome`` is the function's result or the exception it raised.
At most ``window`` tasks are in flight, so a generator of tasks that reads logs as it
goes keeps memory bounded however many logs there are.

- ``jobs=1``: in this process, one task after another (no pickling, no start-up).
- ``jobs=N``: :class:`concurrent.futures.ProcessPoolExecutor` with N spawned processes.
- ``scheduler="tcp://host:8786"`` (or a ``distributed.Client``): an existing
  ``dask.distributed`` cluster (the ``dask`` extra); every worker must have occtool
  installed.

A Dask cluster that runs occtool's tasks is best started with :data:`DASK_CLUSTER_CONFIG`
(see its comment): Dask's own monitoring otherwise costs about a fifth more CPU than the
fits themselves on a small machine.

The functions must be module-level (picklable). Local processes are spawned: a script
that calls the model-set functions with ``jobs > 1`` needs the usual
``if __name__ == "__main__":`` guard, as for any ``multiprocessing`` program. The results do not depend on the
executor: each task is a pure function of its arguments.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass
from typing import Any, TypeVar

from occtool._files import signals_held

Task = tuple[Any, Callable[..., Any], tuple[Any, ...]]

#: A task of fits holds consecutive positions up to this many features (or
#: :data:`CHUNK_POSITIONS` positions): small positions travel together, so a cluster's cost
#: per task (about that of one 0.1 s fit) is shared (model sets' fits and a map's keyframes).
CHUNK_FEATURES = 20_000
CHUNK_POSITIONS = 16

T = TypeVar("T")


def tasks_of_fits(items: Iterable[T], features: Callable[[T], int]) -> Iterator[list[T]]:
    """Consecutive ``items`` (positions, or what stands for them) grouped into tasks of fits,
    lazily: a task holds at most :data:`CHUNK_POSITIONS` of them and :data:`CHUNK_FEATURES`
    features (``features(item)`` each), unless one item alone holds more: a large position
    travels alone. Model sets' fits and a map's keyframes are grouped by this one rule.

    >>> [len(task) for task in tasks_of_fits([5_000] * 5 + [30_000, 10], lambda n: n)]
    [4, 1, 1, 1]
    """
    task: list[T] = []
    size = 0
    for item in items:
        count = features(item)
        if task and size + count > CHUNK_FEATURES:
            yield task
            task, size = [], 0
        task.append(item)
        size += count
        if len(task) >= CHUNK_POSITIONS:
            yield task
            task, size = [], 0
    if task:
        yield task


@dataclass(frozen=True)
class Failed:
    """One item of a task that failed for its data, by its reason: the exception itself may
    not survive pickling back from a worker."""

    reason: str


def default_jobs() -> int:
    """The cores this process may use (its CPU affinity mask, else ``os.cpu_count()``)."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # not on Linux
        return max(1, os.cpu_count() or 1)


def check_jobs(jobs: Any) -> int:
    """``jobs`` as a whole number >= 1 (``None``: :func:`default_jobs`)."""
    if jobs is None:
        return default_jobs()
    if isinstance(jobs, bool) or not isinstance(jobs, int) or jobs < 1:
        from occtool.errors import InputError

        raise InputError(f"jobs must be a whole number >= 1, got {jobs!r}")
    return jobs


class Executor:
    """Runs tasks and yields their outcomes as they finish (see the module's docstring)."""

    #: Where the tasks run, for messages and run records.
    description = "this process"

    def run_unordered(self, tasks: Iterable[Task]) -> Iterator[tuple[Any, Any]]:
        for key, function, args in tasks:
            try:
                outcome = function(*args)
            except Exception as exc:  # noqa: BLE001 - reported per task, the others go on
                outcome = exc
            yield key, outcome

    def close(self, *, cancel: bool = False) -> None:
        """Release the workers; ``cancel`` drops tasks not yet finished (after an interrupt)."""

    def __enter__(self) -> Executor:  # noqa: PYI034 - subclasses return themselves too
        return self

    def __exit__(self, exc_type: type[BaseException] | None, *rest: object) -> None:
        self.close(cancel=exc_type is not None)


def _ignore_interrupts() -> None:
    # Ctrl-C reaches the whole process group: the parent stops the run and writes what is
    # done; the workers must not print tracebacks of their own.
    import signal

    signal.signal(signal.SIGINT, signal.SIG_IGN)


#: Longest a Ctrl-C or SIGTERM waits (seconds) while the parent waits for a worker's result.
SIGNAL_SLICE = 0.25


class ProcessExecutor(Executor):
    """``jobs`` local processes (spawned, so no thread or lock of the parent is inherited)."""

    def __init__(self, jobs: int, *, window: int | None = None) -> None:
        import multiprocessing
        from concurrent.futures import ProcessPoolExecutor

        self.jobs = jobs
        self.window = window or 4 * jobs
        self.description = f"{jobs} local processes"
        self.pool = ProcessPoolExecutor(max_workers=jobs, mp_context=multiprocessing.get_context("spawn"),
                                        initializer=_ignore_interrupts)

    def run_unordered(self, tasks: Iterable[Task]) -> Iterator[tuple[Any, Any]]:
        from concurrent.futures import FIRST_COMPLETED, wait
        from concurrent.futures.process import BrokenProcessPool

        pending: dict[Any, Any] = {}
        source = iter(tasks)
        exhausted = False
        while True:
            while not exhausted and len(pending) < self.window:
                try:
                    key, function, args = next(source)
                except StopIteration:
                    exhausted = True
                    break
                # Ctrl-C or SIGTERM raised inside the pool's own locks (submit's, wait's
                # futures') would leave them held, and the clean-up that needs them hangs:
                # held back, they arrive between these calls (SIGTERM mid-run: a fit -j 2
                # that never exited).
                with signals_held():
                    pending[self.pool.submit(function, *args)] = key
            if not pending:
                return
            done: set[Any] = set()
            while not done:  # in slices, so that a held signal waits a slice at most
                with signals_held():
                    done, _ = wait(pending, timeout=SIGNAL_SLICE, return_when=FIRST_COMPLETED)
            for future in done:
                key = pending.pop(future)
                with signals_held():
                    exc = future.exception()
                    if isinstance(exc, BrokenProcessPool):
                        exc = RuntimeError("a worker process died (out of memory, or killed)")
                    outcome = future.result() if exc is None else exc
                yield key, outcome

    def close(self, *, cancel: bool = False) -> None:
        if cancel:
            # Running tasks would finish for nothing: the parent writes the results.
            for process in list(getattr(self.pool, "_processes", {}).values()):
                process.terminate()
        self.pool.shutdown(wait=True, cancel_futures=cancel)


#: Dask settings for the scheduler and workers of a cluster that runs occtool's fits, for
#: ``dask.config.set`` before starting a ``LocalCluster``, or a Dask YAML file / the
#: ``DASK_DISTRIBUTED__...`` variables of ``dask scheduler`` and ``dask worker``. occtool's
#: tasks are CPU-bound numpy of 0.1-1 s; Dask's defaults sample every worker thread's
#: stack every 10 ms (the profiler, for the dashboard), check each event loop every 20 ms
#: and poll memory and system figures every 0.1-0.5 s. On two cores those cost about a
#: quarter more CPU than a local process pool spends on the same fits (measured: a
#: two-worker LocalCluster, idle for 30 s, 4.7 s of CPU with the defaults, 0.6 s with
#: these). Models do not depend on them. The memory limits still apply, checked every 2 s.
DASK_CLUSTER_CONFIG: dict[str, Any] = {
    "distributed.worker.profile.enabled": False,
    "distributed.admin.tick.interval": "1s",
    "distributed.admin.system-monitor.interval": "5s",
    "distributed.worker.memory.monitor-interval": "2s",
}


class DaskExecutor(Executor):
    """Tasks on an existing ``dask.distributed`` cluster, results streamed back as they finish."""

    def __init__(self, scheduler: Any, *, window: int | None = None) -> None:
        try:
            from distributed import Client
        except ImportError:
            from occtool.errors import MissingDependencyError

            raise MissingDependencyError("dask[distributed]", "dask", "running on a Dask cluster") from None
        if isinstance(scheduler, Client):
            self.client, self.own_client = scheduler, False
        else:
            try:
                self.client = Client(scheduler, timeout="10s")
            except (OSError, TimeoutError, ValueError) as exc:
                from occtool.errors import InputError

                raise InputError(f"cannot connect to the Dask scheduler at {scheduler}: {exc}") from None
            self.own_client = True
        workers = max(1, sum(self.client.nthreads().values()))
        self.window = window or 4 * workers
        self.description = f"Dask cluster {self.client.scheduler.address} ({workers} worker threads)"

    def run_unordered(self, tasks: Iterable[Task]) -> Iterator[tuple[Any, Any]]:
        from distributed import as_completed

        source = iter(tasks)
        pending: dict[Any, Any] = {}
        finished = as_completed()

        def submit_more() -> None:
            while len(pending) < self.window:
                try:
                    key, function, args = next(source)
                except StopIteration:
                    return
                future = self.client.submit(function, *args, pure=False)
                pending[future] = key
                finished.add(future)

        submit_more()
        while pending:
            future = next(finished)
            key = pending.pop(future)
            if future.status == "error":
                outcome = future.exception()
            else:
                outcome = future.result()
            future.release()
            yield key, outcome
            submit_more()

    def close(self, *, cancel: bool = False) -> None:
        if self.own_client:
            self.client.close()


def in_order(executor: Executor | None, doing: str, function: Callable[..., Any],
             arguments: Iterable[tuple[Any, ...]]) -> Iterator[Any]:
    """``function(*args)`` for each of ``arguments`` on ``executor`` (``None``: this
    process), yielded in the order of ``arguments`` whatever order they finish in (those
    that finish early are held until their turn): work split into tasks gives the same
    result as done here. A task's exception is raised as it was in this process, and as one
    :class:`~occtool.errors.InputError` saying what was ``doing`` and where otherwise (a
    worker that died, a cluster that failed)."""
    where = executor if executor is not None else Executor()
    held: dict[int, Any] = {}
    following = 0
    for n, outcome in where.run_unordered((n, function, args) for n, args in enumerate(arguments)):
        if isinstance(outcome, BaseException):
            if type(where) is Executor:
                raise outcome  # as if called here: it was
            from occtool.errors import InputError

            raise InputError(f"{doing} on {where.description}: {type(outcome).__name__}: {outcome}")
        held[n] = outcome
        while following in held:
            yield held.pop(following)
            following += 1


def make_executor(jobs: int | None = None, scheduler: Any = None) -> Executor:
    """The executor for ``jobs`` local processes, or for the Dask cluster at ``scheduler``."""
    if scheduler is not None:
        return DaskExecutor(scheduler)
    jobs = check_jobs(jobs)
    return Executor() if jobs == 1 else ProcessExecutor(jobs)


__all__ = ["CHUNK_FEATURES", "CHUNK_POSITIONS", "DASK_CLUSTER_CONFIG", "DaskExecutor", "Executor", "Failed",
           "ProcessExecutor", "check_jobs", "default_jobs", "in_order", "make_executor", "tasks_of_fits"]
