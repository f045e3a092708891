"""Running a stage's independent shards on worker processes, in order, with a progress bar.

Every scene-parallel stage (generation, labelling, the baseline's candidate labels, the closed
loop's trials) splits its work into fixed shards whose results do not depend on which process
computes them, so the artifact is the same whatever the number of workers and whatever the
executor. ``executor`` (``conf/executor/``, command-line override ``executor=local|ray``):

- ``local`` (default): a fork ``multiprocessing`` pool on this machine.
- ``ray``: ``workers`` Ray actors, each running the stage's ``init(*initargs)`` once and then
  ``fn(task)`` per task, fed in task order (``ray.util.ActorPool``). With ``executor.address``
  null a private Ray instance is started for the call (``workers`` CPUs, a small object store)
  and shut down after it; with an address (``executor.address`` or ``RAY_ADDRESS``, e.g.
  ``ray://head:10001`` or ``auto``) the tasks run on that cluster, and ``workers=0`` means all
  of the cluster's CPUs. Ray is an optional extra: ``pip install -e '.[ray]'`` (also installed
  by ``bash scripts/setup.sh``, which installs ``requirements.lock``).

On a cluster, workers write their shard files themselves (absolute paths under ``paths.root``),
so ``paths.root`` must be a shared filesystem mounted at the same path on every node, and the
``pipeline`` package (with its ``conf/``) must be importable on every node: the same repository
checkout and environment on each, or a Ray ``runtime_env`` that ships them. An exception in a
task is raised again in the driver with its original type and message (the remote traceback is
attached as a note), so the stage fails and discards its half-written work folder as it does
with the local executor.

The executor is not part of any artifact version: results are the same under both
(``tests/test_executor.py``), so ``pipeline.runtime.executor`` is plumbing for the source hash too.
"""

from __future__ import annotations

import importlib
import math
import multiprocessing as mp
import re
import sys
from collections.abc import Callable, Iterator, Sequence
from typing import Any, TypeVar

from tqdm import tqdm

T = TypeVar("T")
R = TypeVar("R")

EXECUTORS = ("local", "ray")
_ANSI_COLOUR = re.compile(r"\x1b\[[0-9;]*m")
RAY_INSTALL_HINT = (
    "executor=ray needs the optional package ray: install it with "
    "`pip install -e '.[ray]'` or `bash scripts/setup.sh` (installs "
    "requirements.lock), or run with executor=local"
)


def executor_name(executor: Any) -> str:
    """``"local"`` or ``"ray"`` for an ``executor`` config node (None → ``"local"``)."""
    name = "local" if executor is None else str(_get(executor, "name", "local"))
    if name not in EXECUTORS:
        raise ValueError(f"executor.name is {name!r}: choose from {', '.join(EXECUTORS)}")
    return name


def _get(node: Any, key: str, default: Any = None) -> Any:
    """``node.key`` for a dataclass, DictConfig or dict config node."""
    if isinstance(node, dict):
        return node.get(key, default)
    return getattr(node, key, default)


def import_ray():
    """The ``ray`` module, or an ImportError that says how to install it."""
    from pipeline.runtime.cli import MissingLibraryError

    try:
        import ray
    except ImportError as e:
        raise MissingLibraryError(RAY_INSTALL_HINT) from e
    return ray


def start_ray(executor: Any, num_cpus: int) -> bool:
    """Initialise Ray for ``executor`` unless it already is; True if this call did it.

    With ``executor.address``: connect to that cluster. Without: start a private local instance
    with ``num_cpus`` CPUs, no dashboard and an object store of
    ``executor.object_store_memory_mb`` (Ray's default reserves 30 % of the RAM).
    """
    ray = import_ray()
    if ray.is_initialized():
        return False
    address = _get(executor, "address") or None
    kwargs: dict[str, Any] = dict(
        include_dashboard=False,
        configure_logging=False,
        log_to_driver=bool(_get(executor, "log_to_driver", True)),
    )
    if address is None:
        # "local": a new instance even where RAY_ADDRESS names a cluster (address is null).
        kwargs.update(
            address="local",
            num_cpus=max(1, int(num_cpus)),
            object_store_memory=int(_get(executor, "object_store_memory_mb", 512)) * 1024 * 1024,
        )
    else:
        kwargs.update(address=str(address))
    ray.init(**kwargs)
    return True


def _cluster_workers(executor: Any) -> int:
    """How many tasks of ``executor.num_cpus_per_task`` CPUs the connected cluster can run."""
    ray = import_ray()
    per_task = float(_get(executor, "num_cpus_per_task", 1) or 1)
    return max(1, int(ray.cluster_resources().get("CPU", 1) // per_task))


def resolve_workers(requested: int, executor: Any = None) -> int:
    """The number of workers a stage uses: ``requested`` if positive; otherwise all of the
    cluster's CPUs for ``executor=ray`` with an address, else this machine's cores."""
    from pipeline.runtime.cli import default_workers

    if requested > 0:
        return int(requested)
    if executor_name(executor) == "ray" and _get(executor, "address"):
        ray = import_ray()
        started = start_ray(executor, 0)
        try:
            return _cluster_workers(executor)
        finally:
            if started:
                ray.shutdown()
    return default_workers(requested)


def _by_reference(fn: Callable) -> Callable:
    """``fn``, or for a function of ``__main__`` run as ``python -m pipeline.<stage>``, the same
    function of module ``pipeline.<stage>``. Ray pickles ``__main__``'s functions by value, each
    with its own copy of the module's globals, so ``init`` would set up state that ``fn`` never
    sees; by reference, both are the worker's imported module's functions."""
    if getattr(fn, "__module__", None) != "__main__":
        return fn
    spec = getattr(sys.modules["__main__"], "__spec__", None)
    if spec is None or not spec.name or spec.name == "__main__":
        return fn
    module = importlib.import_module(spec.name)
    return getattr(module, fn.__qualname__, fn)


class _ShardWorker:
    """A Ray actor: ``init(*initargs)`` once (``setup``), then ``fn(task)`` per task."""

    def __init__(self, fn, init, initargs) -> None:
        self.fn, self.init, self.initargs = fn, init, initargs

    def setup(self) -> None:
        self.init(*self.initargs)

    def run(self, task):
        return self.fn(task)


def _reraise_task_error(ray, error: BaseException, fn: Callable) -> None:
    """Raise a task's exception in the driver as its original type and message."""
    cause = getattr(error, "cause", None)
    if not isinstance(error, ray.exceptions.RayTaskError) or not isinstance(cause, BaseException):
        raise error
    # str(error) is Ray's report: the worker process, then the remote traceback.
    report = _ANSI_COLOUR.sub("", str(error)).rstrip()
    cause.add_note(f"(raised in a Ray worker running {getattr(fn, '__qualname__', fn)}: {report})")
    raise cause from None


def _map_ray(fn, tasks, init, initargs, workers, executor, on_result) -> Iterator:
    ray = import_ray()
    per_task = float(_get(executor, "num_cpus_per_task", 1) or 1)
    if workers <= 0 and not _get(executor, "address"):
        workers = resolve_workers(workers)  # a private instance: this machine's cores
    started = start_ray(executor, math.ceil(max(workers, 1) * per_task))
    actors = []
    try:
        if workers <= 0:
            workers = _cluster_workers(executor)
        workers = max(1, min(workers, len(tasks)))
        actor_cls = ray.remote(num_cpus=per_task, max_restarts=0)(_ShardWorker)
        fn, init = _by_reference(fn), _by_reference(init)
        fn_ref, init_ref, args_ref = ray.put(fn), ray.put(init), ray.put(initargs)
        actors = [actor_cls.remote(fn_ref, init_ref, args_ref) for _ in range(workers)]
        try:
            ray.get([a.setup.remote() for a in actors])
            pool = ray.util.ActorPool(actors)
            for task, result in zip(tasks, pool.map(lambda a, t: a.run.remote(t), list(tasks))):
                on_result(task)
                yield result
        except ray.exceptions.RayTaskError as e:
            _reraise_task_error(ray, e, fn)
    finally:
        for a in actors:
            ray.kill(a)
        if started:
            ray.shutdown()


def map_shards(
    fn: Callable[[T], R],
    tasks: Sequence[T],
    *,
    init: Callable[..., None],
    initargs: tuple,
    workers: int,
    desc: str,
    progress: bool = True,
    size: Callable[[T], int] = lambda t: t.count,
    executor: Any = None,
) -> Iterator[R]:
    """Yield ``fn(task)`` for every task, in task order, on ``workers`` processes.

    ``init(*initargs)`` runs once per process before its first task (in this process when
    ``workers <= 1`` and the executor is local). The bar counts ``size(task)`` units (scenes)
    per finished task. ``executor``: the ``executor`` config node (None: local); with
    ``executor.name == "ray"`` the processes are Ray actors (see the module docstring), and
    ``fn``, ``init``, ``initargs`` and the tasks must be picklable (module-level functions).
    """
    name = executor_name(executor)
    tasks = list(tasks)
    bar = tqdm(
        total=sum(size(t) for t in tasks),
        unit="scene",
        desc=desc,
        disable=not progress,
        smoothing=0.1,
    )
    try:
        if name == "ray":
            if tasks:
                yield from _map_ray(
                    fn, tasks, init, initargs, workers, executor, lambda t: bar.update(size(t))
                )
            return
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
