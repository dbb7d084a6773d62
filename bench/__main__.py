"""``make bench``: real-time factors and per-step costs, measured in one run.

    python -m bench [--quick] [--with-recording]

For each scene (bare CGS table, 20 t rigid specimen, 3-storey frame, 6 m tower):

* the bare ``mj_step`` of the model (random actuator forces), microseconds;
* the whole coupled loop on the strong-motion part of El Centro (80 %, 3 components):
  real-time factor and the ratio whole loop / bare ``mj_step`` (target <= 1.3) of the
  default loop, and the same run unfused (``fuse=False``) for the cost per physics step
  split into physics / hydraulics / controller / output;
* the default single-run route of ``shaketable run`` (the callback route where the
  table allows it, :mod:`sim.loop.callback`) per physics step over the bare ``mj_step``
  of the same model on the same actuator forces (target <= 1.10), the median of three
  alternated repetitions, and the worst scene's figure in one line;
* the hydraulic step alone (12 actuators and a 64 x 12 batch, numba and numpy);
* the coupled step inside MuJoCo and the batch (``bench/batch_bench.py``), with two
  lines a script can read: ``single loop / bare mj_step: X`` (the callback route, 20 t
  scene) and ``batch efficiency (N sims, T threads): Y``;
* the sweep's scaling over worker processes (``bench/sweep_bench.py``), ending with the
  line ``sweep efficiency (N cases, P workers): Z``.

All figures come from this one run on this machine; they are ratios of timings taken
side by side, not absolute promises.
"""

from __future__ import annotations

import argparse
import sys
import time
from math import nan

import mujoco
import numpy as np

import mjcf
from sim.effects import build_model
from sim.loop.simulation import Simulation
from sim.scenario.files import DOFS
from sim.scenario.records import el_centro_motions
from sim.scenario.reference import Reference

SCENES = [
    ("bare", None),
    ("rigid 20 t", "rigid_20t"),
    ("3-storey frame", "frame_3storey_297"),
    ("6 m tower", "tower_6m"),
]


def bare_step_us(model, n=4000) -> float:
    d = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, d, 0)
    rng = np.random.default_rng(0)
    forces = rng.normal(0, 5e4, (64, model.nu))
    for _ in range(200):
        mujoco.mj_step(model, d)
    t = time.perf_counter()
    for i in range(n):
        d.ctrl[:] = forces[i & 63]
        mujoco.mj_step(model, d)
    return (time.perf_counter() - t) / n * 1e6


def strong_motion(seconds: float) -> Reference:
    rate = 1024.0
    mos = el_centro_motions(sample_rate_hz=rate, amplitude_factor=0.8)
    n = len(next(iter(mos.values())).t)
    D = np.zeros((n, 6))
    V = np.zeros((n, 6))
    A = np.zeros((n, 6))
    for dof, m in mos.items():
        i = DOFS.index(dof)
        D[:, i], V[:, i], A[:, i] = m.d, m.v, m.a
    # start where the motion is quiet just before the strong part, at rest offset removed
    i0 = int(np.argmax(np.abs(A[:, 0]) > 0.05 * np.abs(A[:, 0]).max()))
    sl = slice(i0, min(n, i0 + int(seconds * rate) + 1))
    D, V, A = D[sl] - D[sl][0], V[sl], A[sl]
    return Reference(t=np.arange(len(D)) / rate, d=D, v=V, a=A)


def loop_figures(tm, ref) -> dict:
    """The default (fused) loop for the real-time factor and the ratios; the same run
    with ``fuse=False`` (one compiled call per stage) for the cost split."""
    sim = Simulation(tm)
    for fuse in (True, False):  # warm the compiled kernels
        sim.reset()
        sim.run(reference=ref, duration_s=0.5, fuse=fuse)
    sim.reset()
    res = sim.run(reference=ref)
    sim.reset()
    split = sim.run(reference=ref, fuse=False)
    default = default_route(tm, ref, res)
    steps = res.timing["steps"]
    ts, ss = split.timing, split.timing["steps"]
    return {
        "rtf": res.realtime_factor,
        "wall_per_step_us": res.wall_s / steps * 1e6,
        "physics_us": res.timing["physics_s"] / steps * 1e6,
        "split_wall_per_step_us": split.wall_s / ss * 1e6,
        "split_physics_us": ts["physics_s"] / ss * 1e6,
        "hydraulics_us": ts["hydraulics_s"] / ss * 1e6,
        "controller_us": ts["controller_s"] / ss * 1e6,
        "output_us": ts["output_s"] / ss * 1e6,
        **default,
    }


#: seconds of each scene's run timed for the default route (three alternated repetitions)
DEFAULT_ROUTE_S = 5.0


def default_route(tm, ref, loop) -> dict:
    """``shaketable run``'s default route on this model (the callback where it accepts
    the simulation, else the loop) per physics step over the bare ``mj_step`` on the
    loop's actuator forces (:func:`bench.batch_bench.callback_vs_bare`)."""
    from bench.batch_bench import bare_replay_rate, callback_vs_bare
    from sim.loop.callback import accepts

    sim = Simulation(tm)
    n = min(len(ref.t), int(DEFAULT_ROUTE_S * sim.gains.rate_hz) + 1)  # the first seconds: 3 repetitions fit
    ref = Reference(t=ref.t[:n], d=ref.d[:n], v=ref.v[:n], a=ref.a[:n])
    if accepts(sim) is None:
        cvb = callback_vs_bare(tm, ref, loop.channels["actuator_force"][:n])
        return {
            "route": "callback",
            "default_ratio": cvb["callback_ratio"],
            "default_us": cvb["callback_us"],
            "default_cpu_ratio": cvb["callback_cpu_ratio"],
        }
    bare_us = 1e6 / bare_replay_rate(tm, loop.channels["actuator_force"][:n], sim.steps_per_tick)
    per_step = loop.wall_s / loop.timing["steps"] * 1e6
    return {"route": "loop", "default_ratio": per_step / bare_us, "default_us": per_step, "default_cpu_ratio": nan}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m bench")
    ap.add_argument("--quick", action="store_true", help="shorter runs")
    ap.add_argument("--with-recording", action="store_true", help="also time the rerun recording overhead")
    ap.add_argument("--no-dask", action="store_true", help="leave the Dask LocalCluster out of the sweep's scaling")
    args = ap.parse_args(argv)
    secs = 5.0 if args.quick else 15.0
    desc = mjcf.load_table("cgs")
    ref = strong_motion(secs)
    print(
        f"shaketable bench: CGS table, El Centro 80 % strong motion, {secs:.0f} s simulated per scene; "
        f"physics step {1e3 / 2048:.3f} ms (2048 Hz), controller/recorder 1024 Hz"
    )
    print(
        f"{'scene':16s} {'mj_step':>8s} {'loop/step':>9s} {'ratio':>6s} {'ratio*':>6s} {'RTF':>6s} | "
        f"{'unfused':>8s} {'ratio*':>6s} {'physics':>8s} {'hydr.':>7s} {'ctrl':>7s} {'output':>7s} | "
        f"{'default':>8s} {'us/step':>7s} {'/bare':>6s} {'CPU':>5s}  (us per physics step)"
    )
    worst = 0.0
    for label, payload in SCENES:
        tm = build_model(desc, mjcf.load_payload(payload) if payload else None)
        bare = bare_step_us(tm.model)
        f = loop_figures(tm, ref)
        worst = max(worst, f["default_ratio"])
        print(
            f"{label:16s} {bare:8.1f} {f['wall_per_step_us']:9.1f} {f['wall_per_step_us'] / bare:6.2f} "
            f"{f['wall_per_step_us'] / f['physics_us']:6.2f} "
            f"{f['rtf']:6.2f} | {f['split_wall_per_step_us']:8.1f} "
            f"{f['split_wall_per_step_us'] / f['split_physics_us']:6.2f} {f['split_physics_us']:8.1f} "
            f"{f['hydraulics_us']:7.1f} {f['controller_us']:7.1f} {f['output_us']:7.1f} | "
            f"{f['route']:>8s} {f['default_us']:7.1f} {f['default_ratio']:6.2f} {f['default_cpu_ratio']:5.2f}"
        )
        sys.stdout.flush()
    print(
        "ratio = loop per step / isolated mj_step (random forces); ratio* = loop per step / the mj_step calls "
        "inside the same loop (same motion, same solver work); target <= 1.3"
    )
    print(
        "default = shaketable run's route (callback: the coupled step inside mj_step); /bare = its wall time per "
        "physics step over the bare mj_step of the same model on the loop's actuator forces (the median of 3 "
        f"alternated repetitions of the first {DEFAULT_ROUTE_S:g} s); target <= 1.10; CPU = the same in CPU "
        "time per step (the median; steadier than wall time on a shared machine)"
    )
    print(f"default single-run route / bare mj_step (worst of {len(SCENES)} scenes): {worst:.3f}")
    print(
        "left: the default loop (recorder, controller and hydraulics fused into one compiled call per physics "
        "step); right: the same run unfused, one compiled call per stage, for the cost split"
    )
    print()
    from bench import hydraulics_bench

    hydraulics_bench.main()
    if args.with_recording:
        from bench import recording_bench

        recording_bench.main([])
    print()
    from bench import batch_bench

    tm = build_model(desc, mjcf.load_payload("rigid_20t"))
    b = batch_bench.main(
        tm, ref, batch_seconds=0.25 if args.quick else 0.5, sizes=(1, 8, 32) if args.quick else (1, 8, 32, 128)
    )
    n = b["summary_n"]
    print(f"single loop / bare mj_step: {b['callback_ratio']:.3f}")
    print(f"batch efficiency ({n} sims, {b['threads']} threads): {b['batches'][n]['efficiency']:.3f}")
    print()
    from bench import sweep_bench

    sw = sweep_bench.main(64, 2.0 if args.quick else 4.0, with_dask=not args.no_dask)
    p = sw["cores"]
    print(f"sweep efficiency ({sw['cases']} cases, {p} workers): {sw['local'][p]['efficiency']:.3f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
