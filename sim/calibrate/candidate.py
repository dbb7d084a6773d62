"""One effect type at one place as a candidate of the replay and closed-loop paths
(:mod:`sim.calibrate.sensitivity`): its parameters' neutral values, steps and bounds,
and how its internal parameters read as the effect's own."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class Candidate:
    """One effect type at one place, with the parameters fitted (``names``, in the
    order of ``neutral``/``step``/bounds) and fixed entry keys (``fixed``)."""

    type: str
    where: str
    names: tuple
    neutral: np.ndarray
    step: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    units: dict
    screened: tuple = (0,)  # indices of the parameters stepped in the screening
    fixed: dict = field(default_factory=dict)
    sensor: bool = False
    grid: float | None = None  # the parameter (index 0) is realised on this grid
    ref: dict = field(default_factory=dict)  # constants of a transformed parameter (foundation_mode)
    line: tuple | None = None  # the line search's points (internal values), instead of its steps
    #: points (whole internal vectors) the screening steps from, the best kept (a mode's frequencies)
    scan: tuple | None = None

    @property
    def key(self) -> tuple:
        return (self.type, self.where)

    def values(self, theta) -> dict:
        """Parameter values (the effect's own keys, SI) for the internal ``theta``."""
        if self.type == "sensor_lowpass":  # internal: 1/cutoff (s), neutral 0 = no filter
            return {"cutoff_hz": 1.0 / float(theta[0]) if theta[0] > 0 else math.inf}
        if self.type == "payload_mode":  # internal: (mass, log f, damping)
            return {
                "mass_kg": float(theta[0]),
                "frequency_hz": math.exp(float(theta[1])),
                "damping_ratio": float(theta[2]),
            }
        if self.type == "foundation_mode":  # internal: compliance s = (f_ref / f)^2, 0 = rigid
            s = float(theta[0])
            out = {"frequency_hz": self.ref["f_ref"] / math.sqrt(s) if s > 0 else math.inf}
            if self.ref.get("fz_ref"):
                out["frequency_z_hz"] = self.ref["fz_ref"] / math.sqrt(s) if s > 0 else math.inf
            return {**out, **self.ref["held"], **{k: float(v) for k, v in zip(self.names[1:], theta[1:])}}
        return {k: float(v) for k, v in zip(self.names, theta)}

    def sigmas(self, theta, sigma) -> dict:
        if self.type == "sensor_lowpass":
            return {"cutoff_hz": float(sigma[0]) / float(theta[0]) ** 2 if theta[0] > 0 else math.inf}
        if self.type == "payload_mode":  # df = f d(log f)
            f = math.exp(float(theta[1]))
            return {"mass_kg": float(sigma[0]), "frequency_hz": f * float(sigma[1]), "damping_ratio": float(sigma[2])}
        if self.type == "foundation_mode":  # df = f_ref / (2 s^1.5) ds (the held values: no interval)
            s = float(theta[0])
            d = 0.5 * float(sigma[0]) / s**1.5 if s > 0 else math.inf
            out = {"frequency_hz": self.ref["f_ref"] * d}
            if self.ref.get("fz_ref"):
                out["frequency_z_hz"] = self.ref["fz_ref"] * d
            return {**out, **{k: float(v) for k, v in zip(self.names[1:], sigma[1:])}}
        return {k: float(s) for k, s in zip(self.names, sigma)}

    def entry(self, theta) -> dict:
        return {"type": self.type, "where": self.where, **self.fixed, **self.values(theta)}

    def is_neutral(self, theta) -> bool:
        return bool(np.all(np.asarray(theta) == self.neutral))


__all__ = ["Candidate"]
