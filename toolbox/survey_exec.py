"""Where a survey's tasks run: a local process pool, or the workers of a dask.distributed
cluster. A task is plain data and ``fn`` a module-level function, so that both run the same."""

from __future__ import annotations

import logging
import os
import time
from typing import Any, Callable, Mapping

from .errors import DataError, UsageError

log = logging.getLogger("toolbox.survey")

MAX_ATTEMPTS = 3  # a tile whose worker dies this often is reported failed



def _task_name(task: Mapping[str, Any]) -> str:
    return task["name"]  # a tile's, or "split FILE"


class LocalPool:
    """A process pool kept over a survey's phases (split, summaries, tiles): its workers start, and
    import the toolbox and the plugins, once. A pool a dead worker broke is replaced."""

    def __init__(self, workers: int):
        self.workers = workers
        self._pool = None

    def get(self):
        import concurrent.futures as cf
        import multiprocessing as mp

        if self._pool is None:
            # workers start from a clean server process, not forked from the driver: a driver that
            # has run GDAL (or any library with a thread pool) may hold a lock a forked child waits on
            if "forkserver" in mp.get_all_start_methods():
                ctx = mp.get_context("forkserver")
                ctx.set_forkserver_preload(["toolbox.survey", "toolbox.runner"])
            else:
                ctx = mp.get_context("spawn")
            self._pool = cf.ProcessPoolExecutor(max_workers=self.workers, mp_context=ctx)
        return self._pool

    def discard(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True, cancel_futures=True)
            self._pool = None

    def __enter__(self):
        return self

    def __exit__(self, *exc):
        self.discard()


def _run_local(tasks: list[dict], workers: int, on_result: Callable[[dict], None], on_start=None, *, fn,
               pools: LocalPool | None = None) -> None:
    """Tasks in a process pool (``pools``, or one of its own), at most ``workers`` at a time. A
    worker that dies (killed, out of memory) breaks the pool: its tasks are retried on a fresh
    pool, up to MAX_ATTEMPTS times."""
    import concurrent.futures as cf
    from concurrent.futures.process import BrokenProcessPool

    queue = list(tasks)
    attempts: dict[str, int] = {}
    own = pools is None
    pools = pools or LocalPool(workers)
    while queue:
        pool = pools.get()
        running: dict = {}
        broken = False
        try:
            while queue or running:
                while queue and not broken and len(running) < workers:
                    task = queue.pop(0)
                    name = _task_name(task)
                    attempts[name] = attempts.get(name, 0) + 1
                    running[pool.submit(fn, task)] = (task, name)
                    if on_start:
                        on_start(name)
                if not running:
                    break
                done, _ = cf.wait(running, return_when=cf.FIRST_COMPLETED)
                for fut in done:
                    task, name = running.pop(fut)
                    try:
                        on_result(fut.result())
                    except BrokenProcessPool:
                        broken = True
                        if attempts[name] < MAX_ATTEMPTS:
                            queue.insert(0, task)
                            log.warning("tile %s: its worker died; retrying it (attempt %d of %d)", name,
                                        attempts[name] + 1, MAX_ATTEMPTS)
                        else:
                            on_result({"tile": name, "status": "failed", "stats": {}, "outputs": {}, "layer_types": {},
                                       "error": f"its worker died {attempts[name]} times (killed, or out of memory: "
                                                "try a smaller --tile-size-m or fewer --workers)"})
                if broken and not running:
                    break
        except BaseException:  # Ctrl-C, SIGTERM: end the workers rather than wait for their tiles
            from .runner import stop_workers

            stop_workers(pool, running)
            pools.discard()
            raise
        if broken:
            pools.discard()
    if own:
        pools.discard()


def _run_dask(tasks: list[dict], scheduler, on_result: Callable[[dict], None], on_start=None, *, fn) -> dict:
    """Tiles on a dask.distributed cluster (an address, or a Client). Dask reschedules the tile
    of a worker that dies (up to its ``allowed-failures``)."""
    try:
        from distributed import Client, as_completed
    except ImportError:
        raise UsageError("--scheduler needs dask.distributed: pip install 'lidar-toolbox[cluster]'") from None
    own = not hasattr(scheduler, "submit")
    if own:
        try:
            client = Client(scheduler, timeout="20s")
        except (OSError, TimeoutError) as exc:
            raise DataError(f"could not reach the Dask scheduler at {scheduler!r} ({' '.join(str(exc).split())[:120]}); "
                            "start one with 'dask scheduler' and workers with 'dask worker ADDRESS --nthreads 1'") from None
    else:
        client = scheduler
    try:
        info = client.scheduler_info()
        n_workers = len(info.get("workers", {}))
        futures = {}
        for task in tasks:
            name = _task_name(task)
            fut = client.submit(fn, task, key=f"tile-{name}-{os.getpid()}-{time.time_ns()}", pure=False)
            futures[fut] = name
            if on_start:
                on_start(name)
        for fut in as_completed(list(futures)):
            name = futures[fut]
            try:
                on_result(fut.result())
            except Exception as exc:  # KilledWorker: its workers kept dying on this tile
                on_result({"tile": name, "status": "failed", "stats": {}, "outputs": {}, "layer_types": {},
                           "error": f"the cluster gave up on it: {type(exc).__name__}: {' '.join(str(exc).split())[:200]}"})
        return {"address": client.scheduler.address, "n_workers": n_workers}
    finally:
        if own:
            client.close()
