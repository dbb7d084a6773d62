"""Open-loop replay of a run file's recorded valve commands through the model: the
first step of closing the loop with measured data (the residual is what the model
lacks)."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

from sim.errors import RunFileError


@dataclass
class ReplayOutcome:
    """The replayed run (a run file), the loop's result, and the residual NRMSE per
    channel and column against the source run."""

    run: object
    result: object
    residual_nrmse: dict
    source: str

    @property
    def complete(self) -> bool:
        return self.result.incomplete_reason is None


def replay(source, *, table: str | None = None, payload: str | None = None, progress: bool = False) -> ReplayOutcome:
    """Replay ``source`` (a run-file path or :class:`~sim.runs.runfile.RunFile`) open loop.

    ``table``/``payload``: override the descriptions the run carries
    (``meta.table_description``/``meta.payload_description``, else the stock files named
    by ``meta.table``/``meta.payload``).
    """
    from sim.assess.metrics import channel_residuals
    from sim.control.tvc import ControllerGains
    from sim.effects import build_model
    from sim.loop.simulation import Simulation
    from sim.runs.build import build_runfile
    from sim.runs.runfile import payload_of, read_run, table_of

    name = str(source) if isinstance(source, (str, Path)) else "<run>"
    src = read_run(source, require=("valve_command",)) if isinstance(source, (str, Path)) else source
    desc = table_of(src, table)  # --table, else the description the run carries, else the stock file
    if list(src.actuators) != list(desc.actuator_names):
        raise RunFileError(f"{name}: actuators {src.actuators} do not match table '{desc.name}' "
                           f"({list(desc.actuator_names)}); give --table")
    pl = payload_of(src, payload)
    tm = build_model(desc, pl)
    sim = Simulation(tm, gains=ControllerGains(rate_hz=src.sample_rate_hz))
    res = sim.run(valve_command=src.valve_command, progress=progress)
    run = build_runfile(res, tm, description=f"open-loop replay of {Path(name).name}",
                        payload_name=pl.name if pl else None, extra_meta={"replay_of": name})
    if src.reference is not None:
        run.reference = src.reference[:len(res.t)].copy()
    return ReplayOutcome(run=run, result=res, residual_nrmse=channel_residuals(src, run), source=name)


__all__ = ["ReplayOutcome", "replay"]
