"""Run a scenario: the one library function behind ``shaketable run`` (and behind
anything else that runs scenarios: a sweep, a notebook, a Dask worker).

:func:`run_scenario` builds the table, the controller and the reference from a
:class:`sim.scenario.files.Scenario`, runs the drive iterations the scenario asks for,
and returns a :class:`RunOutcome`: the chosen run as a run file, the summary (tracking,
drive-iteration history, diagnostics) and the feasibility verdict, as data. Nothing is
written: :meth:`RunOutcome.write` puts the run file, ``summary.json`` and, optionally,
a rerun recording in a folder.
"""

from __future__ import annotations

import copy
import sys
from dataclasses import asdict, dataclass, field, is_dataclass
from pathlib import Path

import numpy as np

from sim.errors import RunInterrupted, ScenarioError, UserError

SCHEMA = "shaketable-summary/1"


class DivergenceAtStart(UserError):
    """Diverged before a second sample: nothing to keep (a run file needs two samples)."""


def gains_json(g) -> dict:
    """A controller's settings as plain JSON data."""
    return {
        k: (v.tolist() if isinstance(v, np.ndarray) else asdict(v) if is_dataclass(v) else v)
        for k, v in g.__dict__.items()
    }


@dataclass
class RunOutcome:
    """What a scenario run gives back.

    ``run``: the chosen run (:class:`sim.runs.runfile.RunFile`); ``result``: the loop's
    :class:`sim.loop.simulation.RunResult`; ``summary``: the figures of ``summary.json``
    (``summary["feasibility"]`` is the verdict); ``tm``: the compiled table model;
    ``warnings``: the reference beyond the rated envelope, as text.
    """

    run: object
    result: object
    summary: dict
    tm: object
    warnings: list = field(default_factory=list)

    @property
    def verdict(self) -> dict:
        return self.summary["feasibility"]

    @property
    def feasible(self) -> bool:
        return bool(self.summary["feasibility"]["feasible"])

    @property
    def complete(self) -> bool:
        return self.result.incomplete_reason is None

    def write(self, out) -> dict:
        """Write ``<scenario>.run.npz`` and ``summary.json`` to folder ``out``; returns the
        summary with the written paths."""
        from sim.runs.files import out_dir, write_json_atomic
        from sim.runs.runfile import write_run

        out = out_dir(out)
        path = out / f"{self.summary['scenario']}.run.npz"
        write_run(path, self.run)
        self.summary["run_file"] = str(path)
        write_json_atomic(out / "summary.json", self.summary)
        return self.summary


def _tracking(res, ref):
    from sim.assess.metrics import tracking

    return tracking(res.t, ref.d, ref.a, res.channels["table_displacement"], res.channels["table_acceleration"])


@dataclass
class ScenarioPlan:
    """A scenario made ready to run: the table model, the simulation with its controller,
    the reference and the warnings of a reference beyond the rated envelope. Built by
    :func:`plan_scenario`; :meth:`run` runs it (drive iterations included)."""

    scenario: object
    desc: object
    payload: object
    tm: object
    sim: object
    gains: object
    reference: object
    iteration: dict
    warnings: list
    envelope_reference: object = None  #: the whole demanded motion when ``reference`` is a window of it
    window: dict = field(default_factory=dict)  #: which part of the motion runs (start_s, end_s, of_record_s, why)
    engine: str = "loop"  #: "loop" (Simulation.run, the reference) or "callback" (the coupled step inside MuJoCo)

    def run(self, *, progress=None) -> RunOutcome:
        """Run the plan; ``progress(text)`` is called once per stage (None: silent).

        Ctrl-C during a simulation keeps what it computed: the outcome holds that run,
        marked incomplete (``result.interrupted``), for the caller to write."""
        say = progress or (lambda text: None)
        history = []
        try:
            res, plain, best, wall_total, settings = self._simulate(say, progress, history)
        except RunInterrupted as stop:
            res = plain = stop.result
            best, wall_total, history, settings = 0, res.wall_s, [], None
            if len(res.t) < 2:
                raise
        return self.outcome(res, plain=plain, best=best, wall_total=wall_total, history=history, settings=settings)

    def _simulate(self, say, progress, history):
        sim, ref = self.sim, self.reference
        settings = None
        if self.iteration.get("count", 0) > 0:
            from sim.control.iteration import IterationSettings, iterate

            settings = IterationSettings.from_scenario(self.iteration)
            if settings.frf == "noise":
                say(f"measuring the table's FRF ({settings.noise_duration_s:g} s of white noise)")
            results, _drives = iterate(
                sim,
                ref,
                settings,
                progress=lambda i: say(
                    "run with the plain controller" if i == 0 else f"drive iteration {i} of {settings.count}"
                ),
                run=self._runner(progress),
            )
            scores = []
            for i, r in enumerate(results):
                tr = _tracking(r, ref)
                score = float(np.mean([e["nrmse_acceleration"] for e in tr.values()])) if tr else 0.0
                scores.append(score if r.incomplete_reason is None else np.inf)
                history.append({"iteration": i, "mean_nrmse_acceleration": score, "tracking": tr})
            best = int(np.argmin(scores))
            res, plain = results[best], results[0]
            wall_total = sum(r.wall_s for r in results)
        else:
            say("simulating (coupled step inside MuJoCo)" if self.engine == "callback" else "simulating")
            res = self._runner(progress)(ref)
            plain, best, wall_total = res, 0, res.wall_s
        return res, plain, best, wall_total, settings

    def _runner(self, progress):
        """``run(reference) -> RunResult`` of this plan's simulation from its current
        state on its engine (the callback route or ``Simulation.run``: the same run), with
        the progress bar on a terminal when ``progress`` is given."""
        sim, bar = self.sim, progress is not None and sys.stderr.isatty()
        if self.engine == "callback":
            from sim.loop.callback import run_callback

            return lambda ref: run_callback(sim, ref, progress=bar)
        return lambda ref: sim.run(reference=ref, progress=bar)

    def outcome(self, res, *, plain=None, best=0, wall_total=None, history=(), settings=None) -> RunOutcome:
        """The :class:`RunOutcome` of a finished loop result ``res`` of this plan (also
        for a result computed elsewhere, e.g. one simulation of a batch)."""
        from sim.assess.feasibility import diagnostics
        from sim.runs.build import build_runfile

        sc, sim, ref = self.scenario, self.sim, self.reference
        plain = res if plain is None else plain
        wall_total = res.wall_s if wall_total is None else wall_total

        if len(res.t) < 2:
            raise DivergenceAtStart(res.incomplete_reason or "the simulation stopped before its second sample")
        run = build_runfile(
            res,
            self.tm,
            description=sc.description or sc.name,
            payload_name=self.payload.name if self.payload else None,
            reference=ref,
            extra_meta={"scenario": sc.name, "controller": gains_json(self.gains), **_fault_meta(self.tm)},
        )
        summary = {
            "schema": SCHEMA,
            "scenario": sc.name,
            "table": self.desc.name,
            "payload": self.payload.name if self.payload else None,
            "duration_s": float(res.sim_s),
            "window": dict(self.window),
            "wall_s": float(res.wall_s),
            "realtime_factor": float(res.realtime_factor),
            "complete": res.incomplete_reason is None,
            "incomplete_reason": res.incomplete_reason,
            "interrupted": bool(getattr(res, "interrupted", False)),
            "tracking": (tracking := _tracking(res, ref)),
            "drive_iterations": {
                "count": len(history) - 1 if history else 0,
                "chosen": best,
                "frf": settings.frf if history else None,
                "tracking_plain_controller": copy.deepcopy(tracking) if plain is res else _tracking(plain, ref),
                "history": [
                    {"iteration": h["iteration"], "mean_nrmse_acceleration": h["mean_nrmse_acceleration"]}
                    for h in history
                ],
            },
            "wall_s_all_runs": float(wall_total),
            "engine": self.engine,
            "warnings": self.warnings,
        }
        summary.update(
            diagnostics(
                res,
                self.tm,
                sim.hp,
                ref,
                payload=self.payload,
                envelope_reference=self.envelope_reference,
                warnings=self.warnings,
            )
        )
        from sim.assess.faults import fault_summary

        faults = fault_summary(res, self.tm, sim.hp, self.payload)
        if faults is not None:
            summary["faults"] = faults
        return RunOutcome(run=run, result=res, summary=summary, tm=self.tm, warnings=self.warnings)


def _with_overrides(sc, overrides: dict):
    """The table description, the payload and the scenario of ``sc`` with ``overrides``
    (:mod:`sim.scenario.overrides`) applied to their TOML data, parsed again (so every
    value is checked as in a file)."""
    import dataclasses

    from mjcf.description import PAYLOADS_DIR, TABLES_DIR, load_toml, parse_payload, parse_table, resolve
    from sim.scenario.overrides import apply_all

    tpath = resolve(sc.table, TABLES_DIR, "table")
    data = {"table": load_toml(tpath), "motion": sc.motion, "controller": sc.controller, "iteration": sc.iteration}
    ppath = resolve(sc.payload, PAYLOADS_DIR, "payload") if sc.payload else None
    if ppath is not None:
        data["payload"] = load_toml(ppath)["payload"]
    where = str(sc.path or sc.name)
    data = apply_all(data, overrides, where=where)
    desc = parse_table(data["table"], src=f"{tpath} (with overrides)")
    payload = parse_payload({"payload": data["payload"]}, src=f"{ppath} (with overrides)") if ppath else None
    sc = dataclasses.replace(sc, motion=data["motion"], controller=data["controller"], iteration=data["iteration"])
    return desc, payload, sc


def _fault_meta(tm) -> dict:
    """``{"faults": [...]}``: the fault entries of a run with faults (the run file says
    what was done to the table; its table description is the file's, without them)."""
    from sim.effects.faults import is_fault

    faults = [e.entry() for e in tm.effects if is_fault(e)]
    return {"faults": faults} if faults else {}


def _with_faults(desc, sc, iterations: int):
    """``desc`` with the scenario's ``[[fault]]``/``[[effect]]`` entries and its interlock
    added to the table's effects (:func:`sim.effects.faults.scenario_entries`)."""
    import dataclasses

    from sim.control.base import controller_type
    from sim.effects.base import create
    from sim.effects.faults import is_fault, scenario_entries, tick_faults

    src = str(sc.path or sc.name)
    analog = controller_type(desc) == "analog"
    extra = scenario_entries(list(sc.faults), sc.interlock, desc, src, interlock_ok=not analog)
    if not extra:
        return desc
    objs = [create(e, source=src) for e in extra]
    if iterations and any(is_fault(e) for e in objs):
        raise ScenarioError(f"{src}: a scenario with faults runs with the plain controller; set iteration.count = 0")
    if analog and tick_faults(objs):
        kinds = sorted({e.type for e in tick_faults(objs)})
        raise ScenarioError(
            f"{src}: the analog controller runs no controller-tick faults ({', '.join(kinds)}); "
            "use pump_trip, or a large drive for the end cushions"
        )
    raw = dict(desc.raw)  # the raw data too: the analog loop parses its table again from it
    raw["effect"] = list(raw.get("effect", [])) + extra
    return dataclasses.replace(desc, raw=raw, effects=tuple(desc.effects) + tuple(extra))


def check_overrides(scenario, overrides: dict) -> None:
    """Raise the :class:`~sim.errors.UserError` ``overrides`` would give ``scenario``
    (an override naming nothing, a value the table or payload rejects), without
    building a model."""
    from sim.scenario.files import load_scenario

    sc = scenario if not isinstance(scenario, (str, Path)) else load_scenario(scenario)
    _with_overrides(sc, overrides)


def plan_scenario(
    scenario,
    *,
    duration_s: float | None = None,
    iterations: int | None = None,
    payload=...,
    motions: dict | None = None,
    overrides: dict | None = None,
    engine: str = "loop",
    start_s: float | None = None,
) -> ScenarioPlan:
    """Build everything a run of ``scenario`` (a :class:`~sim.scenario.files.Scenario` or
    its name/path) needs; raises :class:`~sim.errors.UserError` for bad inputs.

    ``payload``: a payload description (``mjcf.description`` object, or None for the bare
    table) instead of the scenario's; ``motions``: {dof: Motion} instead of the
    scenario's ``[motion]`` (both used by ``shaketable feasibility``).
    ``overrides``: ``{dotted key: value}`` (or ``{key: {"scale": f}}``) changes of the
    table, payload and scenario data (:mod:`sim.scenario.overrides`), e.g. a sweep case.
    ``engine``: ``"loop"`` (:meth:`Simulation.run`, the reference) or ``"callback"`` (the
    same run with the coupled step inside MuJoCo, :mod:`sim.loop.callback`, drive
    iterations included; used where the table allows it, the loop elsewhere:
    :func:`sim.loop.callback.accepts`). ``start_s``: where the run starts
    in the motion instead of the strong motion (``scenario.start_s``; see
    :func:`sim.scenario.files.build_window`)."""
    import mjcf
    from sim.control.base import controller_settings, controller_type
    from sim.loop.simulation import Simulation
    from sim.scenario.files import build_motions, build_window, limit_warnings, load_scenario

    sc = scenario if not isinstance(scenario, (str, Path)) else load_scenario(scenario)
    if duration_s is not None and not duration_s > 0:
        raise ScenarioError(f"--duration must be positive (got {duration_s})")
    if overrides:
        desc, opayload, sc = _with_overrides(sc, overrides)
        if payload is ...:
            payload = opayload
    else:
        desc = mjcf.load_table(sc.table)
    if payload is ...:
        payload = mjcf.load_payload(sc.payload) if sc.payload else None
    it = dict(sc.iteration)
    desc = _with_faults(desc, sc, iterations if iterations is not None else it.get("count", 0))
    if iterations is not None:
        if iterations < 0 or iterations > 10:
            raise ScenarioError(f"--iterations must be 0..10 (got {iterations})")
        it["count"] = iterations
    try:  # the [controller] overrides: errors name the scenario file
        analog = controller_type(desc) == "analog"  # an analog controller acting at every physics step
        if analog and it.get("count", 0):
            raise ScenarioError("drive iterations are not available with the analog controller")
        gains = controller_settings(desc, sc.controller)  # by [controller] type
    except ScenarioError as e:
        raise ScenarioError(f"{sc.path}: {e}") from None
    if abs(gains.rate_hz - sc.sample_rate_hz) > 1e-9:
        raise ScenarioError(
            f"{sc.path}: output.sample_rate_hz ({sc.sample_rate_hz:g}) must equal controller.rate_hz "
            f"({gains.rate_hz:g}): the recorder samples at the controller ticks"
        )
    if motions is None:
        motions = build_motions(sc)
    for dof, mo in motions.items():
        if dof not in desc.dofs and np.any(mo.d != 0):
            raise ScenarioError(
                f"{sc.path or sc.name}: a motion in {dof} but table '{desc.name}' moves only "
                f"{', '.join(desc.dofs)}; remove [motion.{dof}] or use a table with {dof}"
            )
    ref, window = build_window(sc, motions, duration_s, start_s)
    warns = limit_warnings(desc, motions)
    sim = Simulation.for_table(desc, payload, gains)
    tm = sim.tm
    if engine not in ("loop", "callback"):
        raise ScenarioError(f'engine must be "loop" or "callback" (got {engine!r})')
    if engine == "callback":
        from sim.loop.callback import accepts

        if accepts(sim):
            engine = "loop"  # the callback runs the fused loop only (sim.loop.callback.accepts says why)
    return ScenarioPlan(
        scenario=sc,
        desc=desc,
        payload=payload,
        tm=tm,
        sim=sim,
        gains=gains,
        reference=ref,
        iteration=it,
        warnings=warns,
        window=window,
        engine=engine,
    )


def run_scenario(
    scenario,
    *,
    duration_s: float | None = None,
    iterations: int | None = None,
    progress=None,
    overrides: dict | None = None,
    engine: str = "loop",
    start_s: float | None = None,
) -> RunOutcome:
    """Simulate ``scenario`` (a :class:`~sim.scenario.files.Scenario` or its name/path).

    ``duration_s``: simulate only this long; ``iterations``: off-line drive iterations
    (default: the scenario's ``[iteration] count``); ``progress``: ``progress(text)``
    called once per stage (``None``: silent); ``overrides``: changed inputs (see
    :func:`plan_scenario`). Returns a :class:`RunOutcome`; raises
    :class:`~sim.errors.UserError` for anything wrong with the inputs.
    """
    return plan_scenario(
        scenario, duration_s=duration_s, iterations=iterations, overrides=overrides, engine=engine, start_s=start_s
    ).run(progress=progress)


__all__ = [
    "DivergenceAtStart",
    "check_overrides",
    "RunOutcome",
    "SCHEMA",
    "ScenarioPlan",
    "gains_json",
    "plan_scenario",
    "run_scenario",
]
