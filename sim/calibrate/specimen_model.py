"""The model's specimen accelerometers on the replay and closed-loop paths (run-file channel
``specimen_acceleration``, ``meta.specimen_sensors``: docs/run-file.md).

A sensor is placed by its height above the platen's top surface and its direction. What
the model says it reads:

* at height 0: the platen's acceleration there (the reference point's translation plus
  the rotation's ``alpha x r``; the sensor's plan position is not in the meta, so it is
  taken on the vertical through the reference point, the platen's top centre);
* on a shear-frame payload: at a floor's level, the floor's reading
  (:func:`sim.runs.specimen.specimen_accelerations`); between floors, none;
* on a rigid payload: the platen's acceleration at the sensor's point (a rigid specimen
  moves with the platen), plus the relative acceleration of every specimen mode of the
  model (``payload_mode`` effects, :class:`sim.effects.specimen.PayloadMode`) along
  the sensor's direction;
* with no payload declared (``--payload none``), or a cantilever: none above the platen.
  Where an undeclared specimen's sensor sits on its mode shape is not known: the
  worked example's two-storey frame (floors at participation 0.72 and 1.17 of its first
  mode) read at participation 1 put that mode's modal mass at 316.9 +/- 16.6 kg for
  284.2 (tests/calibrate/test_payload_mode_paths.py, measured), where without its floor
  sensors the truth is inside the interval.

A ``payload_mode`` is a body of the modal mass on a slide with a spring-damper to the
platen (:class:`sim.effects.specimen.PayloadMode`): the model records its slide's
position (:func:`watch_modes` adds it to the payload coordinates the loop keeps), and
its accelerometer reads the force on it per kilogram, ``-(k y + c y') / m`` (as
:mod:`sim.loop.specimen` reads a floor: exact in the model's own integration; an
oscillator integrated apart from the model's platen acceleration missed the simulated
one by 1.2 % NRMSE on the lab table's 6 Hz block, measured, enough to move the fitted
frequency by 0.08 %, 16 times its interval). A sensor on the specimen reads the platen's
acceleration at its point plus each mode's acceleration relative to the platen along the
sensor's direction, at participation 1: it sits on the part that moves on the mode. That
is exact for a block on a flexible clamp (the whole moving part is one mass) and for the
top of a single-storey frame; a multi-storey frame's floors move by ``phi_i Gamma``
times the modal coordinate (1.17 at the top and 0.72 at the first floor of two equal
storeys, first mode): this one-mode model does not fit a shape per sensor, so a sensor
off the mode's effective point biases the modal mass.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

CHANNEL = "specimen_acceleration"


def sensors_of(run) -> list:
    """``run``'s ``meta.specimen_sensors`` entries (one per column), [] without them."""
    return list((run.meta or {}).get("specimen_sensors") or [])


def readable(sensors: list, payload) -> list[int]:
    """The sensors whose reading the model gives for ``payload`` (see the module docstring)."""
    from mjcf.description import CantileverPayload, ShearFramePayload
    from sim.runs.specimen import sensor_place

    out = []
    for j, s in enumerate(sensors):
        h = float(s["height_m"])
        if isinstance(payload, ShearFramePayload):
            ok = sensor_place(payload, h) is not None
        elif payload is None or isinstance(payload, CantileverPayload):
            ok = h == 0.0
        else:  # a rigid block: the sensor on the block, on the part that moves on its modes
            ok = True
        if ok:
            out.append(j)
    return out


def point_acceleration(acc6: np.ndarray, r) -> np.ndarray:
    """(n, 3) translational acceleration of the platen-fixed point ``r`` (m, from the
    reference point) from the platen's 6-DOF acceleration ``acc6`` (n, 6: x y z rx ry rz;
    small rotations, the centripetal term of the angular velocity left out)."""
    acc6 = np.asarray(acc6, float)
    return acc6[:, :3] + np.cross(acc6[:, 3:6], np.asarray(r, float)[None, :])


@dataclass
class Mode:
    """A ``payload_mode`` of the model: its slide's column in the loop's payload
    coordinates, stiffness (N/m), damping (N s/m), mass (kg), axis and place (m, platen frame)."""

    column: int
    k: float
    c: float
    m: float
    axis: np.ndarray
    pos: np.ndarray


def watch_modes(tm) -> list[Mode]:
    """The model's ``payload_mode`` bodies, their slides added to the payload coordinates
    the loop records (``tm.payload_dadr`` -> ``result.extras["payload_qpos"]``)."""
    import mujoco

    m = tm.model
    out = []
    for e in getattr(tm, "effects", []):
        if getattr(e, "type", None) != "payload_mode":
            continue
        jid = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, e.joint)
        dof = int(m.jnt_dofadr[jid])
        tm.payload_dadr = np.append(np.asarray(tm.payload_dadr, int), dof)
        axis = np.asarray(m.jnt_axis[jid], float)
        body = int(m.jnt_bodyid[jid])
        out.append(
            Mode(
                column=len(tm.payload_dadr) - 1,
                k=float(m.jnt_stiffness[jid]),
                c=float(m.dof_damping[dof]),
                m=float(m.body_mass[body]),
                axis=axis / np.linalg.norm(axis),
                pos=np.asarray(m.body_pos[body], float),
            )
        )
    return out


def mode_accelerations(res, modes: list[Mode]) -> list:
    """Each mode's absolute acceleration along its axis at ``res.t``: the force of its
    spring and damper per kilogram (the slide's rate by central differences)."""
    if not modes:
        return []
    t = np.asarray(res.t, float)
    q = np.asarray(res.extras["payload_qpos"], float)
    out = []
    for md in modes:
        y = q[:, md.column]
        yd = np.gradient(y, t) if len(t) > 2 else np.zeros_like(y)
        out.append(-(md.k * y + md.c * yd) / md.m)
    return out


def model_specimen(res, tm, payload, sensors: list, modes: list[Mode]) -> np.ndarray:
    """(n_tick, n_sensors) the model's readings of ``sensors`` at the loop's instants
    ``res.t`` (NaN where it gives none, :func:`readable`); ``modes``: :func:`watch_modes`."""
    from mjcf.description import RigidPayload
    from sim.runs.specimen import specimen_accelerations

    t = np.asarray(res.t, float)
    acc6 = np.asarray(res.channels["table_acceleration"], float)
    out = np.full((len(t), len(sensors)), np.nan)
    if payload is not None and not isinstance(payload, RigidPayload):  # floors (or none): the simulator's own rule
        arr, _notes = specimen_accelerations(t, acc6, res.extras.get("payload_qpos"), payload, sensors)
        keep = readable(sensors, payload)
        out[:, keep] = arr[:, keep]
        return out
    # each mode's acceleration relative to the platen at its place, along its axis
    rel = [
        (md.axis, a - point_acceleration(acc6, md.pos) @ md.axis)
        for md, a in zip(modes, mode_accelerations(res, modes))
    ]
    for j, s in enumerate(sensors):
        d = np.asarray(s["direction"], float)
        d = d / np.linalg.norm(d)
        h = float(s["height_m"])
        out[:, j] = point_acceleration(acc6, [0.0, 0.0, h]) @ d
        if h > 0.0:  # on the specimen: on the part that moves on each mode
            for axis, ydd in rel:
                out[:, j] += ydd * float(axis @ d)
    return out


__all__ = ["CHANNEL", "Mode", "mode_accelerations", "model_specimen", "readable", "sensors_of", "watch_modes"]
