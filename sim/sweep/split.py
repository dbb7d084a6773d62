"""How a sweep uses the machine: worker processes x batch threads, cases per task and
per batch.

A sweep's cases are dealt out in *tasks*: a task of ``task`` cases goes to one worker
process (a process of the local pool, or a Dask worker), which plans each case (builds
and compiles its model), simulates them in batches of ``batch`` cases on MuJoCo's batch
with ``threads`` threads (:func:`sim.assess.many.run_plans`) and assesses them; the
parent only deals tasks and writes the rows that come back.

Why processes first (one thread per batch by default): planning and assessing a case is
Python, so within one process it runs one case at a time; on the 7 s El Centro case of
``scenarios/sweeps/mc_elcentro_20t.toml`` it is about half of a case's CPU time (1.75 s
of CPU per case, ~0.8 s of it the 14 340 physics steps; docs/batch-validation.md), and with the
batch's threads alone a 16-core machine ran that sweep at 4.5 x one core (issue #25's
measurement). Processes run all of it in parallel. More than one thread per batch
pays only where processes cannot be had (memory, one Dask worker per machine) and the
batches hold at least as many cases as threads.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sim.errors import UserError
from sim.parallel import usable_cores

#: tasks per process: the processes finish within about a quarter of a process's share
#: of the sweep of each other (the last tasks are what one process runs while another idles)
TASKS_PER_PROCESS = 4
#: the most cases in one task by default: at most this many are redone after an interruption
MAX_TASK = 32
#: the tasks shrink once fewer cases are left than this many tasks per process would hold
#: (guided self-scheduling: each task about 1/(TAIL_TASKS x processes) of what is left)
TAIL_TASKS = 2


@dataclass(frozen=True)
class Split:
    processes: int  #: worker processes (the local pool, or the Dask LocalCluster's workers)
    threads: int  #: threads of each MuJoCo batch
    task: int  #: the most cases dealt to a worker at once (planned, simulated and assessed there; :func:`deal`)
    batch: int  #: cases simulated together on one batch (at most ``task``)

    def describe(self) -> str:
        return (
            f"{self.processes} process{'es' if self.processes > 1 else ''} x {self.threads} "
            f"thread{'s' if self.threads > 1 else ''}, tasks of {self.task} cases, batches of {self.batch}"
        )


def deal(cases: list, split: Split) -> list[list]:
    """The cases in tasks, in order: tasks of ``split.task`` cases while many are left,
    then smaller ones, each about ``1 / (TAIL_TASKS x processes)`` of the cases left and
    never fewer than ``split.threads`` (a batch of fewer cases leaves threads idle).

    Why: the workers take tasks as they free up, so the sweep ends when the last task
    ends; with equal tasks the last ones start while the other workers run out of work,
    and on 16 workers of 4-case tasks the workers were busy only 0.83 of an 11 s sweep
    (docs/batch.md). Shrinking tasks leave at most a case or two for the others to
    wait on. Which case runs where does not change any case's result."""
    tasks, i, n = [], 0, len(cases)
    while i < n:
        guided = math.ceil((n - i) / (TAIL_TASKS * split.processes))
        size = min(split.task, max(split.threads, guided))
        tasks.append(cases[i : i + size])
        i += size
    return tasks


def _positive(value, name: str):
    if value is not None and (isinstance(value, bool) or not isinstance(value, int) or value < 1):
        raise UserError(f"{name} must be a positive integer (got {value!r})")
    return value


def choose_split(
    n_cases: int,
    *,
    cores: int | None = None,
    processes: int | None = None,
    threads: int | None = None,
    task: int | None = None,
    batch: int | None = None,
) -> Split:
    """The split of ``n_cases`` cases over ``cores`` cores (default: this machine's);
    each of ``processes``, ``threads``, ``task``, ``batch`` given overrides the choice:

    * threads: 1, or the cores left to each of the given processes;
    * processes: as many as the cores hold at ``threads`` each, never more than cases;
    * task: the cases over :data:`TASKS_PER_PROCESS` tasks per process, at most
      :data:`MAX_TASK`, at least ``threads`` (a batch of fewer cases leaves threads idle);
    * batch: the whole task.
    """
    for value, name in ((cores, "--workers"), (processes, "--processes"), (threads, "--threads")):
        _positive(value, name)
    _positive(task, "task (cases per task)")
    _positive(batch, "batch (cases per batch)")
    cores = cores or usable_cores()
    n = max(int(n_cases), 1)
    if threads is None:
        threads = 1 if processes is None else max(1, cores // processes)
    if processes is None:
        processes = max(1, min(cores // threads, n))
    if task is None:
        task = min(MAX_TASK, math.ceil(n / (TASKS_PER_PROCESS * processes)))
        task = min(max(task, threads), n)
    batch = min(batch or task, task)
    return Split(processes=processes, threads=threads, task=task, batch=batch)


__all__ = ["MAX_TASK", "TAIL_TASKS", "TASKS_PER_PROCESS", "Split", "choose_split", "deal"]
