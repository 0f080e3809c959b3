"""Issue 22's defects, each as a world the harness must find it in (scenarios.py).

Each test failed on main before its fix (the harness found the defect: report-sim.md) and
was marked ``xfail(strict=True)`` naming it until the fix landed (then strict xfail failed,
and the mark went). All five are fixed on main.

The families the soak found and main has not fixed yet (``world.UNFIXED``, allowed by the
slice) run the same way: each its world, a strict xfail, so that the fix is noticed; and
the soak's worlds of families fixed since (``scenarios.REGRESSIONS``) must stay clean.
"""

from __future__ import annotations

import pytest

from .scenarios import DEFECTS, REGRESSIONS, UNFIXED_WORLDS, run_defect, run_regression, run_unfixed
from .world import UNFIXED, suspect


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


@pytest.mark.parametrize("name", sorted(REGRESSIONS))
def test_a_pinned_world_of_a_fixed_family_stays_clean(name: str) -> None:
    """Each world the soak found a violation in, fixed since (scenarios.REGRESSIONS)."""
    result = run_regression(name)
    assert result.violation is None, result.reproducer()
    assert result.steps >= REGRESSIONS[name][3]


@pytest.mark.parametrize(
    "kind",
    [pytest.param(k, marks=pytest.mark.xfail(strict=True, reason=k)) for k in sorted(UNFIXED)],
)
def test_an_unfixed_family_shows_in_its_world(kind: str) -> None:
    """Fails while the family is not fixed (every seed of its world clean: fixed; then
    remove it from world.UNFIXED and its world, which makes this a plain pass)."""
    found = [r for r in run_unfixed(kind) if r.violation is not None]
    for r in found:
        print(r.reproducer())
    assert not [r for r in found if suspect(r) == kind]
    assert not found  # (another kind: a finding of its own)


def test_every_unfixed_family_has_a_world() -> None:
    assert set(UNFIXED_WORLDS) == UNFIXED
