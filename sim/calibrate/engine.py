"""The one search of ``shaketable calibrate``: screen, refine, accept, revisit.

Every residual path runs the same loop (:func:`search`); what a path knows, how it
scores, fits and judges a candidate on its own residual, it brings as an object with the
steps of :class:`SearchPath`:

* the mechanical path (:class:`sim.calibrate.mechsearch.MechStage`): the recorded force
  against the force the declared model needs for the recorded motion; a candidate is a
  least-squares term of that balance (or a sensor's timing), so screening it *is* its
  fit, and it is revisited once, after the last round (backward pass, nested demotion);
* the replay and closed-loop paths (:class:`sim.calibrate.pathsearch.PathState`): the
  model replayed through the records; candidates screened by one replay per parameter
  on short windows, the best few refined by nonlinear least squares, judged best first
  on whole-run replays, the accepted effects revisited after every acceptance from the
  second on (joint refit, backward pass: :mod:`sim.calibrate.revisit`).

Both judge by :mod:`sim.calibrate.acceptance` (held-out error, BIC, parameters off their
bounds with the nested law at a bound, whiteness, plausibility against the table's
scale). The loop here does not know which path it drives.
"""

from __future__ import annotations

from typing import Protocol, runtime_checkable

#: rounds of the forward search at most (one effect taken per round)
MAX_ROUNDS = 5


@runtime_checkable
class SearchPath(Protocol):
    """One residual path's steps of the search; the path holds the current model (the
    declared description plus the effects taken so far) and the rows of ``candidates``."""

    #: revisit the accepted effects after every acceptance (True) or once, after the
    #: last round (False)
    revisit_every_round: bool

    def screen(self, rnd: int) -> object:
        """Every candidate of the round scored against the current model."""

    def choose(self, screened, rnd: int) -> list:
        """The screened candidates worth refining, in the order to refine them."""

    def refine(self, chosen: list, rnd: int) -> list:
        """The chosen candidates fitted, in the order to judge them."""

    def judge(self, chosen: list, refined: list, rnd: int) -> object | None:
        """The refined candidates judged in turn; the one to add (None: none passes)."""

    def record(self, screened, chosen: list, refined: list, winner, rnd: int) -> None:
        """The rows of the candidates the judgement did not reach."""

    def take(self, winner, rnd: int) -> None:
        """The winner added to the current model."""

    def revisit(self, rnd: int | None) -> None:
        """The accepted effects looked at again, together (``rnd`` None: after the last round)."""

    def outputs(self) -> object:
        """What the search found, as the path reports it."""


def rounds(path: SearchPath, max_rounds: int) -> int:
    """The forward rounds: screen, choose, refine, judge, take the winner, until a round
    accepts nothing or ``max_rounds`` are done (revisiting after each acceptance when the
    path does so). Returns the rounds that took an effect."""
    taken = 0
    for rnd in range(max_rounds):
        screened = path.screen(rnd)
        chosen = path.choose(screened, rnd)
        refined = path.refine(chosen, rnd)
        winner = path.judge(chosen, refined, rnd)
        path.record(screened, chosen, refined, winner, rnd)
        if winner is None:
            break
        path.take(winner, rnd)
        taken += 1
        if path.revisit_every_round:
            path.revisit(rnd)
    return taken


def search(path: SearchPath, max_rounds: int):
    """The whole search on one path: :func:`rounds`, the revisit after the last round
    (for a path that does not revisit each round), and the path's outputs."""
    rounds(path, max_rounds)
    if not path.revisit_every_round:
        path.revisit(None)
    return path.outputs()


__all__ = ["MAX_ROUNDS", "SearchPath", "rounds", "search"]
