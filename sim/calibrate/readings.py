"""What a found effect means in the description's own numbers, where one number of it
says the same: a ``spring`` at ``supports`` is each static support's air spring made
stiffer, and the air spring's linear stiffness is ``n p0 A^2 / V0`` (the polytropic law
about its preload, :func:`mjcf.builder.build`). At the same preload (the static balance)
and exponent, the stiffer spring is a chamber of ``V0 k0 / (k0 + k)``: the lab reads
"the chambers hold less air than declared" where the search names a spring. A
``coulomb_friction`` at ``supports`` is each piston's friction (``[supports]
piston_friction_n``, the same joint's dry friction) higher by its force; at ``shoes``,
each shoe's (``shoe_friction_n``). An ``added_mass`` at ``supports`` is each piston
heavier (``piston_mass_kg``). A ``sensor_delay`` at ``channel:valve_command`` is the
controller's recorded channels late against the analog ones: each analog channel that
much early against the command (:func:`command_reading`).
"""

from __future__ import annotations

import numpy as np


def support_air_stiffness(desc, payload) -> np.ndarray:
    """Each static support's linear air stiffness as the declared model builds it (N/m)."""
    from sim.effects import build_model

    m = build_model(desc, payload).model
    return np.array([m.jnt_stiffness[m.joint(f"S{i}_air").id] for i in range(1, len(desc.supports.positions_m) + 1)])


def support_reading(desc, payload, effect: dict) -> str | None:
    """The line a ``spring`` at ``supports`` reads as (None for any other effect): the
    air springs' declared and found stiffness and the chamber volume that gives it."""
    if effect.get("name") != "spring" or effect.get("where") != "supports" or desc.supports is None:
        return None
    k = float(effect["parameters"]["stiffness_n_m"])
    k0 = float(np.mean(support_air_stiffness(desc, payload)))
    if k0 + k <= 0:
        return f"each support's air spring {k0:.4g} N/m declared, {k0 + k:.4g} found: no chamber gives that"
    v0 = float(desc.supports.chamber_volume_m3)
    return (
        f"each support's air spring {k0:.4g} -> {k0 + k:.4g} N/m: a chamber of {v0 * k0 / (k0 + k):.4g} m^3 "
        f"for the declared {v0:g} (n p0 A^2 / V, the preload and exponent as declared)"
    )


#: (effect, where) -> (what it is, its parameter, unit, the [supports] key that says the same)
SUPPORT_NUMBERS = {
    ("coulomb_friction", "supports"): ("support piston's friction", "force_n", "N", "piston_friction_n"),
    ("coulomb_friction", "shoes"): ("support shoe's friction", "force_n", "N", "shoe_friction_n"),
    ("added_mass", "supports"): ("support piston's mass", "mass_kg", "kg", "piston_mass_kg"),
}


def support_number_reading(desc, effect: dict) -> str | None:
    """The line a dry friction at ``supports`` or ``shoes``, or a mass at ``supports``,
    reads as (None for any other effect): each piston's (shoe's) declared and found number."""
    known = SUPPORT_NUMBERS.get((effect.get("name"), effect.get("where")))
    if known is None or desc.supports is None or effect.get("options", {}).get("grows_with", "none") != "none":
        return None
    what, par, unit, key = known
    x0 = float(getattr(desc.supports, key))
    x = x0 + float(effect["parameters"][par])
    return f"each {what} {x0:.4g} -> {x:.4g} {unit} ([supports] {key} = {x:.4g})"


def add_readings(res, desc, payload) -> None:
    """Each effect of ``res.effects_added`` that one description number says the same as
    gets ``reads_as`` (:func:`support_reading`, :func:`support_number_reading`)."""
    for e in res.effects_added:
        line = support_reading(desc, payload, e) or support_number_reading(desc, e) or command_reading(e)
        if line:
            e["reads_as"] = line


def command_reading(effect: dict) -> str | None:
    """A delay of the recorded command as each analog channel's skew against it (the
    replay path reads the two clocks against each other, not which one is off)."""
    if effect.get("name") != "sensor_delay" or effect.get("where") != "channel:valve_command":
        return None
    d = 1e3 * float(effect["parameters"]["delay_s"])
    return (
        f"every analog channel {d:.3g} ms early against the valve command (the controller's channels "
        f"recorded {d:.3g} ms late against the analog recorder's): the clocks, not the valve"
    )


__all__ = ["add_readings", "command_reading", "support_air_stiffness", "support_number_reading", "support_reading"]
