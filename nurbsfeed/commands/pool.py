"""convert --jobs: the files converted in worker processes (`convert_in_pool`), each a
commands.batch.convert_one; a worker that dies fails only the file that killed it, and a stop
signal stops every worker, each removing its temporary files.
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from nurbsfeed.commands.batch import convert_one
from nurbsfeed.commands.progress import (
    PROGRESS_TICK_S,
    Notice,
    Progress,
    compile_notice_shared,
    watch_compiling,
)
from nurbsfeed.commands.stops import handle_stop_signals, stop
from nurbsfeed.commands.warm_up import hand_off
from nurbsfeed.errors import EXIT_SIGNAL_BASE, Interrupted

_worker_busy = False  # in a --jobs worker: a file is being converted
WORKER_STOP_S = 10.0  # how long a stopped worker has to remove its temporary files


def _worker_stop(signum: int, frame: Any) -> None:
    """A worker's signal handler: unwind the file being converted (its temporary files go);
    idle, just end."""
    if not _worker_busy:
        os._exit(EXIT_SIGNAL_BASE + signum)
    stop(signum, frame)


def _init_worker(notice_shown: Any, warm_up: list[str] | None, warmed: Any) -> None:
    handle_stop_signals(_worker_stop)
    Notice.quiet, Notice.shared = notice_shown is None, notice_shown
    watch_compiling()
    hand_off(warm_up, warmed)


def _convert_in_worker(*args: Any) -> dict[str, Any]:
    global _worker_busy
    _worker_busy = True
    try:
        return convert_one(*args)
    except Interrupted as exc:
        os._exit(exc.exit_code)  # cleaned up; the parent, signalled too, reports the stop
    finally:
        _worker_busy = False


def convert_in_pool(sources: list[Path], targets: list[Path | None], jobs: int,
                    progress: Progress | None, warm_up: list[str] | None,
                    *args: Any) -> list[dict[str, Any]]:
    """Convert in `jobs` worker processes; `args`: machine, method, dialect. On the first run
    after an install, the first worker to compile hands it to `warm_up`'s children (see
    commands.warm_up) and the others wait for them.

    A worker that dies (killed, out of memory, a crash in compiled code) breaks the pool and
    fails the files in flight, at most `jobs` of them, since files are handed out one at a time;
    each of those is converted again in a process of its own, so that only a file that kills
    its worker fails, and the rest go on in a new pool.
    """
    import multiprocessing

    results: dict[int, dict[str, Any]] = {}
    todo = list(range(len(sources)))
    start = (compile_notice_shared(), warm_up,
             multiprocessing.Value("b", 0) if warm_up is not None else None)
    while todo:
        lost, todo = _pool_round(todo, jobs, sources, targets, args, results, progress, start)
        for index in lost:
            if _pool_round([index], 1, sources, targets, args, results, progress, start)[0]:
                results[index] = {"source": str(sources[index]), "error": (
                    "internal error: BrokenProcessPool: the worker process converting this "
                    "file died (killed by a signal, or out of memory)")}
    return [results[index] for index in range(len(sources))]


def _pool_round(todo: list[int], jobs: int, sources: list[Path], targets: list[Path | None],
                args: tuple[Any, ...], results: dict[int, dict[str, Any]],
                progress: Progress | None,
                start: tuple[Any, ...]) -> tuple[list[int], list[int]]:
    """Convert files `todo` into `results` until done or the pool breaks: (files in flight when
    it broke, files not handed out). The status line moves on as files finish, and its clock
    every PROGRESS_TICK_S in between. `start`: the workers' `_init_worker` arguments."""
    import multiprocessing
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    waiting = todo[::-1]
    lost: list[int] = []
    with ProcessPoolExecutor(max_workers=min(jobs, len(todo)), initializer=_init_worker,
                             initargs=start) as pool:
        try:
            running: dict[Any, int] = {}
            while (waiting or running) and not lost:
                while waiting and len(running) < jobs:
                    index = waiting.pop()
                    running[pool.submit(_convert_in_worker, sources[index], targets[index],
                                        *args, None, False)] = index
                done, _ = wait(running, timeout=PROGRESS_TICK_S if progress else None,
                               return_when=FIRST_COMPLETED)
                for future in done:
                    index = running.pop(future)
                    try:
                        results[index] = future.result()
                    except BrokenProcessPool:
                        lost.append(index)
                    else:
                        if progress:
                            progress.file_done(index, results[index].get("points", 0))
                if progress and not done:
                    progress.show()
            lost += running.values()
        except Interrupted as exc:
            pool.shutdown(wait=False, cancel_futures=True)
            for child in multiprocessing.active_children():
                if child.pid is not None:  # (started: active children always are)
                    os.kill(child.pid, exc.signum)  # each removes its temporary files and ends
            for child in multiprocessing.active_children():
                child.join(WORKER_STOP_S)
                if child.is_alive():  # stuck in compiled code past the grace period
                    child.kill()
            # The pool's manager thread closes its wake-up pipe as it notices the workers gone;
            # concurrent.futures' exit hook writes to that pipe unlocked (Python < 3.12), so
            # the thread is joined here rather than raced at interpreter exit.
            pool.shutdown(wait=True)
            raise
    return lost, waiting[::-1]

