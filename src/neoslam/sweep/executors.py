"""Where a sweep's tasks run: a local process pool (default, one worker per core), this process (debugging), or
Ray tasks on an existing Ray cluster (`pip install "neoslam[cluster]"`). Each calls `done(outcomes)` in the sweep's
process as tasks finish, in whatever order they finish; the sweep stores them, so the order does not matter."""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import suppress
from typing import Any

from neoslam.errors import ConfigError
from neoslam.sweep.runner import THREAD_VARIABLES, Outcome, Task, one_line, run_task, worker_init

__all__ = ["Executor", "LocalPool", "InProcess", "RayCluster", "make_executor"]

Done = Callable[[list[Outcome]], None]
RAY_MISSING = 'the --ray option needs Ray: pip install "neoslam[cluster]" (or pip install "ray>=2.9")'


def _lost(task: Task, error: BaseException) -> list[Outcome]:
    """Every cell of a task whose worker died (killed, out of memory): failed, with what was reported."""
    message = f"worker lost: {one_line(error)}"
    return [Outcome(cell.id, None, message, message) for cell in task.cells]


class Executor:
    name = "executor"
    workers = 1
    remote = False  # workers may run other code: each task checks the code version

    def run(self, tasks: list[Task], done: Done) -> None:
        raise NotImplementedError


class InProcess(Executor):
    """Cells one after another in this process (`--workers 0`: a debugger sees them)."""

    name = "in-process"

    def run(self, tasks: list[Task], done: Done) -> None:
        if not tasks:
            return
        import torch

        threads, variables = torch.get_num_threads(), {k: os.environ.get(k) for k in THREAD_VARIABLES}
        try:
            for task in tasks:
                done(run_task(task))
        finally:  # the cells ran single-threaded; this process goes on as it was
            torch.set_num_threads(threads)
            for key, value in variables.items():
                if value is None:
                    os.environ.pop(key, None)
                else:
                    os.environ[key] = value


class LocalPool(Executor):
    """A pool of worker processes on this machine (spawned: no state of this process leaks into them). Workers
    ignore Ctrl-C; when this process is interrupted it cancels what has not started and ends the workers, and when
    it is killed outright they end by themselves (`worker_init`)."""

    name = "pool"

    def __init__(self, workers: int | None = None) -> None:
        self.workers = workers or os.cpu_count() or 1

    def run(self, tasks: list[Task], done: Done) -> None:
        if not tasks:
            return
        pool = ProcessPoolExecutor(
            max_workers=min(self.workers, len(tasks)),
            mp_context=multiprocessing.get_context("spawn"),
            initializer=worker_init,
            initargs=(os.getpid(),),
        )
        finished = False
        try:
            pending: dict[Future, Task] = {pool.submit(run_task, task): task for task in tasks}
            while pending:
                ready, _ = wait(pending, return_when=FIRST_COMPLETED)
                for future in ready:
                    task = pending.pop(future)
                    try:
                        outcomes = future.result()
                    except Exception as error:  # the worker died (BrokenProcessPool): its cells fail
                        outcomes = _lost(task, error)
                    done(outcomes)
            finished = True
        finally:
            if finished:
                pool.shutdown(wait=True)
            else:  # interrupted (or `done` failed): stop now, leave no worker behind
                processes = list((getattr(pool, "_processes", None) or {}).values())
                pool.shutdown(wait=False, cancel_futures=True)
                for process in processes:
                    with suppress(Exception):
                        process.terminate()
                for process in processes:
                    with suppress(Exception):
                        process.join(timeout=5)


class RayCluster(Executor):
    """Each task a Ray task (one CPU) on the cluster at `address` ("auto", "ray://host:10001", or None for the Ray
    instance this process already started, else a new local one). `workers`: at most this many tasks at a time
    (default: as many as the cluster schedules)."""

    name = "ray"
    remote = True

    def __init__(self, address: str | None = None, workers: int | None = None, check_code: bool = True) -> None:
        self._ray()  # not installed: say so before any work
        self.address = address
        self.workers = workers or 0
        self.remote = check_code  # each task checks that its worker runs the sweep's code version

    @staticmethod
    def _ray() -> Any:
        try:
            import ray
        except ImportError:
            raise ConfigError(RAY_MISSING) from None
        return ray

    def connect(self) -> tuple[Any, bool]:
        """The ray module, and whether this call started the connection (and so should end it)."""
        ray = self._ray()
        if ray.is_initialized():
            return ray, False
        try:
            ray.init(address=self.address, log_to_driver=False, configure_logging=False)
        except (ConnectionError, RuntimeError, ValueError) as error:
            raise ConfigError(f"cannot connect to the Ray cluster at {self.address}: {one_line(error)}") from None
        return ray, True

    def run(self, tasks: list[Task], done: Done) -> None:
        if not tasks:
            return
        ray, started = self.connect()
        remote = ray.remote(num_cpus=1, max_retries=0)(run_task)
        waiting = list(tasks)
        pending: dict[Any, Task] = {}
        try:
            while waiting or pending:
                while waiting and (not self.workers or len(pending) < self.workers):
                    task = waiting.pop(0)
                    pending[remote.remote(task)] = task
                ready, _ = ray.wait(list(pending), num_returns=1)
                for reference in ready:
                    task = pending.pop(reference)
                    try:
                        outcomes = ray.get(reference)
                    except Exception as error:  # RayTaskError, WorkerCrashedError, ...
                        outcomes = _lost(task, error)
                    done(outcomes)
        finally:
            for reference in pending:
                with suppress(Exception):
                    ray.cancel(reference, force=True)
            if started:
                ray.shutdown()


def make_executor(ray_address: str | None = None, workers: int | None = None) -> Executor:
    """Ray when an address is given, else the local pool (`workers` 0: this process)."""
    if workers is not None and workers < 0:
        raise ConfigError(f"--workers must be 0 (this process) or more, not {workers}")
    if ray_address:
        return RayCluster(ray_address, workers)
    if workers == 0:
        return InProcess()
    return LocalPool(workers)
