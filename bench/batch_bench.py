"""The coupled step inside MuJoCo and the batch, against the bare ``mj_step``.

* single simulation: the whole twin on the callback route (``sim.loop.callback``) per
  physics step over the bare ``mj_step`` of the same model (target <= 1.15), beside the
  Python loop's figure;
* batches of N on all cores (``sim.loop.batch``): simulated seconds per wall second, and
  the efficiency = batch physics steps per second / (min(N, threads) x the single bare
  ``mj_step`` rate) (target >= 0.85 for N >= 32), beside the same figure for MuJoCo's
  batch of plain models (no callback): what MuJoCo's batch itself reaches on this machine
  at this moment, so a shortfall can be put on the twin or on MuJoCo / the machine.

All figures from this one run; on a shared machine they are noisy, the ratios less so
(taken side by side).
"""

from __future__ import annotations

import os
import time

import mujoco
import numpy as np

from sim.loop.batch import BatchRunner
from sim.loop.callback import control_callback, run_callback
from sim.loop.simulation import Simulation
from sim.parallel import usable_cores


def bare_rate(model, seconds: float = 1.0) -> float:
    """Bare ``mj_step`` calls per second (random actuator forces), one thread."""
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, 0)
    rng = np.random.default_rng(0)
    forces = rng.normal(0, 5e4, (64, model.nu))
    for _ in range(200):
        mujoco.mj_step(model, d)
    n, t0 = 0, time.perf_counter()
    while time.perf_counter() - t0 < seconds:
        for i in range(256):
            d.ctrl[:] = forces[i & 63]
            mujoco.mj_step(model, d)
        n += 256
    return n / (time.perf_counter() - t0)


def bare_replay_rate(tm, forces, spt: int) -> float:
    """Bare ``mj_step`` calls per second of the same model on the same motion: the
    recorded actuator forces (held over each tick) into ``ctrl``, no hydraulics,
    controller or recorder; one thread."""
    return bare_replay(tm, forces, spt)[0]


def bare_replay(tm, forces, spt: int) -> tuple[float, float]:
    """:func:`bare_replay_rate` and the same in steps per CPU second (the process's CPU
    time: what the steps cost, whatever share of the cores the machine gave them)."""
    m = tm.model
    d = tm.new_data()
    ids = tm.actuator_ids
    c0 = time.process_time()
    t0 = time.perf_counter()
    for f in forces:
        d.ctrl[ids] = f
        for _ in range(spt):
            mujoco.mj_step(m, d)
    n = len(forces) * spt
    return n / (time.perf_counter() - t0), n / max(time.process_time() - c0, 1e-9)


def plain_batch_rate(tm, n: int, threads: int, nstep: int) -> float:
    """Physics steps per second of ``mujoco.batch.Batch`` stepping ``n`` copies of the
    same model with no callback and no controls (MuJoCo's own batch, nothing of the twin):
    the ceiling the twin's batch can reach on this machine."""
    from mujoco import batch as mjbatch

    m = tm.model
    d = tm.new_data()
    row = np.empty(mujoco.mj_stateSize(m, _INTEGRATION))
    mujoco.mj_getState(m, d, row, _INTEGRATION)
    b = mjbatch.Batch(m, n, threads)
    b.state[:] = row
    b.step(nstep=8)  # threads started, MjData touched
    t0 = time.perf_counter()
    b.step(nstep=nstep)
    return n * nstep / (time.perf_counter() - t0)


def plain_step_rate(tm, nstep: int) -> float:
    """Physics steps per second of ``mj_step(m, d, nstep)`` on the same state as
    :func:`plain_batch_rate` (one thread, no Python between steps)."""
    m = tm.model
    d = tm.new_data()
    mujoco.mj_step(m, d, 8)
    t0 = time.perf_counter()
    mujoco.mj_step(m, d, nstep)
    return nstep / (time.perf_counter() - t0)


_INTEGRATION = int(mujoco.mjtState.mjSTATE_INTEGRATION)


#: alternated repetitions of the single-simulation measurement (bare / callback / bare)
REPEATS = 3


def callback_vs_bare(tm, ref, forces, repeats: int = REPEATS) -> dict:
    """The callback route's wall time per physics step over the bare ``mj_step`` of the
    same model on the same forces (``forces``: the loop's actuator forces on ``ref``),
    ``repeats`` alternations of bare replay / callback run / bare replay; each ratio
    against the bare steps timed beside it, the median repetition reported (single
    readings on a shared 2-core VM vary by +-15 %)."""
    sim = Simulation(tm)
    sim.reset()
    run_callback(sim, ref, duration_s=0.2)  # the model compiled with its userdata, the kernels warm
    ratios, cb_us, bares, cpus, cpu_ratios = [], [], [], [], []
    for _ in range(repeats):
        rate0, cpu0 = bare_replay(tm, forces, sim.steps_per_tick)
        sim.reset()
        cb = run_callback(sim, ref)  # CPU: the stepping's and the channels' (as its wall time counts)
        cb_cpu = (cb.timing["callback_cpu_s"] + cb.timing["output_s"]) / cb.timing["steps"] * 1e6
        rate1, cpu1 = bare_replay(tm, forces, sim.steps_per_tick)
        b_us = 2e6 / (rate0 + rate1)  # before and after the callback run
        cb_us.append(cb.wall_s / cb.timing["steps"] * 1e6)
        ratios.append(cb_us[-1] / b_us)
        bares.append(b_us)
        cpus.append(2e6 / (cpu0 + cpu1))
        cpu_ratios.append(cb_cpu / cpus[-1])
    k = int(np.argsort(ratios)[len(ratios) // 2])  # the median repetition
    return {
        "bare_us": bares[k],
        "bare_cpu_us": float(np.median(cpus)),
        "callback_us": cb_us[k],
        "callback_ratio": ratios[k],
        "callback_ratios": ratios,
        "callback_cpu_ratio": float(np.median(cpu_ratios)),  # CPU time per step over the bare's: robust to the load
        "sim_s": cb.sim_s,
    }


def main(tm, ref, *, batch_seconds: float = 0.5, sizes=(1, 8, 32, 128), threads: int | None = None) -> dict:
    threads = threads or usable_cores()
    control_callback()  # compile / load outside the timings
    sim = Simulation(tm)
    sim.reset()
    loop = sim.run(reference=ref)
    cvb = callback_vs_bare(tm, ref, loop.channels["actuator_force"])
    bare_us, bare_cpu_us, ratios = cvb["bare_us"], cvb["bare_cpu_us"], cvb["callback_ratios"]
    out = {
        "bare_us": bare_us,
        "bare_cpu_us": bare_cpu_us,
        "loop_us": loop.wall_s / loop.timing["steps"] * 1e6,
        "callback_us": cvb["callback_us"],
        "callback_ratios": ratios,
        "threads": threads,
        "batches": {},
        "load_before": os.getloadavg()[0],
    }
    out["loop_ratio"] = out["loop_us"] / bare_us
    out["callback_ratio"] = cvb["callback_ratio"]
    print(
        f"single simulation, {cvb['sim_s']:.1f} s of El Centro: bare mj_step (same model, same forces) {bare_us:.1f} us; "
        f"Python loop {out['loop_us']:.1f} us/step ({out['loop_ratio']:.2f} x); "
        f"callback route {out['callback_us']:.1f} us/step ({out['callback_ratio']:.2f} x, the median of "
        f"{REPEATS} alternated repetitions: {', '.join(f'{r:.2f}' for r in ratios)})"
    )
    print(
        f"batches on {threads} threads, {batch_seconds:g} s simulated each; efficiency = physics steps/s over "
        f"min(N, {threads}) x the bare mj_step rate (a batch of N < threads cannot use more than N threads); "
        "'MuJoCo alone' = the same batch of plain models (no callback, no controls) over min(N, threads) x "
        "mj_step(m, d, nstep) measured just before it: MuJoCo's own batch scaling on this machine now; "
        f"'CPU eff.' = the bare mj_step's CPU time per step ({bare_cpu_us:.1f} us) over the batch's (the work "
        "the batch adds, whatever the load); 'busy' = the batch's CPU time over wall time x min(N, threads) "
        "(the share of its threads' cores it got): efficiency ~ CPU eff. x busy"
    )
    print(
        f"  {'N':>5s} {'sim s / wall s':>15s} {'steps/s':>10s} {'efficiency':>10s} {'MuJoCo alone':>12s} "
        f"{'CPU eff.':>9s} {'busy':>6s}"
    )
    nstep = int(round(batch_seconds * sim.gains.rate_hz)) * sim.steps_per_tick
    for n in sizes:
        used = min(n, threads)
        one = plain_step_rate(tm, nstep)
        plain = plain_batch_rate(tm, n, threads, nstep) / (used * one)
        sims = [Simulation(tm) for _ in range(n)]
        runner = BatchRunner(sims, nthread=threads)
        res = runner.run([ref] * n, duration_s=batch_seconds)
        wall = runner.wall_s
        nsteps = sum(r.timing["steps"] for r in res)
        sps = nsteps / wall
        eff = sps / (used * 1e6 / bare_us)
        simps = sum(r.sim_s for r in res) / wall
        cpu_eff = bare_cpu_us / (runner.cpu_s / nsteps * 1e6)
        busy = runner.cpu_s / wall / used
        out["batches"][n] = {
            "sim_s_per_wall_s": simps,
            "steps_per_s": sps,
            "efficiency": eff,
            "mujoco_alone": plain,
            "cpu_efficiency": cpu_eff,
            "busy": busy,
        }
        print(f"  {n:5d} {simps:15.2f} {sps:10.0f} {eff:10.2f} {plain:12.2f} {cpu_eff:9.2f} {busy:6.2f}")
    out["load_after"] = os.getloadavg()[0]
    print(
        f"load average (1 min) {out['load_before']:.1f} before, {out['load_after']:.1f} after, on "
        f"{usable_cores()} cores (a load above the cores: other processes share them with the batch's threads)"
    )
    big = max(n for n in sizes if n >= 32) if any(n >= 32 for n in sizes) else max(sizes)
    out["summary_n"] = big
    return out


def cli(argv=None) -> int:
    """The batch block alone, on the 20 t scene: ``python -m bench.batch_bench [--threads T]
    [--sizes 1,16,64,256] [--seconds S] [--scene-seconds S]`` (e.g. 16 threads on a 16-core
    machine, beside MuJoCo's own batch of plain models)."""
    import argparse

    import mjcf
    from bench.__main__ import strong_motion
    from sim.effects import build_model

    ap = argparse.ArgumentParser(prog="python -m bench.batch_bench")
    ap.add_argument("--threads", type=int, default=None, help="batch threads (default: the cores)")
    ap.add_argument("--sizes", default="1,8,32,128", help="batch sizes N, comma-separated (default 1,8,32,128)")
    ap.add_argument("--seconds", type=float, default=0.5, help="simulated seconds per batch (default 0.5)")
    ap.add_argument("--scene-seconds", type=float, default=15.0, help="El Centro seconds of the single run")
    args = ap.parse_args(argv)
    sizes = tuple(int(x) for x in args.sizes.split(","))
    tm = build_model(mjcf.load_table("cgs"), mjcf.load_payload("rigid_20t"))
    b = main(tm, strong_motion(args.scene_seconds), batch_seconds=args.seconds, sizes=sizes, threads=args.threads)
    n = b["summary_n"]
    print(f"single loop / bare mj_step: {b['callback_ratio']:.3f}")
    print(f"batch efficiency ({n} sims, {b['threads']} threads): {b['batches'][n]['efficiency']:.3f}")
    return 0


__all__ = ["bare_rate", "callback_vs_bare", "cli", "main", "plain_batch_rate", "plain_step_rate"]

if __name__ == "__main__":
    import sys

    sys.exit(cli())
