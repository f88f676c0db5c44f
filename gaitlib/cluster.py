"""Ray plumbing for the embarrassingly parallel jobs (``gaitlib collect``, ``gaitlib benchmark``).

A job is a list of independent *tasks* (collection chunks, benchmark groups) and a *worker*: an object built once
per process from a module-level factory (it loads the library and owns its simulator) and called once per task;
a task's result is a pure function of the task and the worker's settings, whoever runs it. :func:`run_ordered`
runs the tasks and yields the results **in task order**, so the driver (the only process that writes files)
writes exactly what a run without Ray writes:

* without a :class:`ClusterConfig` the worker is built in this process and the tasks run one after the other;
* with one, each worker is a Ray actor (``num_cpus`` / ``num_gpus`` each), tasks are handed out as workers free up
  (:func:`ray.wait`), out-of-order results are held until their turn, and a worker that dies
  (:class:`ray.exceptions.RayActorError`) loses only its task in flight: that task is handed out again, to a new
  actor that replaces the dead one.

Ray is an optional dependency (``pip install -e ".[cluster]"``), imported only here and only when a cluster is
asked for. References: Ray actors https://docs.ray.io/en/latest/ray-core/actors.html, actor fault tolerance
https://docs.ray.io/en/latest/ray-core/fault_tolerance/actors.html, ``ray.wait``
https://docs.ray.io/en/latest/ray-core/api/doc/ray.wait.html.
"""

from __future__ import annotations

import dataclasses
import itertools
import os
import uuid
from collections import deque
from collections.abc import Callable, Iterable, Iterator
from dataclasses import dataclass, field
from typing import Any

from gaitlib.errors import GaitlibError

__all__ = ["INSTALL_HINT", "WORKER_PREFIX", "ClusterConfig", "ClusterError", "WorkerSpec", "require_ray", "run_ordered"]

INSTALL_HINT = 'pip install -e ".[cluster]"'
"""How to install Ray for ``--ray`` (the ``cluster`` extra)."""

WORKER_PREFIX = "gaitlib-worker-"
"""Name prefix of the Ray actors (``ray list actors`` shows them; each has a ``pid`` method)."""


class ClusterError(GaitlibError):
    """Ray is missing, cannot be reached, or its workers keep dying (one-line message)."""


@dataclass(frozen=True, kw_only=True)
class ClusterConfig:
    """Where the tasks of a job run: Ray workers."""

    address: str | None = None
    """Ray address: ``None`` starts a local Ray for the run (stopped after it), ``auto`` joins the cluster this
    node belongs to (``ray start --head``), ``ray://HOST:10001`` a remote one."""
    workers: int | None = None
    """Ray actors, each with its own copy of the library and its own simulator (``None``: as many as the cluster
    has CPUs, or GPUs for GPU workers, for the per-worker reservation)."""
    cpus_per_worker: float = 1.0
    """CPU cores Ray reserves per worker."""
    gpus_per_worker: float = 0.0
    """GPUs Ray reserves per worker (1 for the ``newton`` backend on CUDA)."""
    max_replacements: int | None = None
    """Dead workers replaced before the job gives up (``None``: twice ``workers`` plus two)."""

    def __post_init__(self) -> None:
        if self.workers is not None and self.workers < 1:
            raise ClusterError(f"need at least one worker, got {self.workers}")

    def for_backend(self, backend: str, device: str | None) -> ClusterConfig:
        """This configuration with one GPU per worker for the ``newton`` backend on CUDA (its default device where
        ``device`` is ``None``), as set otherwise."""
        if backend == "newton" and (device or "cuda").startswith("cuda") and self.gpus_per_worker == 0:
            return dataclasses.replace(self, gpus_per_worker=1.0)
        return self

    def worker_count(self, resources: dict[str, float]) -> int:
        """``workers``, else what the cluster's ``resources`` (``ray.cluster_resources()``) hold."""
        if self.workers is not None:
            return self.workers
        if self.gpus_per_worker > 0:
            return max(1, int(resources.get("GPU", 0) // self.gpus_per_worker))
        return max(1, int(resources.get("CPU", 1) // self.cpus_per_worker))


@dataclass(frozen=True)
class WorkerSpec:
    """How a worker is built: ``factory(**kwargs)`` returns a callable ``task -> result`` (with an optional
    ``close()``); ``factory`` must be importable by name on every node (a module-level function or class)."""

    factory: Callable[..., Callable[[Any], Any]]
    kwargs: dict = field(default_factory=dict)


def require_ray():
    """The ``ray`` module, or a one-line :class:`ClusterError` telling how to install it."""
    try:
        import ray
    except ImportError:
        raise ClusterError(f"--ray needs Ray, which is not installed: {INSTALL_HINT}") from None
    return ray


def run_ordered(
    tasks: Iterable[Any], *, spec: WorkerSpec, cluster: ClusterConfig | None = None
) -> Iterator[tuple[Any, Any]]:
    """``(task, result)`` for every task, in task order: in this process without ``cluster``, else on Ray workers
    (see the module doc). Closing the iterator early stops the workers; a task's own error is raised as is."""
    if cluster is None:
        yield from _run_here(tasks, spec)
    else:
        yield from _run_on_ray(tasks, spec, cluster)


def _run_here(tasks: Iterable[Any], spec: WorkerSpec) -> Iterator[tuple[Any, Any]]:
    worker = spec.factory(**spec.kwargs)
    try:
        for task in tasks:
            yield task, worker(task)
    finally:
        getattr(worker, "close", lambda: None)()


_NO_TASK = object()
"""What an empty task list yields first."""


class _Host:
    """The Ray actor: builds one worker and runs tasks on it."""

    def __init__(self, spec: WorkerSpec) -> None:
        self._worker, self._error = None, None
        try:
            self._worker = spec.factory(**spec.kwargs)
        except Exception as error:  # raised by the first task, as the task's own error (one line, not a death)
            self._error = error

    def run(self, task: Any) -> Any:
        if self._error is not None:
            raise self._error
        return self._worker(task)

    def pid(self) -> int:
        """Process id of the actor (to watch or kill it)."""
        return os.getpid()


def _run_on_ray(tasks: Iterable[Any], spec: WorkerSpec, cluster: ClusterConfig) -> Iterator[tuple[Any, Any]]:
    ray = require_ray()
    tasks = iter(tasks)
    first = next(tasks, _NO_TASK)
    if first is _NO_TASK:  # nothing to do (a finished run resumed): no Ray started, no worker built
        return
    tasks = itertools.chain([first], tasks)
    started = not ray.is_initialized()
    if started:
        try:
            ray.init(address=cluster.address, include_dashboard=False, log_to_driver=False, configure_logging=False)
        except (ConnectionError, RuntimeError, ValueError) as error:
            where = cluster.address or "a local Ray"
            raise ClusterError(f"cannot start or reach {where}: {str(error).splitlines()[0]}") from None
    pool = _Pool(ray, spec, cluster)
    try:
        yield from pool.results(tasks)
    finally:
        pool.stop()
        if started:
            ray.shutdown()


class _Pool:
    """Ray actors handing out tasks; results delivered in task order (see the module doc)."""

    def __init__(self, ray, spec: WorkerSpec, cluster: ClusterConfig) -> None:
        self._ray, self._cluster = ray, cluster
        self._remote = ray.remote(_Host)
        self._options = {"num_cpus": cluster.cpus_per_worker, "num_gpus": cluster.gpus_per_worker, "max_restarts": 0}
        self._spec = ray.put(spec)
        workers = cluster.worker_count(ray.cluster_resources())
        self._left = cluster.max_replacements if cluster.max_replacements is not None else 2 * workers + 2
        self._names = (f"{WORKER_PREFIX}{uuid.uuid4().hex[:8]}-{k}" for k in itertools.count())
        self.actors = [self._start() for _ in range(workers)]
        """The live actors (``actor.pid.remote()`` gives a process id)."""

    def _start(self):
        return self._remote.options(name=next(self._names), **self._options).remote(self._spec)

    def results(self, tasks: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        """``(task, result)`` in task order; ``tasks`` is read lazily, no further than the window ahead."""
        ray = self._ray
        source = enumerate(tasks)
        todo: deque[tuple[int, Any]] = deque()  # (index, task) to run, a dead actor's task first
        running: dict[Any, tuple[int, Any, Any]] = {}  # object ref -> (task index, task, actor)
        done: dict[int, tuple[Any, Any]] = {}
        window = 4 * len(self.actors)  # results held at most this far ahead of the next one due
        turn = 0
        while True:
            idle = [a for a in self.actors if all(a is not b for _, _, b in running.values())]
            while idle:
                if not todo:
                    following = next(source, None)
                    if following is None:
                        break
                    todo.append(following)
                if todo[0][0] >= turn + window:
                    break
                (i, task), actor = todo.popleft(), idle.pop()
                running[actor.run.remote(task)] = (i, task, actor)
            if not running:
                return
            ready, _ = ray.wait(list(running), num_returns=1)
            i, task, actor = running.pop(ready[0])
            try:
                done[i] = (task, ray.get(ready[0]))
            except ray.exceptions.RayTaskError as error:  # the task's own error, e.g. a one-line GaitlibError
                raise error.cause from None
            except ray.exceptions.RayActorError:
                self._replace(actor)
                todo.appendleft((i, task))
            while turn in done:
                yield done.pop(turn)
                turn += 1

    def _replace(self, dead) -> None:
        """Swap a dead actor for a new one (its task goes back to the queue)."""
        if self._left <= 0:
            raise ClusterError("Ray workers keep dying (out of memory? a node lost?); the committed results are kept")
        self._left -= 1
        self.actors = [a for a in self.actors if a is not dead] + [self._start()]

    def stop(self) -> None:
        for actor in self.actors:
            self._ray.kill(actor)
        self.actors = []
