"""The CI slice: 200 seeds x 2,000 steps, every invariant after every step.

A violation prints the one-line reproducer (``python -m tests.simulation --seed S ...``).
While a defect is not fixed on main, violations pointing to it (``world.suspect``) are
allowed here (and reported); any other violation fails. Each defect's own world is a strict
xfail in test_defects.py, which tells when its fix has landed: then its line goes here.
"""

from __future__ import annotations

import pytest

from .world import EXPOSED, UNFIXED, run, suspect

SEEDS = range(200)
STEPS = 2000


def test_200_seeds_of_2000_steps_hold_every_invariant(capsys: pytest.CaptureFixture[str]) -> None:
    found: dict[int, tuple[str, str]] = {}
    steps = 0
    idle: list[int] = []  # a world none of whose clients ran checks nothing
    for seed in SEEDS:
        result = run(seed, STEPS)
        steps += result.steps
        if result.steps == 0:
            idle.append(result.seed)
        if result.violation is not None:
            found[seed] = (suspect(result), result.reproducer())
    assert steps >= len(SEEDS) * STEPS
    assert not idle, f"seeds whose world ran no step: {idle}"
    with capsys.disabled():
        for seed, (kind, line) in sorted(found.items()):
            print(f"\nseed {seed}: {kind}: {line[:300]}")
    unexpected = [line for kind, line in found.values() if kind not in UNFIXED | EXPOSED]
    assert not unexpected, "\n".join(unexpected)
