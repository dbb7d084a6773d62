"""Figure of the worked example (docs/lab-example.md): the imported record against its
open-loop replays (as recorded, with the valve null removed, with the calibrated table).

    python scenarios/lab_example/figures.py RECORD.run.npz REPLAY.run.npz... --labels A B ... --out FIG.png
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))


def main(argv=None) -> int:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from sim.runs.runfile import read_run

    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("record")
    p.add_argument("replays", nargs="+")
    p.add_argument("--labels", nargs="+")
    p.add_argument("--out", required=True)
    p.add_argument(
        "--window", nargs=2, type=float, metavar=("T0", "T1"), help="time window shown (s; default the last 2 s)"
    )
    a = p.parse_args(argv)
    rec = read_run(a.record)
    reps = [read_run(r) for r in a.replays]
    labels = a.labels or [Path(r).name for r in a.replays]
    fig, ax = plt.subplots(3, 1, figsize=(9, 7.5), sharex=True)
    ax[0].plot(rec.t, 1e3 * rec.table_displacement[:, 0], "k", lw=1.2, label="record")
    ax[1].plot(rec.t, rec.table_acceleration[:, 0], "k", lw=1.2, label="record")
    ax[2].plot(rec.t, 1e-3 * rec.actuator_force[:, 0], "k", lw=1.2, label="record")
    for r, lab in zip(reps, labels):
        x = r.dofs.index("x")
        ax[0].plot(r.t, 1e3 * r.table_displacement[:, x], lw=0.9, label=lab)
        ax[1].plot(r.t, r.table_acceleration[:, x], lw=0.9, label=lab)
        ax[2].plot(r.t, 1e-3 * r.actuator_force[:, 0], lw=0.9, label=lab)
    ax[0].set_ylabel("table displacement (mm)")
    ax[1].set_ylabel("table acceleration (m/s$^2$)")
    ax[2].set_ylabel("actuator force (kN)")
    ax[2].set_xlabel("t (s)")
    # the last 2 s by default: the detail after the drift has had time
    ax[1].set_xlim(*(a.window or (rec.t[-1] - 2.0, rec.t[-1])))
    ax[0].legend(loc="upper left", fontsize=8)
    fig.suptitle(f"worked example: {Path(a.record).name} (204.8 Hz) and open-loop replays", fontsize=10)
    fig.tight_layout()
    fig.savefig(a.out, dpi=90)
    print(a.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
