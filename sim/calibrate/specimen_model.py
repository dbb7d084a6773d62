"""The model's specimen accelerometers on the replay and closed-loop paths (run-file channel
``specimen_acceleration``, ``meta.specimen_sensors``: docs/run-file.md).

A sensor is placed by its height above the platen's top surface and its direction. What
the model says it reads:

* at height 0: the platen's acceleration there (the reference point's translation plus
  the rotation's ``alpha x r``; the sensor's plan position is not in the meta, so it is
  taken on the vertical through the reference point, the platen's top centre);
* on a shear-frame payload: at a floor's level, the floor's reading
  (:func:`sim.runs.specimen.specimen_accelerations`); between floors, none;
* on a payload with no floors of its own (a rigid block, or none declared): the
  platen's acceleration at the sensor's point (a rigid specimen moves with the platen),
  plus the relative acceleration of every specimen mode of the model (``payload_mode``
  effects, :class:`sim.effects.mechanical.PayloadMode`) along the sensor's direction;
* on a cantilever payload: none (its deformed shape is not read here).

A ``payload_mode`` is a body of the modal mass on a spring-damper to the platen, so its
motion relative to the platen is the linear oscillator driven by the platen's
acceleration at its point: ``y'' + 2 zeta w y' + w^2 y = -a_base``, integrated here on
the model's own recorded platen acceleration (first-order hold, exact for the
oscillator). The sensor reads ``a_base + y''`` at participation 1: it sits on the part
that moves on the mode. That is exact for a block on a flexible clamp (the whole moving
part is one mass) and for the top of a single-storey frame; a multi-storey frame's
floors move by ``phi_i Gamma`` times the modal coordinate (1.17 at the top and 0.72 at
the first floor of two equal storeys, first mode): this one-mode model does not fit a
shape per sensor, so a sensor off the mode's effective point biases the modal mass.
"""

from __future__ import annotations

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
        elif isinstance(payload, CantileverPayload):
            ok = h == 0.0
        else:
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


def mode_relative_acceleration(t: np.ndarray, a_base: np.ndarray, f_hz: float, zeta: float) -> np.ndarray:
    """``y''`` of the oscillator ``y'' + 2 zeta w y' + w^2 y = -a_base`` from rest, at ``t``
    (``a_base`` first-order held between samples)."""
    import scipy.signal as sig

    w = 2 * np.pi * float(f_hz)
    # y'' = -a_base - 2 zeta w y' - w^2 y: states (y, y'), output y''
    A = np.array([[0.0, 1.0], [-(w**2), -2 * zeta * w]])
    B = np.array([[0.0], [-1.0]])
    C = np.array([[-(w**2), -2 * zeta * w]])
    D = np.array([[-1.0]])
    _, y, _ = sig.lsim((A, B, C, D), np.asarray(a_base, float), np.asarray(t, float) - float(t[0]))
    return np.asarray(y, float).reshape(-1)


def payload_modes(tm) -> list:
    """``(axis (3,), position (3,) from the reference point, frequency Hz, damping ratio)``
    of each ``payload_mode`` of the model ``tm`` (its body's place in the platen frame)."""
    import mujoco

    out = []
    for e in getattr(tm, "effects", []):
        if getattr(e, "type", None) != "payload_mode":
            continue
        jid = mujoco.mj_name2id(tm.model, mujoco.mjtObj.mjOBJ_JOINT, e.joint)
        body = int(tm.model.jnt_bodyid[jid])
        axis = np.zeros(3)
        axis[("x", "y", "z").index(e.where.partition(":")[2])] = 1.0
        pos = np.asarray(tm.model.body_pos[body], float)
        out.append((axis, pos, float(e.values["frequency_hz"]), float(e.values["damping_ratio"])))
    return out


def model_specimen(res, tm, payload, sensors: list) -> np.ndarray:
    """(n_tick, n_sensors) the model's readings of ``sensors`` at the loop's instants
    ``res.t`` (NaN where it gives none, :func:`readable`)."""
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
    modes = [
        (ax, mode_relative_acceleration(t, point_acceleration(acc6, pos) @ ax, f, z))
        for ax, pos, f, z in payload_modes(tm)
    ]
    for j, s in enumerate(sensors):
        d = np.asarray(s["direction"], float)
        d = d / np.linalg.norm(d)
        h = float(s["height_m"])
        out[:, j] = point_acceleration(acc6, [0.0, 0.0, h]) @ d
        if h > 0.0:  # on the specimen: on the part that moves on each mode
            for ax, ydd in modes:
                out[:, j] += ydd * float(ax @ d)
    return out


__all__ = ["CHANNEL", "model_specimen", "mode_relative_acceleration", "payload_modes", "readable", "sensors_of"]
