"""Many planned scenario runs at once: the one route of sweeps, feasibility suites,
the largest-scale search and calibration candidates.

:func:`run_plans` takes :class:`sim.assess.run.ScenarioPlan` objects (each from its own
:func:`~sim.assess.run.plan_scenario`, so each may have its own table parameters,
payload, motion, scale and window) and returns their :class:`~sim.assess.run.RunOutcome`
in order. Plans without drive iterations whose simulation the callback can run are
simulated together by :func:`sim.loop.batch.run_many` (MuJoCo's batch, the coupled step
inside ``mj_step``, no Python between physics steps); the others (drive iterations, the
Rice table's analog loop) run their own :meth:`ScenarioPlan.run`. The outcomes equal
the plans' own runs (``tests/sweep/test_sweep.py``).

A plan whose inputs make the run impossible (a :class:`~sim.errors.UserError`, e.g. a
divergence before the second sample) gives that error in its place instead of raising,
so one bad case does not stop the others.
"""

from __future__ import annotations

from sim.errors import UserError


def batchable(plan) -> bool:
    """Can :func:`run_plans` simulate this plan on the batch (closed loop on the
    callback, no drive iterations)?"""
    from sim.loop.batch import BatchRunner

    return BatchRunner.accepts(plan)


def run_plans(plans: list, *, nthread: int = 0, group: int = 32, reset: bool = True) -> list:
    """Run every plan; returns, in order, its ``RunOutcome`` or the ``UserError`` it
    raised. ``nthread``: the batch's threads (0: all cores); ``group``: simulations per
    batch; ``reset``: start every simulation from rest (``sim.reset()``, as a fresh
    :meth:`ScenarioPlan.run` does). A batched outcome's ``wall_s`` is its share of its
    batch's wall time."""
    from sim.loop.batch import run_many

    out: list = [None] * len(plans)
    batch = [i for i, p in enumerate(plans) if batchable(p)]
    for i, p in enumerate(plans):
        if i in batch:
            continue
        if reset:
            p.sim.reset()
        try:
            out[i] = p.run()
        except UserError as e:
            out[i] = e
    if batch:
        sims = [plans[i].sim for i in batch]
        if reset:
            for s in sims:
                s.reset()
        results = run_many(sims, [plans[i].reference for i in batch], nthread=nthread, group=group)
        for i, res in zip(batch, results):
            try:
                out[i] = plans[i].outcome(res)
            except UserError as e:
                out[i] = e
    return out


__all__ = ["batchable", "run_plans"]
