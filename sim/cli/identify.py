"""``shaketable identify``: a uni-axial table's mechanical model by least squares on run
files (the LHPOST paper's method). The papers' whole programmes run under
``shaketable characterize`` (sim/cli/characterize.py)."""

from __future__ import annotations

import sys
from pathlib import Path

from sim.errors import UserError
from sim.runs.files import json_text


def add_parsers(sub) -> None:
    p = sub.add_parser("identify", help="identify a uni-axial table's mechanical model from run files")
    p.add_argument("runs", nargs="+", metavar="RUN", help="run files (.run.npz), pooled")
    p.add_argument(
        "--model",
        required=True,
        choices=["ucsd-ls"],
        help="ucsd-ls: M u'' + K u + C |u'|^alpha sign u' + F sign u' = F_act by least squares (the LHPOST paper)",
    )
    p.add_argument("--alpha", type=float, default=0.5, help="power-law exponent (default 0.5, as the LHPOST paper)")
    p.add_argument("--scan-alpha", action="store_true", help="also print the error for alpha = 0.1 ... 1.0")
    p.add_argument("--ce", type=float, metavar="N(s/m)^a", help="constrain C_e to this value (the LHPOST paper: 45900)")
    p.add_argument(
        "--weights",
        default="force",
        choices=["force", "unit", "velocity", "velocity_sqrt"],
        help="per-test weights (default force: 1/int F^2 dt, every test counts alike)",
    )
    p.add_argument(
        "--accel-lowpass",
        "--force-lowpass",
        dest="accel_lowpass",
        type=float,
        metavar="HZ",
        help="the accelerometers' analog low-pass (4-pole Butterworth, e.g. 100 for the LHPOST): "
        "the force and the other regressors are passed through the same filter",
    )
    p.add_argument(
        "--deadband",
        type=float,
        default=0.0,
        metavar="M/S",
        help="leave out samples with |velocity| below this (stick at reversals, sign of the "
        "velocity noise); e.g. 0.001 for the LHPOST (4 x its velocity noise). Default 0",
    )
    p.add_argument("--no-trim", action="store_true", help="keep the rest before and after the motion")
    p.add_argument(
        "--holdout",
        nargs="+",
        metavar="RUN",
        default=[],
        help="runs NOT fitted: the identified model is scored on them (its normalised force error per run)",
    )
    p.add_argument("--json", action="store_true", help="print JSON")
    p.set_defaults(func=cmd_identify)


def cmd_identify(args) -> int:
    from sim.identify import least_squares as I

    if not (0.0 < args.alpha <= 2.0):
        raise UserError(f"--alpha must be in (0, 2] (got {args.alpha:g})")
    if args.deadband < 0:
        raise UserError(f"--deadband must be >= 0 (got {args.deadband:g})")
    fitted = {str(Path(p).resolve()) for p in args.runs}
    both = [h for h in args.holdout if str(Path(h).resolve()) in fitted]
    if both:
        raise UserError(f"{both[0]}: is both a fitted run and a --holdout run; hold out runs that are not fitted")
    recs = _records(args, args.runs)
    held = _records(args, args.holdout)
    try:
        res = I.identify(recs, args.alpha, weights=args.weights, ce_fixed=args.ce)
    except Exception as e:  # singular normal equations: no motion, or a constant velocity sign
        raise UserError(
            f"the least squares has no unique solution for these runs ({e}); give tests with motion in both directions"
        ) from None
    scan = I.scan_alpha(recs, weights=args.weights, ce_fixed=args.ce) if args.scan_alpha else []
    ho = I.holdout_errors(res, held)
    for w in res.warnings():
        print(f"warning: {w}", file=sys.stderr)
    if args.json:
        out = {k: v for k, v in res.as_dict().items()}
        if held:
            out["holdout_error"] = ho
        if scan:
            out["alpha_scan"] = [{"alpha": s.alpha, "error": s.error} for s in scan]
        print(json_text(out, indent=1))
        return 0
    print(
        f"ucsd-ls on {len(recs)} run(s), alpha = {res.alpha:g}, weights {res.weights}"
        f"{', C_e constrained' if res.constrained else ''}"
    )
    print(f"  M_e   = {res.M_e_kg / 1e3:10.2f} t")
    print(f"  K_e   = {res.K_e_N_per_m / 1e6:10.4f} MN/m")
    print(f"  C_e   = {res.C_e / 1e3:10.2f} kN (s/m)^{res.alpha:g}")
    print(f"  F_mu  = {res.F_mu_N / 1e3:10.2f} kN")
    print(f"  error = {res.error:10.4f} (normalised force error, Eq. 2)")
    for name, e in res.per_test_error.items():
        print(f"    {e:8.4f}  {name}")
    if held:
        print("  held out (not fitted): normalised force error with these parameters")
        for name, e in ho.items():
            print(f"    {e:8.4f}  {name}")
    for s in scan:
        print(f"  alpha {s.alpha:.1f}: error {s.error:.4f}")
    return 0


def _records(args, paths) -> list:
    """The prepared least-squares records of run files (one-line error for a missing file)."""
    from sim.identify import least_squares as I

    recs = []
    for path in paths:
        if not Path(path).is_file():
            raise UserError(f"{path}: no such run file")
        r = I.record_from_run(path)
        trim = None if args.no_trim else 0.01
        recs.append(I.prepare(r, trim=trim, accel_lowpass_hz=args.accel_lowpass, deadband_m_s=args.deadband))
    return recs
