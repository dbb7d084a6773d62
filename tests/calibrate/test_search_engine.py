"""The one search loop (sim/calibrate/engine.py): the steps in order on any path, the
revisit when the path says, and both residual paths plug into it."""

from __future__ import annotations

import inspect

import pytest

from sim.calibrate import engine as E
from sim.calibrate.mechsearch import MechStage
from sim.calibrate.pathsearch import PathState


class Fake:
    """A path that accepts the candidates of ``wins`` (one per round, None: none passes)."""

    def __init__(self, wins, every_round):
        self.wins, self.revisit_every_round, self.log = list(wins), every_round, []

    def screen(self, rnd):
        self.log.append(("screen", rnd))
        return [f"s{rnd}"]

    def choose(self, screened, rnd):
        self.log.append(("choose", rnd, screened))
        return [f"c{rnd}"]

    def refine(self, chosen, rnd):
        self.log.append(("refine", rnd, chosen))
        return [f"r{rnd}"]

    def judge(self, chosen, refined, rnd):
        self.log.append(("judge", rnd, chosen, refined))
        return self.wins[rnd] if rnd < len(self.wins) else None

    def record(self, screened, chosen, refined, winner, rnd):
        self.log.append(("record", rnd, winner))

    def take(self, winner, rnd):
        self.log.append(("take", rnd, winner))

    def revisit(self, rnd):
        self.log.append(("revisit", rnd))

    def outputs(self):
        return [x for x in self.log if x[0] in ("take", "revisit")]


def test_rounds_run_each_step_in_order_until_nothing_is_taken():
    p = Fake(["a", "b", None], every_round=True)
    out = E.search(p, max_rounds=5)
    assert [x[0] for x in p.log[:6]] == ["screen", "choose", "refine", "judge", "record", "take"]
    assert ("choose", 0, ["s0"]) in p.log and ("judge", 0, ["c0"], ["r0"]) in p.log
    assert out == [("take", 0, "a"), ("revisit", 0), ("take", 1, "b"), ("revisit", 1)]
    assert ("record", 2, None) in p.log and ("screen", 3) not in p.log


def test_a_path_that_revisits_at_the_end_is_revisited_once_after_the_last_round():
    p = Fake(["a", "b", "c"], every_round=False)
    assert E.search(p, max_rounds=2) == [("take", 0, "a"), ("take", 1, "b"), ("revisit", None)]
    q = Fake([None], every_round=False)
    assert E.search(q, max_rounds=5) == [("revisit", None)]
    assert E.rounds(Fake(["a"], every_round=False), max_rounds=3) == 1  # rounds alone: no revisit


@pytest.mark.parametrize("cls", [MechStage, PathState])
def test_both_residual_paths_implement_the_engines_steps(cls):
    steps = [n for n, f in inspect.getmembers(E.SearchPath, inspect.isfunction) if not n.startswith("_")]
    assert sorted(steps) == ["choose", "judge", "outputs", "record", "refine", "revisit", "screen", "take"]
    for name in steps:
        want = list(inspect.signature(getattr(E.SearchPath, name)).parameters)
        got = list(inspect.signature(getattr(cls, name)).parameters)
        assert len(got) == len(want), (cls.__name__, name, got, want)
    assert isinstance(cls.revisit_every_round, bool)


def test_the_engine_names_no_path():
    src = inspect.getsource(E).split('"""', 2)[2]  # the code, past the module's docstring
    for word in ("mechanical", "replay", "closed", "mechsearch", "pathsearch"):
        assert word not in src, word
