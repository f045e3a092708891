"""Running a stage's independent shards on worker processes, in order, with a progress bar.

Every scene-parallel stage (generation, labelling, ...) splits its work into fixed shards whose
results do not depend on which process computes them, so the artifact is the same whatever
the number of workers.
"""

from __future__ import annotations

import math
import multiprocessing as mp
from typing import Callable, Iterator, Sequence, TypeVar

from tqdm import tqdm

T = TypeVar("T")
R = TypeVar("R")


def map_shards(fn: Callable[[T], R], tasks: Sequence[T], *, init: Callable[..., None],
               initargs: tuple, workers: int, desc: str, progress: bool = True,
               size: Callable[[T], int] = lambda t: t.count) -> Iterator[R]:
    """Yield ``fn(task)`` for every task, in task order, on ``workers`` processes.

    ``init(*initargs)`` runs once per process before its first task (in this process when
    ``workers <= 1``). The bar counts ``size(task)`` units (scenes) per finished task.
    """
    bar = tqdm(total=sum(size(t) for t in tasks), unit="scene", desc=desc,
               disable=not progress, smoothing=0.1)
    try:
        if workers <= 1:
            init(*initargs)
            for task in tasks:
                result = fn(task)
                bar.update(size(task))
                yield result
            return
        # fork: workers start in milliseconds and callers need no `if __name__ == "__main__"`
        # guard. Safe because stages open no log stream or pybullet client before this.
        ctx = mp.get_context("fork")
        with ctx.Pool(workers, initializer=init, initargs=initargs) as pool:
            for task, result in zip(tasks, pool.imap(fn, tasks, chunksize=1)):
                bar.update(size(task))
                yield result
    finally:
        bar.close()


def log_quota(sizes: dict[str, int], max_logged: int) -> dict[str, int]:
    """How many scenes of each split to log: ``max_logged`` in all, in proportion to the splits."""
    total = sum(sizes.values())
    if total == 0:
        return {s: 0 for s in sizes}
    return {s: min(n, math.ceil(max_logged * n / total)) for s, n in sizes.items()}
