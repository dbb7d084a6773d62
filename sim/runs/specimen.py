"""The model's specimen accelerometers (run-file channel ``specimen_acceleration``).

A sensor on the specimen is placed by its height above the platen's top surface and its
direction (``meta.specimen_sensors``, docs/run-file.md). The model gives its reading when
the payload has floors at that height: a shear frame's floor ``i`` sits at
``base_m[2] + i * storey_height_m`` (mjcf/builder.py) on a slide along the frame's
direction, so its absolute acceleration is the platen's plus the second derivative of
its drift; a sensor at height 0 is on the platen. The reading is that acceleration along
the sensor's direction, gravity removed (as ``accelerometers``). The drift is recorded at
the controller's rate and differentiated by central differences: the error is
(omega h)^2 / 12 of the mode's amplitude, 4e-4 for a 10.5 Hz mode at 1024 Hz.
Any other place (between floors, a rigid or cantilever payload) has no reading: its
column is NaN (the format's missing samples) and a note says why.

The loop records the floors' own accelerometers exactly during a simulation, from the
frame's springs and dampers (:mod:`sim.loop.specimen`); this module serves a record's
sensors after a run (a replay), where only the recorded platen acceleration and floor
drifts are at hand. Both place the floors with :func:`sim.loop.specimen.floor_heights`;
tests/runs/test_specimen.py holds their readings together (0.2-0.3 % RMS apart).
"""

from __future__ import annotations

import numpy as np

from sim.loop.specimen import floor_heights, frame_axis

#: a sensor within this fraction of a storey of a floor's level is on that floor (a
#: sensor sits on the slab, not at the lumped mass's exact height)
FLOOR_TOLERANCE = 0.25


def sensor_place(payload, height_m: float) -> int | None:
    """Where a sensor at ``height_m`` is in the model: 0 the platen, i >= 1 floor i, None nowhere."""
    floors = floor_heights(payload)
    step = float(payload.storey_height_m) if floors else 0.1
    if abs(height_m) <= FLOOR_TOLERANCE * step:
        return 0
    for i, z in enumerate(floors, start=1):
        if abs(height_m - z) <= FLOOR_TOLERANCE * step:
            return i
    return None


def specimen_accelerations(t, table_acceleration, payload_qpos, payload, sensors: list) -> tuple[np.ndarray, list[str]]:
    """The model's readings of ``sensors`` (``meta.specimen_sensors`` entries) at times
    ``t`` from the platen's ``table_acceleration`` (N, 6) and the floor drifts
    ``payload_qpos`` (N, n_floors; the loop's ``extras["payload_qpos"]``, None without a
    flexible payload): ``(array (N, n_sensors) m/s^2, notes)``; NaN columns where the
    model has no floor at the sensor's height (each with a note)."""
    t = np.asarray(t, float)
    a_platen = np.asarray(table_acceleration, float)[:, :3]
    out = np.full((len(t), len(sensors)), np.nan)
    notes = []
    drift_acc = None
    if floor_heights(payload) and payload_qpos is not None and len(t) > 2:
        u = np.asarray(payload_qpos, float)
        drift_acc = np.gradient(np.gradient(u, t, axis=0), t, axis=0)
    axis = np.array(frame_axis(payload))
    for j, s in enumerate(sensors):
        d = np.asarray(s["direction"], float)
        d = d / np.linalg.norm(d)
        place = sensor_place(payload, float(s["height_m"])) if payload is not None else None
        if payload is None and abs(float(s["height_m"])) < 1e-9:
            place = 0
        if place == 0:
            out[:, j] = a_platen @ d
        elif place is not None and drift_acc is not None:
            out[:, j] = a_platen @ d + drift_acc[:, place - 1] * float(axis @ d)
        else:
            notes.append(_no_reading(s, payload))
    return out, notes


def _no_reading(sensor: dict, payload) -> str:
    name, h = sensor["name"], float(sensor["height_m"])
    floors = floor_heights(payload)
    if payload is None:
        why = "the model has no payload (a bare table)"
    elif not floors:
        why = f"payload '{payload.name}' has no floors (a {type(payload).__name__})"
    else:
        why = f"payload '{payload.name}' has floors at {', '.join(f'{z:g}' for z in floors)} m"
    return (
        f"specimen sensor {name} at {h:g} m: the model gives no acceleration there ({why}); "
        "its specimen_acceleration column is NaN"
    )


__all__ = ["FLOOR_TOLERANCE", "floor_heights", "sensor_place", "specimen_accelerations"]
