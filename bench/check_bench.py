"""The loop's divergence check, piece by piece (microseconds per call, best of 5).

    python -m bench.check_bench

The loop checks every ``gap_every`` (8) recorded samples, i.e. every 16 physics steps
of the CGS table. Before (last session): the swivel gap (compiled), MuJoCo's warning
counters read one by one through pybind (five ``d.warning[w].number``), a compiled
finiteness test, four numpy reductions on the chamber pressures. Now: the gap, then one
compiled call (:func:`sim.loop._kernels.healthy`) on the raw arrays with the warning
counters as a view (``d.warning.number``); the messages (``Simulation._check``) only
when that fails. The figures are timings side by side on this machine, not promises.
"""

from __future__ import annotations

import math
import sys
import timeit

import numpy as np

import mjcf
from sim.effects import build_model
from sim.loop.simulation import MJ_WARNINGS, Simulation


def parts(number: int = 20000) -> dict:
    """Cost of each piece of the check on the bare CGS table at rest (us per call)."""
    sim = Simulation(build_model(mjcf.load_table("cgs")))
    d, st, fl = sim.d, sim.hs.state, sim._fl
    lo, hi = sim._pressure_limits()
    wnum, widx = d.warning.number, sim._warn_idx
    w0 = wnum[widx].copy()
    sim._warn0 = [int(v) for v in w0]
    qa = np.asarray(sim.tm.stroke_qadr, dtype=np.int64)

    def t(f) -> float:
        f()
        return min(timeit.repeat(f, number=number, repeat=5)) / number * 1e6

    return {
        "swivel gap (compiled, both)": t(sim.loop_gap),
        "before: warning counters, 5 pybind reads": t(
            lambda: [w for w, n0 in zip(MJ_WARNINGS, sim._warn0) if d.warning[w].number > n0]
        ),
        "before: all_finite (compiled)": t(lambda: fl.all_finite(d.qpos, d.qvel, st.p_a, st.p_b)),
        "before: pressure range, 4 numpy reductions": t(
            lambda: (
                st.p_a.max() <= hi
                and st.p_b.max() <= hi
                and st.p_a.min() >= lo
                and st.p_b.min() >= lo
                and math.isfinite(st.p_supply[0])
            )
        ),
        "now: healthy (one compiled call, all of it)": t(
            lambda: fl.healthy(d.qpos, d.qvel, st.p_a, st.p_b, st.p_supply, lo, hi, wnum, widx, w0, qa, math.inf)
        ),
        "the messages (Simulation._check, on failure only)": t(lambda: sim._check(0.0, 0.0)),
    }


def main() -> int:
    from bench.__main__ import bare_step_us

    p = parts()
    before = sum(v for k, v in p.items() if k.startswith("before")) + p["swivel gap (compiled, both)"]
    now = p["now: healthy (one compiled call, all of it)"] + p["swivel gap (compiled, both)"]
    for k, v in p.items():
        print(f"  {k:52s} {v:7.2f} us")
    step = bare_step_us(build_model(mjcf.load_table("cgs")).model)
    print(f"  check every 16 physics steps: before {before:.2f} us, now {now:.2f} us; bare mj_step {step:.1f} us")
    print(
        f"  the check's share of the loop per physics step (ratio* points): before {before / 16 / step:.4f}, now {now / 16 / step:.4f}"
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
