"""The time series of a rerun recording: channels grouped into entities (one scalar per
series and row), their roles' colours, the display stride, and a compare run's samples
on this run's time. Used by :mod:`sim.report.rerun`."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

_C_REF = (150, 150, 150)
_C_ACH = (31, 119, 180)
_C_CMP = (255, 127, 14)
_C_RES = (214, 39, 40)
_C_B = (44, 160, 44)
_ROLE_COLORS = {"reference": _C_REF, "achieved": _C_ACH, "command": _C_REF, "spool": _C_ACH, "a": _C_ACH, "b": _C_B}
_CMP_SHADES = [_C_CMP, (140, 86, 75)]  # compare run: orange, brown
_RES_SHADES = [_C_RES, (148, 103, 189)]  # residual: red, purple


def _aligned(run, other_t: np.ndarray, other_vals: np.ndarray) -> np.ndarray:
    """``other_vals`` sampled at ``run.t`` (linear), NaN outside the other run's span."""
    t = run.t
    vals = np.atleast_2d(np.asarray(other_vals, dtype=float).T).T if other_vals.ndim == 1 else other_vals
    if len(other_t) == len(t) and np.allclose(other_t, t, rtol=0, atol=1e-9):
        return vals
    out = np.full((len(t), vals.shape[1]), np.nan)
    inside = (t >= other_t[0]) & (t <= other_t[-1])
    for j in range(vals.shape[1]):
        out[inside, j] = np.interp(t[inside], other_t, vals[:, j])
    return out


def _reference_acceleration(run) -> np.ndarray | None:
    if run.reference is None:
        return None
    dt = run.dt
    return np.gradient(np.gradient(run.reference, dt, axis=0), dt, axis=0)


@dataclass
class _Group:
    """Channels drawn together: one entity ``plots/<sub>``, one scalar per channel and row."""

    sub: str  # entity sub-path under plots/
    unit: str
    labels: list  # series names, one per column
    roles: list  # colour role per column (None: the viewer's own colours)
    values: np.ndarray  # (N, k)


def _channel_groups(run) -> list[_Group]:
    """The run's time series, grouped as they are drawn (see the module table)."""
    out = []
    dofs, acts = run.dofs, run.actuators

    def cols(*pairs):
        have = [(role, arr) for role, arr in pairs if arr is not None]
        return [r for r, _ in have], [a for _, a in have]

    ref_acc = _reference_acceleration(run)
    for j, d in enumerate(dofs):
        for q, unit, ref, ach in (
            ("displacement", "m or rad", run.reference, run.table_displacement),
            ("acceleration", "m/s² or rad/s²", ref_acc, run.table_acceleration),
        ):
            roles, arrs = cols(("reference", ref), ("achieved", ach))
            if roles:
                out.append(_Group(f"dof/{d}/{q}", unit, roles, roles, np.column_stack([a[:, j] for a in arrs])))
    for j, a in enumerate(acts):
        for q, unit, pairs in (
            ("valve", "fraction of rated opening", (("command", run.valve_command), ("spool", run.spool_position))),
            ("pressure", "Pa", (("a", run.pressure_a), ("b", run.pressure_b))),
        ):
            roles, arrs = cols(*pairs)
            if roles:
                out.append(_Group(f"actuators/{a}/{q}", unit, roles, roles, np.column_stack([x[:, j] for x in arrs])))
    for q, unit, arr in (("force", "N", run.actuator_force), ("stroke", "m", run.actuator_displacement)):
        if arr is not None:
            out.append(_Group(f"actuators/{q}", unit, list(acts), [None] * len(acts), np.asarray(arr, dtype=float)))
    if run.accelerometers is not None:
        names = run.column_names("accelerometers")
        out.append(
            _Group(
                "accelerometers", "m/s²", list(names), [None] * len(names), np.asarray(run.accelerometers, dtype=float)
            )
        )
    for key, where, unit in (
        ("supply_pressure", "hydraulics", "Pa"),
        ("accumulator_gas_volume", "hydraulics", "m³"),
        ("loop_gap", "model", "m"),
    ):
        if key in run.extras:
            arr = np.asarray(run.extras[key], dtype=float)
            out.append(
                _Group(f"{where}/{key}", unit, [key], ["achieved"], (arr if arr.ndim == 1 else arr[:, 0])[:, None])
            )
    return out


def _specimen_groups(run, compare=None) -> list[_Group]:
    """The specimen's sensors (``specimen_acceleration``), each drawn under the payload,
    ``payload/sensors/<name>/acceleration`` (not under plots/): the run's series and,
    when the compare run has a sensor of that name, its series beside it."""
    if run.specimen_acceleration is None:
        return []
    theirs = {}
    if compare is not None and compare.specimen_acceleration is not None:
        for j, nm in enumerate(compare.column_names("specimen_acceleration")):
            theirs[nm] = _aligned(run, compare.t, np.asarray(compare.specimen_acceleration, float)[:, [j]])[:, 0]
    out = []
    for j, nm in enumerate(run.column_names("specimen_acceleration")):
        labels, roles, cols = [nm], ["achieved"], [np.asarray(run.specimen_acceleration, float)[:, j]]
        if nm in theirs:
            labels, roles, cols = labels + [f"{nm} (compare)"], roles + [None], cols + [theirs[nm]]
        out.append(_Group(f"payload/sensors/{nm}/acceleration", "m/s²", labels, roles, np.column_stack(cols)))
    return out


def _role_colors(roles: list, kind: str) -> list | None:
    """One colour per column: the role's colour for this run, shades of orange / red for the
    compare run and the residual; None when the viewer should pick (one channel per actuator)."""
    if kind == "run":
        cols = [_ROLE_COLORS.get(r) if r is not None else None for r in roles]
        return None if any(c is None for c in cols) else cols
    if all(r is None for r in roles):
        return None
    shades = _CMP_SHADES if kind == "compare" else _RES_SHADES
    return [shades[i % len(shades)] for i in range(len(roles))]


def series_stride(sample_rate_hz: float, series_rate_hz: float | None) -> int:
    """Keep every n-th sample of a time series: the largest n whose rate is at least ``series_rate_hz``
    (1, the full rate, for None or a run sampled at or below it)."""
    if series_rate_hz is None or not (sample_rate_hz > series_rate_hz):
        return 1
    return max(1, int(np.floor(sample_rate_hz / series_rate_hz + 1e-9)))


# ---------------------------------------------------------------------- writer
