"""The worlds of issue 22's defects 1-5: a configuration and a fault schedule each, as the
issue tells them (used by test_defects.py and by ``python -m tests.simulation --defect N``);
and a world for each family of violations not yet fixed on main (``world.UNFIXED``)."""

from __future__ import annotations

from dataclasses import replace

from .world import UNFIXED, Config, Episode, Result, World

#: One connect() session, 16 tasks, UDP unit 1 answering normally unless told.
BASE = Config(
    units=1,
    relays=frozenset(),
    fixed=frozenset(),
    timeout=0.2,
    retries=0,
    max_sid_spaces=4,
    max_in_flight=255,
    connect_sessions=1,
    connect_tasks=16,
    tcp_sessions=0,
    pool_tasks=0,
    poller_groups=0,
    poll_interval=0.05,
    think=0.0,
    mean_gap=1.0,
)

#: defect -> (what the issue says, the configuration, the schedule, steps, seed)
DEFECTS: dict[int, tuple[str, Config, list[Episode], int, int]] = {
    1: (
        "a breaker probe on the Poller's path never reports: silence 0.6 s, wrong SIDs 0.6 s",
        replace(BASE, connect_sessions=0, poller_groups=1, max_in_flight=5),
        [Episode(0.5, 0.6, 1, "silence", 1.0), Episode(1.1, 0.6, 1, "wrong_sid", 1.0)],
        1000,
        1,
    ),
    2: (
        "extra SID spaces behind a unit that replies to one fixed port",
        replace(BASE, fixed=frozenset({1})),
        [Episode(0.2, 1.0, 1, "dup", 0.3)],
        30000,
        0,
    ),
    3: (
        "a late relay error reaches a request to another destination that reused the SID",
        replace(BASE, relays=frozenset({1}), connect_tasks=8, max_in_flight=16, max_sid_spaces=1),
        [Episode(0.2, 3.0, 1, "relay", 0.3)],
        8000,
        1,
    ),
    4: (
        "max_sid_spaces=1: after the faults, no free SID for long (all quarantined)",
        replace(BASE, relays=frozenset({1}), max_in_flight=255, max_sid_spaces=1),
        [Episode(0.2, 3.0, 1, "relay", 0.1)],
        30000,
        1,
    ),
    5: (
        "replies duplicated up to 0.3 s late while SIDs wrap at a high rate",
        BASE,
        [Episode(0.05, 20.0, 1, "dup", 1.0)],
        40000,
        1,
    ),
}


def run_defect(number: int) -> Result:
    _, config, schedule, steps, seed = DEFECTS[number]
    world = World(seed, steps, schedule=schedule, config=config)
    world.command = f"python -m tests.simulation --defect {number}"
    return world.run()


#: A world for each kind of violation in ``world.UNFIXED``: (what it shows, the
#: configuration, the schedule, steps, seeds). It fails on main while the family is not
#: fixed (any of its seeds showing a violation of that kind); test_defects.py runs it as a
#: strict xfail. Pinned configurations and schedules (found by the soak), so that a change
#: of the generator leaves them alone.
UNFIXED_WORLDS: dict[str, tuple[str, Config, list[Episode], int, tuple[int, ...]]] = {
    "defect 5 (a late duplicate taken for a new reply)": (
        "4 spaces, 1 session x 32 tasks, timeout 0.1 s, retries 0: 5 % of replies"
        " duplicated up to 0.3 s late from the start; at ~4,000 reads a second a SID comes"
        " round every few ms, and a copy 87 ms late of a reply the SID carried five uses"
        " ago, received before the link's first duplicate was seen (so neither kept nor"
        " compared: the session keeps the recent replies of each SID only once the link"
        " has shown duplicates), answers a read of the same length: it returns the other"
        " read's words (soak seed 30485 itself, its schedule to the last digit; the worlds"
        " of seed 30263, late replies then duplicates, of seed 40079, a copy of the SID's"
        " last reply to a read without retries, and this configuration's seed 4, a copy of"
        " an older reply once the link had shown duplicates, pass since this family was"
        " narrowed)",
        replace(
            BASE,
            timeout=0.1,
            max_sid_spaces=4,
            connect_sessions=1,
            connect_tasks=32,
            think=0.001,
            mean_gap=0.01,
            storm=True,
        ),
        [Episode(0.00711489360145835, 0.38255768741480084, 1, "dup", 0.05)],
        20000,
        (30485,),
    ),
}
# (The "no free SID after the faults" family's world, soak seed 20047's: fixed by a598f59,
# only a copy of a SID's last reply teaches the linger; tests/session/test_duplicates.py.)
assert set(UNFIXED_WORLDS) == UNFIXED, "every unfixed family needs its world (and no more)"


def run_unfixed(kind: str) -> list[Result]:
    """The runs of ``kind``'s world, one per seed."""
    _, config, schedule, steps, seeds = UNFIXED_WORLDS[kind]
    results = []
    for seed in seeds:
        world = World(seed, steps, schedule=schedule, config=config)
        world.command = f"python -m tests.simulation --unfixed  # its seed {seed}"
        results.append(world.run())
    return results
