"""The reason a candidate is refused says what its held-out error did (issue 24: a
message said the error "falls by less than 5 %" when it rose)."""

from sim.calibrate.search import accept_numbers, holdout_not_enough


def test_a_rise_is_called_a_rise():
    assert holdout_not_enough(0.10, 0.12, 0.05) == "held-out error 0.1000 -> 0.1200 rose (by 20 %)"
    assert "falls" not in accept_numbers(0.10, 0.12, 0.0, -1.0, 1.0, 1.0)[1]


def test_a_small_fall_and_no_change():
    assert holdout_not_enough(0.10, 0.098, 0.05) == "held-out error 0.1000 -> 0.0980 falls by less than 5 %"
    assert holdout_not_enough(0.10, 0.10, 0.05) == "held-out error 0.1000 -> 0.1000 did not change"
