"""``shaketable feasibility`` as library calls: one case (:func:`assess`), the largest
amplitude scale (:func:`max_scale`), many cases (:func:`suite`).

A case is a table, a specimen (a payload description or None), a motion and an
amplitude scale. The motion is a built-in record by name (:data:`BUILTIN_RECORDS`), an
AT2 file (x), a folder of AT2 files (one per component: two horizontals -> x, y in name
order, the vertical -> z), or a scenario's ``[motion]``. The rated envelope is checked
on the whole scaled motion; the simulation (closed loop, with the drive iterations asked
for) runs on the whole motion or, with ``window_s``, on its strongest window: the
``window_s`` seconds holding the most Arias intensity, preceded by a 1 s lead-in in which
the reference is blended from rest into the record (a quintic that cancels the record's
displacement, velocity and acceleration at the start of the lead-in).

Every function returns data; :func:`assess` is a plain call on picklable inputs, so a
sweep can run it in parallel.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from mjcf.description import DOFS6
from sim.errors import UserError
from sim.parallel import usable_cores

#: Built-in records: name -> what it is. Aliases map to the same record.
BUILTIN_RECORDS = {"elcentro1940": "1940 Imperial Valley, El Centro Array #9 (PEER RSN6), 3 components"}
_ALIASES = {
    "elcentro1940": "elcentro1940",
    "elcentro": "elcentro1940",
    "el_centro_1940": "elcentro1940",
    "el_centro": "elcentro1940",
    "elcentro_1940": "elcentro1940",
}
LEAD_IN_S = 1.0  # run choice: blend from rest into the window over 1 s (well below the record's 0.1 Hz high-pass)


class CaseError(UserError):
    """A case that cannot be assessed as given (motion, scale, table)."""


@dataclass
class Case:
    """One feasibility case. ``payload``: a payload description or None (bare table)."""

    table: str
    motion: str | None = None
    payload: object = None
    scale: float = 1.0
    window_s: float | None = None
    iterations: int | None = None  #: drive iterations (None: the scenario's, or 0)
    scenario: object = None  #: a Scenario: its table, payload, motion, controller and iterations
    name: str = "feasibility"
    iteration: dict = field(default_factory=dict)


# ------------------------------------------------------------------ motions
def _vertical(path: Path, rec) -> bool:
    s = (path.stem + " " + str(rec.header.get("component", ""))).upper()
    return any(k in s for k in ("-UP", "_UP", " UP", "DWN", "-V.", "VERT", "-Z", "_V"))


def record_motions(spec: str, *, rate_hz: float) -> tuple[dict, str]:
    """{dof: Motion} at unit scale for a record name, an AT2 file or a folder of AT2
    files; and a label. Raises :class:`CaseError` for a wrong name or component count."""
    from sim.scenario import records as R

    key = _ALIASES.get(str(spec).lower().replace("-", "_").replace(" ", ""), None)
    if key == "elcentro1940":
        return R.el_centro_motions(sample_rate_hz=rate_hz), "elcentro1940"
    p = Path(spec)
    if p.is_dir():
        files = sorted(f for f in p.iterdir() if f.suffix.lower() == ".at2")
        if len(files) not in (1, 2, 3):
            raise CaseError(f"{p}: a record folder holds 1 to 3 .AT2 components (x, y, z); it has {len(files)}")
        recs = {f: R.read_at2(f) for f in files}
        vert = [f for f in files if _vertical(f, recs[f])]
        if len(vert) > 1:
            raise CaseError(f"{p}: more than one vertical component ({', '.join(f.name for f in vert)}); keep one")
        hor = [f for f in files if f not in vert]
        if len(hor) > 2:
            raise CaseError(
                f"{p}: {len(hor)} horizontal components and no vertical one (UP/DWN/V in the file name); "
                "name the vertical component or give 2 horizontals"
            )
        comps = dict(zip(("x", "y"), (recs[f] for f in hor)))
        if vert:
            comps["z"] = recs[vert[0]]
        return R.process_components(comps, sample_rate_hz=rate_hz), p.name
    if p.suffix.lower() == ".at2" or p.is_file():
        rec = R.read_at2(p)
        return {"x": R.process_record(rec.acceleration, rec.dt, sample_rate_hz=rate_hz, name=p.name)}, p.stem
    known = ", ".join(BUILTIN_RECORDS)
    raise CaseError(f"--motion {spec!r} is not a built-in record ({known}), an .AT2 file or a folder of .AT2 files")


def check_dofs(desc, motions: dict, where: str) -> None:
    """A motion in a DOF the table does not have is a user error."""
    for dof, m in motions.items():
        if dof not in desc.dofs and np.any(m.d != 0):
            raise CaseError(
                f"{where}: a motion in {dof} but table '{desc.name}' moves only {', '.join(desc.dofs)}; "
                f"give a motion in {', '.join(desc.dofs)} only"
            )


def scaled(motions: dict, scale: float) -> dict:
    return {d: m.scaled(scale) for d, m in motions.items()}


def strongest_window(motions: dict, window_s: float, lead_in_s: float = LEAD_IN_S) -> tuple[dict, float]:
    """The ``window_s`` seconds of the motions with the most Arias intensity (all DOFs),
    with a lead-in from rest (see the module docstring). Returns ({dof: Motion}, start
    time of the lead-in in the original motion)."""
    from sim.scenario.motions import Motion

    any_m = next(iter(motions.values()))
    rate = any_m.sample_rate_hz
    n = len(any_m.t)
    nw = int(round(window_s * rate))
    nl = int(round(lead_in_s * rate))
    if nw + nl >= n:
        return motions, 0.0
    ai = np.zeros(n)
    for m in motions.values():
        ai += m.a[:n] ** 2
    c = np.concatenate([[0.0], np.cumsum(ai)])
    gain = c[nw:] - c[:-nw]  # intensity in [i, i + nw)
    i0 = int(np.argmax(gain[nl:])) + nl
    s0 = i0 - nl
    t = np.arange(nw + nl) / rate
    tau = np.clip(t / lead_in_s, 0.0, 1.0)
    out = {}
    for dof, m in motions.items():
        d, v, a = m.d[s0 : s0 + nw + nl].copy(), m.v[s0 : s0 + nw + nl].copy(), m.a[s0 : s0 + nw + nl].copy()
        cd, cv, ca = _quintic_fade(d[0], v[0], a[0], tau, lead_in_s)
        out[dof] = Motion(
            t,
            d - cd,
            v - cv,
            a - ca,
            m.name + f" (window {s0 / rate:.1f} s + {lead_in_s + window_s:.1f} s)",
            dict(m.info, window_start_s=s0 / rate),
        )
    return out, s0 / rate


def _quintic_fade(d0, v0, a0, tau, T):
    """c(t) with c, c', c'' = d0, v0, a0 at t = 0 and 0 at t = T (tau = t / T), zero after."""
    # c(tau) = d0 h0 + v0 T h1 + a0 T^2 h2 with the quintic Hermite basis of the start point
    h0 = 1 - 10 * tau**3 + 15 * tau**4 - 6 * tau**5
    h1 = tau - 6 * tau**3 + 8 * tau**4 - 3 * tau**5
    h2 = 0.5 * tau**2 - 1.5 * tau**3 + 1.5 * tau**4 - 0.5 * tau**5
    dh0 = -30 * tau**2 + 60 * tau**3 - 30 * tau**4
    dh1 = 1 - 18 * tau**2 + 32 * tau**3 - 15 * tau**4
    dh2 = tau - 4.5 * tau**2 + 6 * tau**3 - 2.5 * tau**4
    ddh0 = -60 * tau + 180 * tau**2 - 120 * tau**3
    ddh1 = -36 * tau + 96 * tau**2 - 60 * tau**3
    ddh2 = 1 - 9 * tau + 18 * tau**2 - 10 * tau**3
    c = d0 * h0 + v0 * T * h1 + a0 * T * T * h2
    cv = (d0 * dh0 + v0 * T * dh1 + a0 * T * T * dh2) / T
    ca = (d0 * ddh0 + v0 * T * ddh1 + a0 * T * T * ddh2) / (T * T)
    done = tau >= 1.0
    return np.where(done, 0.0, c), np.where(done, 0.0, cv), np.where(done, 0.0, ca)


# ------------------------------------------------------------------ one case
@dataclass
class Prepared:
    """A case made ready: the table, the specimen, the motion at unit scale (whole and
    simulated window), the specimen checks and the interaction."""

    case: Case
    desc: object
    payload: object
    motions: dict
    window: dict
    window_start_s: float
    static: list
    interaction: dict | None
    plan: object = None  #: the ScenarioPlan of slot 0 (built once, re-used for every scale)
    buildable: bool = True
    spare_plans: list = field(default_factory=list)  #: more plans, one per scale simulated at the same time


def _scenario_for(case: Case, desc):
    from sim.scenario.files import Scenario

    if case.scenario is not None:
        return case.scenario
    from sim.control.base import controller_settings

    gains = controller_settings(desc, {})
    return Scenario(
        name=case.name,
        table=case.table,
        payload=None,
        duration_s=None,
        pad_to_duration=False,
        description=f"feasibility of {case.motion} on {desc.name}",
        motion={"type": "el_centro_1940"},
        controller={},
        sample_rate_hz=float(gains.rate_hz),
        iteration=dict(case.iteration, count=case.iterations or 0),
    )


def prepare(case: Case) -> Prepared:
    """Load and check everything of a case (no simulation yet)."""
    import mjcf
    from sim.assess.feasibility import specimen_checks
    from sim.assess.specimen import interaction
    from sim.scenario.files import build_motions

    if not (case.scale > 0 and np.isfinite(case.scale)):
        raise CaseError(
            f"--scale must be a positive amplitude factor (got {case.scale:g}); 1.0 is the record as recorded"
        )
    if case.window_s is not None and not case.window_s > 0:
        raise CaseError(f"--window must be a positive number of seconds (got {case.window_s:g})")
    sc = case.scenario
    desc = mjcf.load_table(sc.table if sc is not None else case.table)
    payload = case.payload
    if payload is None and sc is not None and sc.payload:
        payload = mjcf.load_payload(sc.payload)
    scen = _scenario_for(case, desc)
    if case.motion is not None:
        motions, _ = record_motions(case.motion, rate_hz=scen.sample_rate_hz)
        where = f"--motion {case.motion}"
    elif sc is not None:
        motions, where = build_motions(sc), str(sc.path or sc.name)
    else:
        raise CaseError("give a scenario or --motion (a record name such as elcentro1940, an .AT2 file or a folder)")
    check_dofs(desc, motions, where)
    motions = {d: m for d, m in motions.items() if d in desc.dofs}
    static = specimen_checks(desc, payload, bare_support_n=_bare_support(desc))
    buildable = all(c["pass"] for c in static if c["name"] == "support_load")
    inter = interaction(desc, payload) if (payload is not None and buildable) else None
    if case.window_s is not None:
        window, t0 = strongest_window(motions, case.window_s)
    else:
        window, t0 = motions, 0.0
    return Prepared(
        case=case,
        desc=desc,
        payload=payload,
        motions=motions,
        window=window,
        window_start_s=t0,
        static=static,
        interaction=inter,
        buildable=buildable,
    )


_BARE: dict = {}


def _bare_support(desc):
    if desc.supports is None:
        return None
    from sim.assess.feasibility import bare_support_load_n

    if desc.source not in _BARE:
        _BARE[desc.source] = bare_support_load_n(desc)
    return _BARE[desc.source]


def evaluate(prep: Prepared, scale: float, *, simulate: bool = True, progress=None) -> dict:
    """The verdict of a prepared case at ``scale``: specimen and envelope checks on the
    whole motion; if they pass (or always, with the specimen buildable and ``simulate``)
    the run checks of a closed-loop simulation of the window, run on the shared route
    of many runs (:func:`sim.assess.many.run_plans`; the batch where the table allows)."""
    from sim.assess.many import run_plans

    pre, plan = stage(prep, scale, simulate=simulate)
    if plan is None:
        return pre
    if progress:
        progress(f"simulating {plan.reference.t[-1]:.1f} s at scale {scale:.4g}")
    outcome = run_plans([plan], nthread=1)[0]
    if isinstance(outcome, UserError):
        raise outcome
    return settle(prep, scale, outcome)


def stage(prep: Prepared, scale: float, *, simulate: bool = True, slot: int = 0) -> tuple[dict | None, object]:
    """What a verdict at ``scale`` needs: ``(verdict, None)`` when it needs no simulation
    (the specimen cannot be built, or the checks on the whole motion fail and not
    ``simulate``), else ``(None, plan)``: the :class:`~sim.assess.run.ScenarioPlan` of
    the window at ``scale``, for :func:`settle` once run. ``slot``: which of the prepared
    case's simulations the plan uses (built on first use, re-used for later scales):
    plans of one case staged together need different slots to run together."""
    from sim.assess.feasibility import envelope_checks, verdict
    from sim.assess.run import plan_scenario
    from sim.scenario.reference import reference_from_motions

    rate = next(iter(prep.motions.values())).sample_rate_hz
    full = scaled(prep.motions, scale)
    length = max(m.duration_s for m in full.values())
    env_ref = reference_from_motions(full, rate, length)
    env = envelope_checks(prep.desc, env_ref)
    warns = list(prep.interaction["warnings"]) if prep.interaction else []
    if not prep.buildable or not simulate:
        out = verdict(prep.static + env, warns)
        out["simulated"] = False
        out["note"] = (
            "not simulated: the static supports cannot carry the specimen"
            if not prep.buildable
            else "not simulated: the specimen or envelope checks already fail"
        )
        out["scale"] = float(scale)
        return out, None
    win = scaled(prep.window, scale)
    wlen = max(m.duration_s for m in win.values())
    if prep.plan is None:
        prep.plan = plan_scenario(
            _scenario_for(prep.case, prep.desc), payload=prep.payload, motions=win, iterations=prep.case.iterations
        )
    while slot > len(prep.spare_plans):
        prep.spare_plans.append(
            plan_scenario(
                _scenario_for(prep.case, prep.desc), payload=prep.payload, motions=win, iterations=prep.case.iterations
            )
        )
    base = prep.plan if slot == 0 else prep.spare_plans[slot - 1]
    plan = replace(base, reference=reference_from_motions(win, rate, wlen), envelope_reference=env_ref, warnings=warns)
    return None, plan


def settle(prep: Prepared, scale: float, outcome) -> dict:
    """The verdict of a simulated :func:`stage` plan from its ``RunOutcome``."""
    fe = dict(outcome.summary["feasibility"])
    fe["simulated"] = True
    fe["scale"] = float(scale)
    fe["window_start_s"] = prep.window_start_s
    fe["simulated_s"] = float(outcome.result.sim_s)
    fe["wall_s"] = float(outcome.summary.get("wall_s_all_runs", outcome.result.wall_s))
    fe["_outcome"] = outcome
    return fe


def assess(case: Case, *, progress=None) -> dict:
    """The verdict of one case (see :func:`evaluate`), with the interaction figures."""
    prep = prepare(case)
    fe = evaluate(prep, case.scale, simulate=True, progress=progress)
    return _finish(prep, fe)


def _finish(prep: Prepared, fe: dict) -> dict:
    fe["table"] = prep.desc.name
    fe["payload"] = getattr(prep.payload, "name", None)
    fe["motion"] = prep.case.motion or (prep.case.scenario.name if prep.case.scenario else None)
    if prep.interaction is not None:
        fe["interaction"] = {k: v for k, v in prep.interaction.items() if k != "warnings"}
    return fe


# ------------------------------------------------------------------ largest scale
def max_scale(
    case: Case,
    *,
    rel_tol: float = 0.02,
    max_rounds: int | None = None,
    max_runs: int | None = None,
    progress=None,
    nthread: int = 0,
) -> dict:
    """The largest amplitude scale at which every check passes: a search on simulations
    in log scale, bracketed from the utilisations of the runs, run in rounds of up to
    ``k`` simulations together on the shared route of many runs
    (:func:`sim.assess.many.run_plans`; ``k`` = ``nthread`` threads, 0: all cores; 1
    where the table's runs cannot go on the batch, e.g. drive iterations).

    A round stages ``k`` scales at once, each on its own simulation of the prepared case:

    * the first round: ``case.scale``, and with ``k > 1`` up to ``k - 1`` scales spread
      (in log scale) from it up to just under the scale where the highest
      amplitude-driven utilisation of its checks on the whole motion (the rated
      envelope) reaches 100 % (the envelope fails above it without a simulation);
    * while only passing (failing) scales are known: the prediction from the
      utilisations of the largest passing (smallest failing) one, the scale at which the
      highest amplitude-driven utilisation would reach 100 % if it grew linearly, and
      ``k - 1`` points around it ``1 + rel_tol`` apart;
    * once bracketed: the ``k``-section of the bracket in log scale (fewer points when
      fewer close it to ``rel_tol``).

    With ``k = 1`` this is the bisection: the same scales, the same answer. The bracket
    is the smallest failing scale and the largest passing one below it.

    Scale-free failures (specimen mass, support load) give ``max_scale`` None. Checks on
    the whole motion (envelope) fail without a simulation, so only scales inside the
    rated envelope cost a run (a scale failing there lowers the bracket and the round is
    planned again). Stops when the bracket is within ``rel_tol``, after ``max_rounds``
    rounds or after ``max_runs`` simulations (a round runs at most the simulations
    left); with neither given, after 6 rounds (the one-at-a-time search's 6 runs: with
    ``k = 1`` the same budget; with ``k = 2`` on an idle 2-core machine the same wall
    time and a bracket closed where 6 single runs leave it open, measured in
    docs/feasibility.md).
    Returns the verdict at ``case.scale``, ``max_scale`` with its verdict (``at_max``),
    the limiting check just above it (``limiting_above``), ``max_scale_runs``
    (simulations) and ``max_scale_rounds`` (rounds of simulations run together).
    """
    if max_rounds is None and max_runs is None:
        max_rounds = 6
    round_cap = max_rounds if max_rounds is not None else 10**9
    run_cap = max_runs if max_runs is not None else 10**9
    prep = prepare(case)
    search = _ScaleSearch(prep, progress or (lambda text: None), nthread)
    s0 = float(case.scale)
    scale_free = [c["name"] for c in prep.static if not c["pass"]]
    needs, pre0 = search.free(s0)
    k = 1 if scale_free else _round_size(prep, s0, nthread)
    if needs:
        search.first_round(s0, pre0, k, rel_tol, run_cap)
    search.count["steps"] = 0
    first = search.cache[s0]
    result = _finish(prep, dict(first))
    if scale_free:  # the specimen cannot be built at any scale
        return _with_max(result, search, None, scale_free[0], scale_free[0])
    search.refine(k, rel_tol, run_cap, round_cap)
    lo, hi = _bracket(search.cache)
    if lo is None:  # even the smallest scale tried fails
        return _with_max(result, search, None, first["limiting"], search.cache[hi]["limiting"])
    above = search.cache.get(hi) if hi is not None else None
    at = search.cache[lo]
    if result.get("_outcome") is None and at.get("_outcome") is not None:
        result["_outcome"] = at["_outcome"]  # the report's figures: the run at the largest scale
        result["figures_scale"] = float(lo)
    limiting = at["limiting"] if above is None else _first_failed(above)
    upper = None if hi is None else float(hi)
    return _with_max(result, search, lo, limiting, None if above is None else _first_failed(above), at, upper)


def _round_size(prep: Prepared, s0: float, nthread: int) -> int:
    """How many simulations a round runs together: ``nthread`` (0: all cores) where the
    case's runs go on the batch, else 1 (e.g. drive iterations)."""

    from sim.assess.many import batchable

    _, plan0 = stage(prep, s0, simulate=True)
    return max(1, int(nthread or usable_cores())) if batchable(plan0) else 1


def _with_max(result: dict, search: "_ScaleSearch", lo, limiting, above, at=None, upper=...) -> dict:
    """``result`` with the search's answer: ``max_scale`` ``lo`` (None: none passes) and
    ``max_scale_upper`` (the smallest failing scale, when one passes), the check that
    limits it, the verdict there (``at``) and the check failing just above, with the
    simulations and rounds it took."""
    result["max_scale"] = None if lo is None else float(lo)
    if upper is not ...:
        result["max_scale_upper"] = upper
    result.update(
        max_scale_limiting=limiting,
        at_max=None if at is None else _strip(at),
        limiting_above=above,
        max_scale_runs=search.count["runs"],
        max_scale_rounds=search.count["rounds"],
    )
    return result


class _ScaleSearch:
    """The state of a :func:`max_scale` search on the prepared case ``prep``: every
    verdict so far by scale (``cache``: simulated, or failing without a simulation) and
    the simulations, rounds and steps counted."""

    def __init__(self, prep: Prepared, say, nthread: int):
        self.prep, self.say, self.nthread = prep, say, nthread
        self.cache: dict[float, dict] = {}
        self.count = {"runs": 0, "rounds": 0, "steps": 0}

    def free(self, s: float) -> tuple[bool, dict]:
        """(needs a simulation, the verdict of the checks without one) at ``s``."""
        pre = evaluate(self.prep, s, simulate=False)
        if pre["feasible"] and self.prep.buildable:
            return True, pre
        self.say(f"scale {s:.4g}: {pre['limiting']} fails without a simulation")
        self.cache[s] = pre
        self.count["steps"] += 1  # evaluations without a simulation are free; never loop for ever
        return False, pre

    def simulate(self, scales: list[float]) -> None:
        """One round: the simulations at ``scales`` together, their verdicts cached."""
        from sim.assess.many import run_plans

        staged = [stage(self.prep, s, simulate=True, slot=j) for j, s in enumerate(scales)]
        count = self.count
        count["runs"] += len(scales)
        count["rounds"] += 1
        count["steps"] += 1
        many = len(scales) > 1
        self.say(
            f"round {count['rounds']}: simulating scale{'s' if many else ''} "
            + ", ".join(f"{s:.4g}" for s in scales)
            + f" (run{'s' if many else ''} {count['runs'] - len(scales) + 1}"
            + (f"-{count['runs']})" if many else ")")
        )
        outs = run_plans([plan for _, plan in staged], nthread=self.nthread)
        for s, o in zip(scales, outs):
            if isinstance(o, UserError):
                raise o
            self.cache[s] = settle(self.prep, s, o)

    def first_round(self, s0: float, pre0: dict, k: int, rel_tol: float, run_cap: int) -> None:
        """``s0``, and with ``k > 1`` up to ``k - 1`` scales spread in log scale from it to
        just under where the rated envelope fails (from ``pre0``, the verdict at ``s0``)."""
        todo = [s0]
        n = min(k, run_cap) - 1
        if n > 0:
            u = _scaling_utilisation(pre0)
            top = (s0 / u if u > 0 else s0 * 4) * 0.995  # just under where the envelope fails
            if top > s0 * (1 + rel_tol):
                for s in (s0 * (top / s0) ** (j / n) for j in range(1, n + 1)):
                    if not self.free(s)[0]:  # the envelope is linear in the scale: not expected
                        break
                    todo.append(s)
        self.simulate(todo)

    def refine(self, k: int, rel_tol: float, run_cap: int, round_cap: int) -> None:
        """Rounds of up to ``k`` simulations (:func:`_next_scales`) until the bracket is
        within ``rel_tol`` or the budget is spent."""
        count = self.count
        while count["runs"] < run_cap and count["rounds"] < round_cap and count["steps"] <= 40:
            lo, hi = _bracket(self.cache)
            scales = _next_scales(self.cache, lo, hi, min(k, run_cap - count["runs"]), rel_tol)
            if not scales:
                break
            todo = []
            for s in scales:  # ascending: a scale failing without a simulation fails every larger one
                if not self.free(s)[0]:
                    break
                todo.append(s)
            else:
                self.simulate(todo)


def _bracket(cache: dict) -> tuple[float | None, float | None]:
    """(largest passing scale below the smallest failing one, smallest failing scale)."""
    fails = [s for s, v in cache.items() if not v["feasible"]]
    hi = min(fails) if fails else None
    passes = [s for s, v in cache.items() if v["feasible"] and (hi is None or s < hi)]
    return (max(passes) if passes else None), hi


def _next_scales(cache: dict, lo, hi, n: int, rel_tol: float) -> list[float]:
    """The next round's scales, ascending (see :func:`max_scale`); [] when the bracket
    is closed."""
    if n < 1:
        return []
    if lo is not None and hi is not None:
        if hi / lo <= 1 + rel_tol:
            return []
        need = int(np.ceil(np.log(hi / lo) / np.log1p(rel_tol) - 1e-9)) - 1  # points that close it in one round
        n = max(1, min(n, need))
        if n == 1:
            return [float(np.sqrt(lo * hi))]
        return [float(lo * (hi / lo) ** (j / (n + 1))) for j in range(1, n + 1)]
    base = cache[lo] if lo is not None else cache[hi]
    u = _scaling_utilisation(base)
    guess = base["scale"] / u if u > 0 else base["scale"] * 4
    step = 1 + rel_tol
    if lo is not None:  # only passing so far: jump to the prediction, at least +rel_tol
        s = max(guess * 0.995, lo * step)
        ok = lambda x: x >= lo * step * (1 - 1e-12)  # noqa: E731
    else:
        s = min(guess * 0.995, hi / step)
        ok = lambda x: x <= hi / step * (1 + 1e-12)  # noqa: E731
    out = [s]
    m = 1
    while len(out) < n and m <= 4 * n:
        for x in (s * step**m, s / step**m):
            if len(out) < n and ok(x):
                out.append(x)
        m += 1
    return sorted(float(x) for x in out)


def _first_failed(v: dict) -> str:
    """The most utilised failed capability check (tracking checks do not enter the verdict)."""
    from sim.assess.feasibility import is_tracking

    failed = [c for c in v["checks"] if not c["pass"] and not is_tracking(c)]
    return max(failed, key=lambda c: c["utilisation"])["name"] if failed else v["limiting"]


def _scaling_utilisation(v: dict) -> float:
    """Highest utilisation among the checks that grow with the amplitude."""
    skip = ("specimen_mass", "support_load", "loop_closure", "run_completed")
    us = [
        c["utilisation"]
        for c in v["checks"]
        if not c["name"].startswith(("pga_error", "spectrum_"))
        and c["name"] not in skip
        and np.isfinite(c["utilisation"])
    ]
    return max(us) if us else 0.0


def _strip(v: dict) -> dict:
    return {k: x for k, x in v.items() if not k.startswith("_")}


# ------------------------------------------------------------------ suite
def suite_records(folder) -> list[str]:
    """The records of a suite folder: every sub-folder holding .AT2 files (one record of
    up to 3 components each) and the folder itself if it holds any."""
    p = Path(folder)
    if not p.is_dir():
        raise CaseError(f"--suite {folder}: not a folder; give a folder of record folders (3 .AT2 components each)")
    recs = [str(d) for d in sorted(p.iterdir()) if d.is_dir() and any(f.suffix.lower() == ".at2" for f in d.iterdir())]
    if any(f.suffix.lower() == ".at2" for f in p.iterdir()):
        recs.insert(0, str(p))
    if not recs:
        raise CaseError(f"--suite {folder}: no .AT2 records in it or its sub-folders")
    return recs


SUITE_COLUMNS = ("record", "scale", "payload", "feasible", "limiting", "limiting_utilisation", "failed", "simulated")


def suite(
    table: str,
    records: list[str],
    scales: list[float],
    payloads: list,
    *,
    window_s=None,
    iterations=0,
    progress=None,
    nthread: int = 0,
    processes: int | None = None,
) -> list[dict]:
    """Every record x scale x payload: one row per case (see :data:`SUITE_COLUMNS`).

    The cases are dealt out in tasks (about four per process) to ``processes`` worker
    processes (default: one per core, at most one per case; 1: this process), each task
    prepared, staged and settled in its worker with its simulations run together on the
    shared route of many runs (:func:`sim.assess.many.run_plans`: MuJoCo's batch on
    ``nthread`` threads, default the cores left to each process, where the table
    allows): each case the same run and verdict as its own :func:`assess`, whatever the
    split. Processes first, as for sweeps (:mod:`sim.sweep.split`): preparing and
    settling a case is Python, one case at a time per process."""
    import math
    from functools import partial

    from sim.parallel import iter_jobs

    say = progress or (lambda text: None)
    keys = [(rec, pay, s) for rec in records for pay in payloads for s in scales]
    cases = [
        Case(table=table, motion=rec, payload=pay, scale=s, window_s=window_s, iterations=iterations)
        for rec, pay, s in keys
    ]
    cores = usable_cores()
    procs = max(1, min(processes or cores, len(cases)))
    per = max(1, math.ceil(len(cases) / (4 * procs)))
    tasks = [list(range(i, min(i + per, len(cases)))) for i in range(0, len(cases), per)]
    say(f"simulating {len(cases)} cases: {len(tasks)} tasks on {procs} process{'es' if procs > 1 else ''}")
    rows: list = [None] * len(cases)
    fn = partial(_suite_task, nthread=nthread or max(1, cores // procs))
    for i, part in iter_jobs(fn, [[cases[j] for j in t] for t in tasks], workers=procs):
        for j, v in zip(tasks[i], part):
            rec, pay, s = keys[j]
            rows[j] = {
                "record": Path(rec).name,
                "scale": s,
                "payload": getattr(pay, "name", None) or "bare",
                **{k: v[k] for k in ("feasible", "limiting", "limiting_utilisation", "simulated")},
                "failed": ";".join(v["failed"]),
            }
    return [{k: r[k] for k in SUITE_COLUMNS} for r in rows]


def _suite_task(cases: list, *, nthread: int) -> list[dict]:
    """The verdicts of ``cases`` (one suite task): each prepared and staged, the
    simulations run together (:func:`sim.assess.many.run_plans`), each settled; without
    the outcomes (a worker sends the verdicts back)."""
    from sim.assess.many import run_plans

    preps = [prepare(c) for c in cases]  # one per case: each case's plan has its own simulation
    staged = [stage(p, c.scale, simulate=True) for p, c in zip(preps, cases)]
    todo = [i for i, (pre, plan) in enumerate(staged) if plan is not None]
    outs = run_plans([staged[i][1] for i in todo], nthread=nthread)
    verdicts = {i: pre for i, (pre, plan) in enumerate(staged) if plan is None}
    for i, o in zip(todo, outs):
        if isinstance(o, UserError):
            raise o
        verdicts[i] = settle(preps[i], cases[i].scale, o)
    keep = ("feasible", "limiting", "limiting_utilisation", "failed", "simulated")
    return [{k: _finish(p, verdicts[i])[k] for k in keep} for i, p in enumerate(preps)]


__all__ = [
    "BUILTIN_RECORDS",
    "Case",
    "CaseError",
    "Prepared",
    "SUITE_COLUMNS",
    "assess",
    "check_dofs",
    "evaluate",
    "max_scale",
    "prepare",
    "record_motions",
    "settle",
    "stage",
    "strongest_window",
    "suite",
    "suite_records",
    "DOFS6",
]
