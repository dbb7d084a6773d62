"""Many simulations of one table at once, on MuJoCo's batch (``mujoco.batch.Batch``).

:class:`BatchRunner` takes N prepared :class:`sim.loop.simulation.Simulation` objects
(each from its own plan, so each may have its own payload mass, bulk modulus, gains,
friction, motion and scale) and runs them together, closed loop on references or open
loop on recorded valve commands (calibration replays): MuJoCo steps them on
its thread pool with the coupled step compiled as its control callback
(:mod:`sim.loop.callback`), so no Python runs between physics steps. Per-simulation
model fields come from each simulation's own compiled model (``Batch.set_models``:
models compiled from one spec with other parameters, the MjData layout unchanged); the
compiled kernels are shared, nothing is recompiled per simulation.

The hydraulic and controller state of the batch sits in arrays with the simulations as
their first axis (``X`` (N, NX, 1, n_act): ``force`` is the (N, n_act) view of the
piston forces); each simulation's callback context points at its slice.

Each simulation's result equals its single run (``Simulation.run``), bit for bit: the
batch runs each simulation's steps on one MjData in order, and the callback does what
the loop does (``tests/loop/test_batch.py``).
"""

from __future__ import annotations

import time

import mujoco
import numpy as np
from mujoco import batch as mjbatch

from sim.errors import ScenarioError
from sim.loop import callback as CB
from sim.parallel import usable_cores

_INTEGRATION = int(mujoco.mjtState.mjSTATE_INTEGRATION)


class BatchRunner:
    """N simulations of one table on one ``mujoco.batch.Batch`` of ``nthread`` threads (0:
    all cores); ``open_loop``: for valve-command replays only."""

    def __init__(self, sims: list, *, nthread: int = 0, open_loop: bool = False):
        if not sims:
            raise ValueError("BatchRunner needs at least one simulation")
        for s in sims:
            why = CB.accepts(s, open_loop=open_loop)
            if why:
                raise ScenarioError(f"a simulation of this batch cannot run on the callback: {why}")
        self.open_loop = open_loop
        self.sims = list(sims)
        self.nthread = nthread or usable_cores()
        compiled = {}  # one model per table model (simulations of one TableModel share it)
        self.models = [
            compiled.setdefault(id(s.tm), CB.callback_model(s)) if id(s.tm) not in compiled else compiled[id(s.tm)]
            for s in self.sims
        ]
        sizes = {(m.nq, m.nv, m.nu, m.nbody, m.neq, m.nuserdata) for m in self.models}
        if len(sizes) != 1:
            raise ScenarioError(
                "the simulations of a batch must share one table layout (same bodies, joints, "
                "actuators); run other tables in another batch"
            )

    @staticmethod
    def accepts(plan) -> bool:
        """Can the batch run this :class:`sim.assess.run.ScenarioPlan` (closed loop on
        the callback, no drive iterations)?"""
        from sim.loop.simulation import Simulation

        return isinstance(plan.sim, Simulation) and CB.accepts(plan.sim) is None and not plan.iteration.get("count", 0)

    def run(
        self,
        references: list | None = None,
        *,
        valve_commands: list | None = None,
        duration_s: float | None = None,
        chunk_ticks: int = 256,
    ) -> list:
        """Run simulation i on ``references[i]`` (closed loop) or ``valve_commands[i]``
        ((n_i, n_act) at the controller rate, open loop; give one of the two) from its
        current state (its ``reset``); returns one
        :class:`sim.loop.simulation.RunResult` per simulation."""
        sims, N = self.sims, len(self.sims)
        refs, vcs = _inputs(N, references, valve_commands)
        if self.open_loop and references is not None:
            raise ValueError("this batch was made for valve-command replays (open_loop=True); give valve_commands")
        ns = np.array([CB.run_length(s, r, v, duration_s) for s, r, v in zip(sims, refs, vcs)])
        from hydraulics import _layout as HL

        # the batch's hydraulic and pre-sliding state, simulations first
        self.X = np.stack([s.hs._X for s in sims])  # (N, NX, 1, n_act)
        self.Y = np.stack([s.hs._Y for s in sims])
        self.IC = np.stack([s.hs._IC for s in sims])
        self.ICS = np.stack([s.hs._ICS for s in sims])
        self.ZFR = np.stack([s._zfr for s in sims])
        self.force = self.X[:, HL.FORCE, 0, :]  # (N, n_act) view
        ctxs = [
            CB.Context(
                s,
                r,
                int(n),
                state={"X": self.X[i], "Y": self.Y[i], "IC": self.IC[i], "ICS": self.ICS[i], "ZFR": self.ZFR[i]},
                valve_command=v,
            )
            for i, (s, r, v, n) in enumerate(zip(sims, refs, vcs, ns))
        ]
        m0 = self.models[0]
        b = mjbatch.Batch(m0, N, self.nthread)
        if N > 1 or self.models[0] is not m0:
            b.set_models(self.models)
        rows = np.empty((N, b.nstate))
        for i, (s, m2, ctx) in enumerate(zip(sims, self.models, ctxs)):
            d2 = mujoco.MjData(m2)
            CB.copy_state(s.m, s.d, m2, d2)
            d2.userdata[0] = ctx.address
            d2.userdata[1] = 0.0
            mujoco.mj_getState(m2, d2, rows[i], _INTEGRATION)
        b.state[:] = rows
        spt = np.array([s.steps_per_tick for s in sims])
        if len(set(spt.tolist())) != 1:
            raise ScenarioError("the simulations of a batch must share one physics step and controller rate")
        spt = int(spt[0])
        done = np.zeros(N, dtype=np.int64)
        with CB.installed():
            c0 = time.process_time()
            t0 = time.perf_counter()
            while True:
                # stopped: diverged, or reset by MuJoCo after a bad state (which zeroes userdata,
                # so the callback has stopped counting its steps)
                live = np.array([c.C[CB.S_DONE] < 0 and c.C[CB.S_CALLS] >= dn * spt for c, dn in zip(ctxs, done)])
                active = np.flatnonzero((done < ns) & live)
                if not len(active):
                    break
                k = int(min(chunk_ticks, (ns[active] - done[active]).min()))
                b.step(ids=active, nstep=k * spt)
                done[active] += k
            wall = time.perf_counter() - t0
            self.cpu_s = time.process_time() - c0  # CPU time of every thread of the process
        self.wall_s = wall
        self.batch = b
        qpos, qvel = b.bind("qpos"), b.bind("qvel")
        out = []
        for i, ctx in enumerate(ctxs):
            out.append(ctx.result(wall / N, (qpos[i], qvel[i])))
        return out


def _inputs(N: int, references, valve_commands) -> tuple[list, list]:
    """Per simulation: its reference and its valve commands (one of them None)."""
    if (references is None) == (valve_commands is None):
        raise ValueError("give exactly one of references and valve_commands")
    given = references if references is not None else valve_commands
    if len(given) != N:
        what = "references" if references is not None else "valve command arrays"
        raise ValueError(f"{N} simulations but {len(given)} {what}")
    none = [None] * N
    return (list(references), none) if references is not None else (none, list(valve_commands))


def run_batch(
    sims: list,
    references: list | None = None,
    *,
    valve_commands: list | None = None,
    nthread: int = 0,
    duration_s: float | None = None,
) -> list:
    """:meth:`BatchRunner.run` of a new runner: one result per simulation."""
    runner = BatchRunner(sims, nthread=nthread, open_loop=references is None)
    return runner.run(references, valve_commands=valve_commands, duration_s=duration_s)


#: model sizes that do not size MjData (the names' text and the model's own buffer)
_NOT_LAYOUT = ("nbuffer", "nnames", "nnames_map", "npaths", "ntext", "ntextdata", "ntuple", "ntupledata")


def _layout(m) -> tuple:
    """Every size of the model that sizes MjData (each ``n*`` integer: bodies, joints,
    tendons, wraps, their Jacobians' nonzeros, ...). A tendon added by an effect at a DOF
    (a spring, a damper) keeps nq, nv, nu and nbody but not ntendon, nwrap, nJten: such
    models cannot share a batch (``mjb_setModels``)."""
    return tuple(
        (k, v) for k in sorted(dir(m)) if k.startswith("n") and k not in _NOT_LAYOUT and type(v := getattr(m, k)) is int
    )


def _batch_key(sim):
    """Simulations with equal keys can share one batch (same MjData layout, physics step
    and controller rate)."""
    return (_layout(sim.m), sim.steps_per_tick, float(sim.dt))


def run_many(
    sims: list,
    references: list | None = None,
    *,
    valve_commands: list | None = None,
    nthread: int = 0,
    group: int = 32,
    counts: dict | None = None,
) -> list:
    """Run simulation ``i`` closed loop on ``references[i]``, or open loop on
    ``valve_commands[i]`` ((n_i, n_act) at the controller rate; give one of the two),
    from its current state (as :meth:`Simulation.run
    <sim.loop.simulation.Simulation.run>` does: ``reset`` first for a fresh run);
    returns one result per simulation, in order.

    The shared route for many simulations (sweep cases, feasibility suites, calibration
    candidates): simulations the callback can run (:func:`sim.loop.callback.accepts`)
    go to :class:`BatchRunner` in batches of up to ``group`` simulations that share a
    layout, on ``nthread`` threads (0: all cores); the others (the Rice table's analog
    loop, per-step effects, a valve delay) run their own ``run``. Every result equals
    the simulation's own ``Simulation.run`` bit for bit (``tests/loop/test_batch.py``,
    ``tests/loop/test_batch_open.py``). A simulation that diverges ends early with
    ``incomplete_reason`` set, as in ``Simulation.run``; the others are not affected.
    ``counts`` (a dict, optional) gets ``"batch"`` and ``"fallback"`` added: how many
    simulations went each way.
    """
    refs, vcs = _inputs(len(sims), references, valve_commands)
    if group < 1:
        raise ValueError(f"group must be at least 1 (got {group})")
    from sim.loop.simulation import Simulation

    out: list = [None] * len(sims)
    pending: dict = {}  # batch key -> indices waiting for a batch
    order = []
    open_loop = references is None
    for i, s in enumerate(sims):
        if isinstance(s, Simulation) and CB.accepts(s, open_loop=open_loop) is None:
            k = _batch_key(s)
            if k not in pending:
                pending[k] = []
                order.append(k)
            pending[k].append(i)
        elif refs[i] is not None:
            out[i] = s.run(reference=refs[i])
        else:
            out[i] = s.run(valve_command=vcs[i])
    for k in order:
        idx = pending[k]
        for j in range(0, len(idx), group):
            part = idx[j : j + group]
            runner = BatchRunner([sims[i] for i in part], nthread=nthread, open_loop=open_loop)
            if references is not None:
                res = runner.run([refs[i] for i in part])
            else:
                res = runner.run(valve_commands=[vcs[i] for i in part])
            for i, r in zip(part, res):
                out[i] = r
    if counts is not None:
        n_batch = sum(len(v) for v in pending.values())
        counts["batch"] = counts.get("batch", 0) + n_batch
        counts["fallback"] = counts.get("fallback", 0) + len(sims) - n_batch
    return out


__all__ = ["BatchRunner", "run_batch", "run_many"]
