"""User-facing errors.

Anything the user can fix (a wrong file, a missing channel, a bad parameter) raises a
subclass of :class:`UserError` with a one-line message that names the problem and the
fix. The CLI prints that line and exits with code 2, without a traceback. Anything else
is a bug and keeps its traceback.
"""


class UserError(Exception):
    """A problem with the user's input: printed as one line, exit code 2."""


class RunFileError(UserError):
    """A run file that is not in the shaketable-run/1 format, or lacks a needed channel."""


class MotionError(UserError):
    """A motion or record that cannot be turned into a table reference."""


class ScenarioError(UserError):
    """A scenario file with a missing, unknown or invalid key."""


class DivergenceError(Exception):
    """The simulation left its physical bounds; carries the time and the reason."""

    def __init__(self, time_s: float, reason: str):
        super().__init__(f"simulation diverged at t = {time_s:.4f} s: {reason}")
        self.time_s = time_s
        self.reason = reason


class RunInterrupted(KeyboardInterrupt):
    """Ctrl-C inside a simulation loop: a :class:`KeyboardInterrupt` (so whoever does not
    catch it stops as before) that carries what was computed up to then in ``result``
    (a :class:`sim.loop.simulation.RunResult` marked incomplete), for a caller that can
    keep it in a run file."""

    def __init__(self, result):
        super().__init__(result.incomplete_reason or "interrupted")
        self.result = result


def is_interrupt(e: BaseException | None) -> bool:
    """Whether ``e`` is a Ctrl-C: a KeyboardInterrupt, or an exception raised from one
    (a signal that lands while a compiled numba function is called comes back as
    ``SystemError: ... returned a result with an exception set``, caused by the
    KeyboardInterrupt)."""
    seen = set()
    while e is not None and id(e) not in seen:
        if isinstance(e, KeyboardInterrupt):
            return True
        seen.add(id(e))
        e = e.__cause__ or e.__context__
    return False


def user_errors() -> tuple[type[BaseException], ...]:
    """Every exception class a user can fix: ``sim``'s own, the model layer's
    (:class:`mjcf.errors.MjcfError`) and the hydraulic parameters'. The layers below
    ``sim`` import nothing from it, so their errors are gathered here."""
    from hydraulics import HydraulicsParamError
    from mjcf.errors import MjcfError

    return (UserError, MjcfError, HydraulicsParamError)
