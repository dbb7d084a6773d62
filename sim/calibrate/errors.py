"""The calibration's user error (one line: file, field, fix), below every module that raises it."""

from __future__ import annotations

from sim.errors import UserError


class CalibrationError(UserError):
    """Runs that cannot be calibrated together (one line: file, field, fix)."""


__all__ = ["CalibrationError"]
