"""A specimen's modes as effects: :class:`PayloadMode` (``payload_mode``), a mass on a
slide along one DOF with the spring and damper of a mode of what stands on the platen;
with ``from_payload`` the mass is part of the declared payload's, and the first such
mode at each DOF share one part of it (:meth:`PayloadMode._shared`)."""

from __future__ import annotations

import mujoco
import numpy as np

from sim.effects.base import Effect, register
from sim.effects.mechanical import INF, _hint, _payload_bodies, _unique, _vector
from sim.errors import ScenarioError


@register
class PayloadMode(Effect):
    """One flexible mode of what stands on the platen: a body of ``mass_kg`` (the modal
    mass) on a slide along the DOF (``where = "dof:x|y|z"``) with a spring-damper to the
    platen giving ``frequency_hz`` and ``damping_ratio`` on a fixed platen; at
    ``position_m`` from the reference point. One entry per mode.

    ``from_payload = true``: the modal mass is part of the declared payload's (a specimen
    declared rigid that is flexible: ``mass_kg`` of it moves on the mode): the payload's
    bodies keep ``1 - mass_kg / M`` of their mass and inertia (M their total), so the table
    carries the same weight, and the mode sits at the payload's centre of gravity unless
    ``position_m`` says otherwise. A payload of one body's mass M moving as one mode of
    modal mass m and the rest rigid is this model exactly (the clamped block of
    ``clamp_mass_fraction``, mjcf.builder)."""

    type = "payload_mode"
    places = ("dof",)
    SPEC = {
        "frequency_hz": ("Hz", 1e-3, INF, None),
        "mass_kg": ("kg", 1e-9, INF, None),
        "damping_ratio": ("1", 0.0, 10.0, None),
    }
    OPTIONS = {"position_m": None, "from_payload": False}

    def edit_spec(self, spec, desc):
        d = self.where.partition(":")[2]
        if d not in ("x", "y", "z"):
            raise ScenarioError(f"{self.source}: a payload_mode moves along x, y or z, not '{d}'{_hint(d, 'xyz')}")
        v = self.values
        m = v["mass_kg"]
        pos = _vector(self.options["position_m"], self, "position_m")
        group = shared_modes(getattr(desc, "effects", []) or [])
        index = _entry_index(self.source)
        if self.options["from_payload"] and index in group:
            self.joint = self._shared(spec, desc, group)
            return
        if self.options["from_payload"]:
            cg, inertia = self._take_from_payload(spec, m)
            pos = cg if self.options["position_m"] is None else pos
        b = _point_body(spec, _unique(spec, f"payload_mode_{d}"), m, pos)
        if self.options["from_payload"]:
            b.inertia = np.maximum(inertia, 1e-6 * m).tolist()
        self.joint = _mode_slide(spec, b, f"{b.name}_slide", d, m, v["frequency_hz"], v["damping_ratio"], desc).name

    def _shared(self, spec, desc, group: dict) -> str:
        """The first ``from_payload`` mode at each DOF: one part of the payload that moves on
        all of them (a block on its clamp, a specimen's first modes in x, y and z), built
        once, by the first of them, as layers: sorted by modal mass, the smallest mass
        slides along every DOF of the group, the next layer (the difference) along all but
        the lightest DOF's, and so on; each layer's spring along a DOF gives that DOF's
        frequency and damping. Along each DOF the moving mass is then its mode's, the rest
        of the payload rigid, and the payload gives up only the largest (separate bodies,
        one per mode, would take the sum). Returns this entry's slide (on the all-DOF
        layer: every layer moves alike along a DOF)."""
        d = self.where.partition(":")[2]
        stem = "payload_mode_shared"
        last = f"{stem}{len(group)}"  # the layer every mode of the group moves (never empty)
        if spec.body(last) is None:
            members = sorted((dict(desc.effects[i]) for i in group), key=lambda e: float(e["mass_kg"]), reverse=True)
            masses = [float(e["mass_kg"]) for e in members] + [0.0]
            cg, inertia = self._take_from_payload(spec, masses[0])
            pos = cg if self.options["position_m"] is None else _vector(self.options["position_m"], self, "position_m")
            for k in range(len(members)):  # layer k+1: the members 0..k slide it
                mk = masses[k] - masses[k + 1]
                if mk <= 0:  # equal modal masses: that layer is empty
                    continue
                b = _point_body(spec, f"{stem}{k + 1}", mk, pos)
                b.inertia = np.maximum(inertia * mk / masses[0], 1e-6 * mk).tolist()  # its share of what turns
                for e in members[: k + 1]:
                    dd = str(e["where"]).partition(":")[2]
                    _mode_slide(
                        spec,
                        b,
                        f"{b.name}_{dd}",
                        dd,
                        float(b.mass),
                        float(e["frequency_hz"]),
                        float(e["damping_ratio"]),
                        desc,
                    )
        return f"{last}_{d}"

    def _take_from_payload(self, spec, m: float) -> tuple[np.ndarray, np.ndarray]:
        """Moves ``m`` kg out of the payload's bodies (each keeps the same share of its
        mass and inertia); returns their centre of gravity in the platen frame and the
        rotational inertia taken (diagonal, kg m^2: the moving part turns with it)."""
        bodies = [b for b in _payload_bodies(spec) if float(b.mass) > 0]
        total = sum(float(b.mass) for b in bodies)
        if not bodies or m > total * (1.0 + 1e-9):
            have = f"{total:.6g} kg" if bodies else "none is built"
            raise ScenarioError(
                f"{self.source}: a payload_mode with from_payload = true takes its mass_kg ({m:.6g}) from the "
                f"payload, which must weigh more ({have}); lower mass_kg or drop from_payload"
            )
        cg = sum(float(b.mass) * (np.asarray(b.pos, float) + np.asarray(b.ipos, float)) for b in bodies) / total
        keep = max(0.0, 1.0 - m / total)
        taken = np.zeros(3)
        for b in bodies:
            b.mass = float(b.mass) * keep
            taken += np.asarray(b.inertia, float) * (1.0 - keep)
            b.inertia = (np.asarray(b.inertia, float) * keep).tolist()
        return cg, taken


def shared_modes(entries) -> dict[int, str]:
    """Index -> DOF of the first ``payload_mode`` with ``from_payload`` at each DOF among
    ``entries`` (``[[effect]]`` tables): the modes one part of the payload shares
    (:meth:`PayloadMode._shared`)."""
    out, seen = {}, set()
    for i, e in enumerate(entries):
        if isinstance(e, dict) and e.get("type") == "payload_mode" and e.get("from_payload"):
            d = str(e.get("where", "")).partition(":")[2]
            if d not in seen:
                seen.add(d)
                out[i] = d
    return out


def payload_taken(modes) -> float:
    """The mass (kg) ``from_payload`` modes ``[(dof, mass_kg), ...]`` take from the payload:
    the first at each DOF share one part (the largest of them), each later one its own."""
    first, rest = {}, 0.0
    for d, m in modes:
        if d in first:
            rest += float(m)
        else:
            first[d] = float(m)
    return max(first.values(), default=0.0) + rest


def _entry_index(source: str) -> int | None:
    """The ``[[effect]]`` index an effect was built from (its source ends ``effect[i]``)."""
    import re

    m = re.search(r"effect\[(\d+)\]$", str(source))
    return int(m.group(1)) if m else None


def _point_body(spec, name: str, m: float, pos) -> object:
    b = spec.body("platen").add_body(name=name, pos=list(map(float, pos)))
    b.explicitinertial = True
    b.mass = m
    b.ipos = [0, 0, 0]
    b.inertia = [1e-6 * m] * 3  # assumed: a point mass (the inertia of a 1 mm radius keeps M regular)
    return b


def _mode_slide(spec, b, name: str, d: str, m: float, f: float, z: float, desc):
    """A slide of body ``b`` (mass ``m``) along ``d`` with the spring and damper of a mode
    of frequency ``f`` and damping ratio ``z`` as the model's step has it
    (:func:`mjcf.stepping.mode_spring`)."""
    from mjcf.stepping import mode_spring

    axis = [0.0, 0.0, 0.0]
    axis[("x", "y", "z").index(d)] = 1.0
    j = b.add_joint(name=name, type=mujoco.mjtJoint.mjJNT_SLIDE, axis=axis)
    k, c = mode_spring(spec, m, f, z)
    j.stiffness = [k, 0, 0]
    j.damping = [c, 0, 0]
    if d == "z":  # home is the static equilibrium under gravity
        j.springref = m * desc.gravity_m_s2 / k
    return j


__all__ = ["PayloadMode", "payload_taken", "shared_modes"]
