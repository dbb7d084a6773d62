"""Sweep files: one scenario, the inputs to vary (a grid, or random draws with a seed).

A sweep file (TOML)::

    [sweep]
    name = "mc_20t"                 # folder name of the results (default: the file's stem)
    scenario = "elcentro_20t"       # scenario name or path (relative to the sweep file)
    duration_s = 5.0                # optional: simulate S seconds (of a record: its strong motion)
    start_s = 20.0                  # optional: start there in the motion instead (scenario.start_s)
    task = 8                        # optional: cases dealt to a worker process at once (local or Dask)
    batch = 8                       # optional: cases simulated together on one batch (default: the task)
    iterations = 0                  # optional: drive iterations per case (default: the scenario's)
    mode = "random"                 # "grid" (every combination) or "random"
    n = 1000                        # random: number of cases
    seed = 7                        # random: the draws' seed
    run_files = false               # also write each case's run file

    [[vary]]                        # one varied input (a grid takes `values`)
    name = "payload_mass"           # column name (default: the first key)
    keys = ["payload.mass_kg", "payload.inertia_kg_m2"]   # one draw applied to each key
    scale = true                    # the draw multiplies the file's values (false: sets them)
    distribution = "uniform"        # random: uniform (low, high) | normal (mean, std) | lognormal (mean, std of log)
    low = 0.8
    high = 1.2

Keys are those of :mod:`sim.scenario.overrides`. Every key is checked; an error names
the file, the field and the fix in one line. ``task`` and ``batch`` only change how the
cases are dealt out (:mod:`sim.sweep.split`), never a result; left out, they are chosen
from the machine and the case count. The old ``group`` (which meant both: cases per Dask
task and per local batch) still loads, as ``task``, with a warning.
"""

from __future__ import annotations

import itertools
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from mjcf.description import load_toml
from sim.errors import UserError

_SWEEP_KEYS = {
    "name", "scenario", "duration_s", "start_s", "task", "batch", "group", "iterations", "mode", "n", "seed", "run_files",
}  # fmt: skip
#: the warning of a file with the old key ``group``
GROUP_DEPRECATED = (
    "'sweep.group' is deprecated (it meant both cases per Dask task and cases per local batch); "
    "read as 'task' (cases dealt to a worker process at once); write 'task = {n}' instead "
    "(and 'batch' for cases simulated together)"
)
_VARY_KEYS = {"name", "key", "keys", "scale", "values", "distribution", "low", "high", "mean", "std"}
_DISTS = {"uniform": ("low", "high"), "normal": ("mean", "std"), "lognormal": ("mean", "std")}


class SweepError(UserError):
    """A sweep file with a missing, unknown or invalid field."""


@dataclass
class Vary:
    name: str
    keys: list
    scale: bool
    values: list | None = None
    distribution: str | None = None
    params: dict = field(default_factory=dict)


@dataclass
class Case:
    """One simulation of a sweep: ``id`` (folder/row name), the varied ``values`` by
    column name, and the ``overrides`` handed to :func:`sim.assess.run.run_scenario`."""

    id: str
    values: dict
    overrides: dict


@dataclass
class Sweep:
    name: str
    scenario: str
    duration_s: float | None
    iterations: int | None
    mode: str
    n: int
    seed: int
    run_files: bool
    vary: list
    path: Path | None = None
    start_s: float | None = None  #: where each run starts in the motion (None: the strong motion of a record)
    task: int | None = None  #: cases dealt to a worker process at once (None: chosen by sim.sweep.split)
    batch: int | None = None  #: cases simulated together on one batch (None: the task)
    warnings: list = field(default_factory=list)  #: what the file should change (one line each, with the file)

    def cases(self) -> list[Case]:
        """Every case, in a fixed order (the same file always gives the same cases)."""
        if self.mode == "grid":
            combos = list(itertools.product(*[v.values for v in self.vary]))
        else:
            rng = np.random.default_rng(self.seed)
            cols = []
            for v in self.vary:
                p = v.params
                if v.distribution == "uniform":
                    cols.append(rng.uniform(p["low"], p["high"], self.n))
                elif v.distribution == "normal":
                    cols.append(rng.normal(p["mean"], p["std"], self.n))
                else:
                    cols.append(rng.lognormal(p["mean"], p["std"], self.n))
            combos = [tuple(float(c[i]) for c in cols) for i in range(self.n)]
        width = max(5, len(str(len(combos))))
        out = []
        for i, combo in enumerate(combos):
            ov, vals = {}, {}
            for v, x in zip(self.vary, combo):
                vals[v.name] = x
                for k in v.keys:
                    ov[k] = {"scale": x} if v.scale else x
            out.append(Case(id=f"{i:0{width}d}", values=vals, overrides=ov))
        return out


def _number(x, where, *, positive=False, integer=False):
    ok = not isinstance(x, bool) and isinstance(x, int if integer else (int, float))
    if not ok or (positive and not x > 0):
        kind = "a positive " if positive else "a "
        raise SweepError(f"{where} must be {kind}{'integer' if integer else 'number'} (got {x!r})")
    return x


def load_sweep(path) -> Sweep:
    """Load and check a sweep file."""
    path = Path(path)
    src = str(path)
    data = load_toml(path, SweepError, "sweep file")
    bad = set(data) - {"sweep", "vary"}
    if bad:
        raise SweepError(f"{src}: unknown table '{sorted(bad)[0]}'; a sweep file has [sweep] and [[vary]]")
    sw = data.get("sweep")
    if not isinstance(sw, dict):
        raise SweepError(f"{src}: missing the [sweep] table (scenario, mode, ...)")
    bad = set(sw) - _SWEEP_KEYS
    if bad:
        raise SweepError(f"{src}: unknown key 'sweep.{sorted(bad)[0]}'; known: {', '.join(sorted(_SWEEP_KEYS))}")
    scen = sw.get("scenario")
    if not isinstance(scen, str):
        raise SweepError(f"{src}: 'sweep.scenario' must name a scenario (e.g. \"elcentro_20t\") or a .toml path")
    if scen.endswith(".toml") and not Path(scen).is_absolute():
        scen = str(path.parent / scen)
    mode = sw.get("mode", "grid")
    if mode not in ("grid", "random"):
        raise SweepError(f'{src}: \'sweep.mode\' must be "grid" or "random" (got {mode!r})')
    dur = sw.get("duration_s")
    if dur is not None:
        _number(dur, f"{src}: 'sweep.duration_s'", positive=True)
    start = sw.get("start_s")
    if start is not None:
        _number(start, f"{src}: 'sweep.start_s'")
        if start < 0:
            raise SweepError(f"{src}: 'sweep.start_s' must be 0 or more seconds into the motion (got {start!r})")
    task, batch, warns = _dealing(sw, src)
    it = sw.get("iterations")
    if it is not None:
        _number(it, f"{src}: 'sweep.iterations'", integer=True)
    n = sw.get("n", 0)
    seed = sw.get("seed", 0)
    if mode == "random":
        if "n" not in sw or "seed" not in sw:
            raise SweepError(f"{src}: a random sweep needs 'sweep.n' (cases) and 'sweep.seed' (the draws' seed)")
        _number(n, f"{src}: 'sweep.n'", positive=True, integer=True)
        _number(seed, f"{src}: 'sweep.seed'", integer=True)
    run_files = sw.get("run_files", False)
    if not isinstance(run_files, bool):
        raise SweepError(f"{src}: 'sweep.run_files' must be true or false")
    vary_raw = data.get("vary")
    if not isinstance(vary_raw, list) or not vary_raw:
        raise SweepError(f"{src}: no [[vary]] table; add one per varied input (keys, values or distribution)")
    vary = []
    for i, v in enumerate(vary_raw, start=1):
        where = f"{src}: [[vary]] #{i}"
        bad = set(v) - _VARY_KEYS
        if bad:
            raise SweepError(f"{where}: unknown key '{sorted(bad)[0]}'; known: {', '.join(sorted(_VARY_KEYS))}")
        keys = v.get("keys", [v["key"]] if "key" in v else None)
        if not isinstance(keys, list) or not keys or not all(isinstance(k, str) for k in keys):
            raise SweepError(f"{where}: give 'key' (text) or 'keys' (list of text), e.g. key = \"payload.mass_kg\"")
        scale = v.get("scale", False)
        if not isinstance(scale, bool):
            raise SweepError(f"{where}: 'scale' must be true or false")
        item = Vary(name=str(v.get("name", keys[0])), keys=keys, scale=scale)
        if mode == "grid":
            vals = v.get("values")
            if not isinstance(vals, list) or not vals:
                raise SweepError(f"{where}: a grid sweep needs 'values' (a non-empty list)")
            item.values = [_number(x, f"{where}: 'values'") for x in vals]
        else:
            dist = v.get("distribution")
            if dist not in _DISTS:
                raise SweepError(f"{where}: 'distribution' must be one of {', '.join(_DISTS)} (got {dist!r})")
            for p in _DISTS[dist]:
                if p not in v:
                    raise SweepError(f"{where}: distribution '{dist}' needs '{p}'")
                item.params[p] = float(_number(v[p], f"{where}: '{p}'"))
            if dist == "uniform" and not item.params["high"] > item.params["low"]:
                raise SweepError(f"{where}: 'high' must be above 'low'")
            item.distribution = dist
        vary.append(item)
    names = [v.name for v in vary]
    if len(set(names)) != len(names):
        raise SweepError(f"{src}: two [[vary]] tables have the column name '{names[0]}'; give each a 'name'")
    return Sweep(
        name=str(sw.get("name", path.stem)),
        scenario=scen,
        duration_s=dur,
        iterations=it,
        mode=mode,
        n=int(n),
        seed=int(seed),
        run_files=run_files,
        vary=vary,
        path=path,
        start_s=None if start is None else float(start),
        task=task,
        batch=batch,
        warnings=warns,
    )


def _dealing(sw: dict, src: str) -> tuple:
    """``task`` and ``batch`` of the [sweep] table ``sw`` (the old ``group`` read as
    ``task``, with a warning) and the warnings."""
    for key in ("task", "batch", "group"):
        if sw.get(key) is not None:
            _number(sw[key], f"{src}: 'sweep.{key}'", positive=True, integer=True)
    task, warns = sw.get("task"), []
    if "group" in sw:
        if task is not None:
            raise SweepError(
                f"{src}: 'sweep.group' and 'sweep.task' both given; remove 'group' (the old name of 'task')"
            )
        task = sw["group"]
        warns.append(f"{src}: " + GROUP_DEPRECATED.format(n=task))
    batch = sw.get("batch")
    if task is not None and batch is not None and batch > task:
        raise SweepError(
            f"{src}: 'sweep.batch' ({batch}) is more than 'sweep.task' ({task}); a batch is part of a task"
        )
    return task, batch, warns


__all__ = ["GROUP_DEPRECATED", "Case", "Sweep", "SweepError", "Vary", "load_sweep"]
