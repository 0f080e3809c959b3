"""Issue 22's defects, each as a world the harness must find it in (scenarios.py).

Each test failed on main before its fix (the harness found the defect: report-sim.md) and
was marked ``xfail(strict=True)`` naming it until the fix landed (then strict xfail failed,
and the mark went). All five are fixed on main.
"""

from __future__ import annotations

from .scenarios import DEFECTS, run_defect


def _clean(number: int) -> None:
    result = run_defect(number)
    assert result.violation is None, result.reproducer()


def test_defect_1_the_poller_recovers_after_silence_then_wrong_sids() -> None:
    _clean(1)


def test_defect_2_extra_spaces_behind_a_fixed_reply_port() -> None:
    _clean(2)


def test_defect_3_a_late_relay_error_names_its_own_request() -> None:
    _clean(3)


def test_defect_4_one_sid_space_recovers_after_the_faults() -> None:
    _clean(4)


def test_defect_5_late_duplicates_while_sids_wrap() -> None:
    _clean(5)


def test_every_defect_has_a_world() -> None:
    assert sorted(DEFECTS) == [1, 2, 3, 4, 5]
