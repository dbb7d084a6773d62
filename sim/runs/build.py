"""A run file from what the loop recorded (:class:`sim.loop.simulation.RunResult`)."""

from __future__ import annotations

from mjcf.description import DOFS6


def build_runfile(res, tm, *, source="simulated", description="", payload_name=None, reference=None, extra_meta=None):
    """RunFile from a :class:`sim.loop.simulation.RunResult` (every channel of the format)."""
    from sim.runs.runfile import FORMAT, RunFile, description_meta

    desc = tm.desc
    n = len(res.t)
    meta = {
        "format": FORMAT,
        "table": desc.name,
        "sample_rate_hz": 1.0 / float(res.t[1] - res.t[0]) if n > 1 else 1024.0,
        "actuators": list(desc.actuator_names),
        "dofs": list(DOFS6),
        "source": source,
        "description": description,
        "payload": payload_name,
        "accelerometers": [
            {"name": a.name, "position": a.position_m.tolist(), "direction": a.direction.tolist()}
            for a in desc.accelerometers
        ],
        "accelerometer_convention": "kinematic acceleration along the sensor direction, gravity removed",
        "angle_convention": "intrinsic x-y-z rotation of the platen from home",
    }
    # the descriptions themselves, so replay/view/fit rebuild this table, not the stock file
    meta.update(description_meta("table", desc.source, desc.raw))
    payload = getattr(tm, "payload", None)
    if payload is not None and getattr(payload, "raw", None):
        meta.update(description_meta("payload", payload.source, payload.raw))
    from sim.loop.specimen import specimen_sensors

    spec = specimen_sensors(tm) if "specimen_acceleration" in res.channels else None
    if spec is not None:  # accelerometers on the specimen's floors (docs/run-file.md)
        meta["specimen_sensors"] = spec.meta
    lag = float(getattr(res, "force_lag_s", 0.0) or 0.0)
    if lag:  # the loop's recorder: docs/run-file.md, meta force_lag_s
        meta["force_lag_s"] = lag
    hold = getattr(res, "valve_hold", None)
    if hold is not None:  # docs/run-file.md, meta valve_hold_command
        meta["valve_hold_command"] = [float(v) for v in hold]
    if extra_meta:
        meta.update(extra_meta)
    ch = dict(res.channels)
    for e in getattr(tm, "effects", []):  # sensor effects: what the table's sensors report
        ch = e.measure(res.t, ch, None)
    run = RunFile(
        t=res.t,
        meta=meta,
        valve_command=ch["valve_command"],
        spool_position=ch["spool_position"],
        actuator_displacement=ch["actuator_displacement"],
        actuator_force=ch["actuator_force"],
        pressure_a=ch["pressure_a"],
        pressure_b=ch["pressure_b"],
        table_displacement=ch["table_displacement"],
        table_velocity=ch["table_velocity"],
        table_acceleration=ch["table_acceleration"],
        accelerometers=ch["accelerometers"],
        specimen_acceleration=ch.get("specimen_acceleration") if spec is not None else None,
        reference=None if reference is None else reference.d[:n].copy(),
        extras=dict(res.extras),
    )
    if res.incomplete_reason:
        run.mark_incomplete(res.incomplete_reason)
    return run
