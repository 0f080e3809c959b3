"""Tag lists compile into the fewest frames, and decode back into typed values."""

from __future__ import annotations

import pytest
from hypothesis import given
from hypothesis import strategies as st

from aiofins.protocol.areas import MemoryAddress
from aiofins.protocol.errors import CommandError, DecodeError
from aiofins.protocol.values import parse_value_type
from aiofins.tags import ReadPlan, WordRun, compile_tags


def test_neighbouring_words_and_bits_share_one_frame() -> None:
    plan = compile_tags(
        {"temp": "D100:float32", "count": "D102:uint32", "flag": "D104.03", "raw": "D110"}
    )
    assert plan.runs == (WordRun(0x82, 100, 11),)
    assert plan.multiple == ()
    assert plan.frame_count == 1


def test_bits_of_one_word_cost_one_word() -> None:
    plan = compile_tags({"a": "CIO 0.00", "b": "CIO 0.01", "c": "CIO 0.15", "w": "CIO 0"})
    assert plan.runs == (WordRun(0xB0, 0, 1),)


def test_scattered_words_go_to_one_multiple_read() -> None:
    tags = {f"t{i}": f"D{i * 1000}" for i in range(10)}
    plan = compile_tags(tags)
    assert plan.runs == ()
    assert len(plan.multiple) == 1
    assert plan.multiple[0] == tuple(MemoryAddress(0x82, i * 1000, 0) for i in range(10))


def test_long_runs_stay_0101_and_isolated_words_join_0104() -> None:
    tags = {"block": "D0:string:400", "x": "W5", "y": "H7", "z": "D5000"}
    plan = compile_tags(tags)
    assert plan.runs == (WordRun(0x82, 0, 200),)
    assert sorted(a.area_code for a in plan.multiple[0]) == [0x82, 0xB1, 0xB2]
    assert plan.frame_count == 2


def test_gap_setting_and_route_limit() -> None:
    tags = {"a": "D0", "b": "D20"}
    assert compile_tags(tags, max_gap=19).runs == (WordRun(0x82, 0, 21),)
    assert compile_tags(tags, max_gap=18).frame_count == 1  # both words in one 0104
    wide = {"a": "D0", "b": "D300"}
    plan = compile_tags(wide, max_gap=400, max_read_words=269)
    assert plan.frame_count == 1  # 301 words would exceed 269: two single words in 0104


def test_a_short_block_and_scattered_words_fit_one_multiple_read() -> None:
    tags = {"block": "D0:string:200", "x": "W5", "y": "H7"}
    assert compile_tags(tags).frame_count == 1


def test_decode_gives_typed_values() -> None:
    plan = compile_tags({"temp": "D100:float32", "flag": "D102.01", "n": "D103:int16"})
    words = [0x0000, 0x3FC0, 0x0002, 0xFFFF]
    assert plan.decode([words], []) == {"temp": 1.5, "flag": True, "n": -1}


def test_values_decode_in_tag_order_without_a_dict() -> None:
    """Numbers, bits and words of one frame come back as a tuple in the tag list's order
    (bits between numbers too); the names and their positions are shared per plan."""
    plan = compile_tags(
        {"flag": "D102.01", "temp": "D100:float32", "n": "D103:int16", "u": "D104:uint32"}
    )
    words = [0x0000, 0x3FC0, 0x0002, 0xFFFF, 0x0001, 0x0002]
    assert plan.decode_values([words], []) == (True, 1.5, -1, 0x20001)
    assert plan.tag_names is plan.tag_names
    assert plan.tag_names.names == ("flag", "temp", "n", "u")
    assert plan.tag_names.index == {"flag": 0, "temp": 1, "n": 2, "u": 3}
    with pytest.raises(DecodeError, match=r"expected 6 words, got 5"):
        plan.decode_values([words[:5]], [])
    assert plan.decode_values([[*words[:5], 0x10000]], []) is None  # not from a reply
    one = compile_tags({"only": "D7:int16"})
    assert one.decode_values([[0xFFFE]], []) == (-2,)
    tags = {"a": "D0", "b": "D500", "c": "D1000.02"}
    several = compile_tags(tags, max_multiple_elements=1)
    assert several.frame_count == 3
    assert several.decode_values([[1], [2], [4]], []) == (1, 2, True)
    multiple = compile_tags(tags)
    assert multiple.decode_values([], [[1, 2, 4]]) == (1, 2, True)
    # BCD, strings and swapped word orders are decoded by name (decode), never here.
    assert compile_tags({"b": "D0:bcd16"}).decode_values([[0x12]], []) is None
    assert compile_tags({"s": "D0:uint32:BADC"}).decode_values([[1, 2]], []) is None


REPLY_HEAD = bytes.fromhex("c00002000100000100070101") + b"\x00\x00"  # 0101 reply, end 0000


def words_frame(words: list[int]) -> bytes:
    return REPLY_HEAD + b"".join(w.to_bytes(2, "big") for w in words)


@given(st.lists(st.integers(0, 0xFFFF), min_size=6, max_size=6))
def test_a_one_frame_plan_decodes_its_reply_frame_as_its_words(words: list[int]) -> None:
    """frame_decoder: the reply frame straight to the values decode_values gives its words."""
    plan = compile_tags(
        {"flag": "D102.01", "temp": "D100:float32", "n": "D103:int16", "u": "D104:uint32"}
    )
    decode = plan.frame_decoder()
    assert decode is not None and plan.frame_decoder() is decode  # made once per plan
    got = decode(words_frame(words))
    want = plan.decode_values([words], [])
    assert got is not None and want is not None
    assert len(got) == len(want) == 4
    for a, b in zip(got, want, strict=True):
        assert a == b or (a != a and b != b)  # (NaN floats: equal words, unequal values)


def test_frame_decoder_gives_none_where_the_tags_are_decoded_by_name() -> None:
    plan = compile_tags({"temp": "D100:float32", "n": "D102:int16"})
    decode = plan.frame_decoder()
    assert decode is not None
    assert decode(words_frame([0x0000, 0x3FC0, 0xFFFF])) == (1.5, -1)
    assert decode(words_frame([0x0000, 0x3FC0])) is None  # short: decode() says which frame
    assert decode(words_frame([0, 0x3FC0, 0xFFFF, 0])) is None
    assert compile_tags({"b": "D0:bcd16"}).frame_decoder() is None
    assert compile_tags({"s": "D0:uint32:BADC"}).frame_decoder() is None
    tags = {"a": "D0", "b": "D500", "c": "D1000.02"}
    assert compile_tags(tags, max_multiple_elements=1).frame_decoder() is None  # 3 frames
    assert compile_tags(tags).frame_decoder() is None  # one 0104 frame


def test_results_not_matching_the_plans_frames_are_refused() -> None:
    tags = compile_tags({"temp": "D100:float32", "w": "D300"}).tags
    plan = ReadPlan(tags, (WordRun(0x82, 100, 2),), ((MemoryAddress(0x82, 300, 0),),))
    assert plan.decode([[0, 0x3FC0]], [[1]]) == {"temp": 1.5, "w": 1}
    with pytest.raises(DecodeError, match="do not match the plan's frames"):
        plan.decode([[0, 0x3FC0]], [])
    with pytest.raises(DecodeError, match=r"words 100\.\.101: expected 2 words, got 1"):
        plan.decode([[0]], [[1]])
    with pytest.raises(DecodeError, match="0104 result has the wrong number of elements"):
        plan.decode([[0, 0x3FC0]], [[1, 0]])
    # A wrong result once does not spoil the plan for the next, right one.
    assert plan.decode([[0, 0x3FC0]], [[7]]) == {"temp": 1.5, "w": 7}


def test_a_hand_built_plan_missing_a_word_names_the_tag() -> None:
    plan = compile_tags({"temp": "D100:float32"})
    short = ReadPlan(plan.tags, (WordRun(0x82, 100, 1),), ())  # D101 in no frame
    with pytest.raises(DecodeError, match=r"'temp' \(D100\): word 101"):
        short.decode([[0]], [])


def test_bad_tags_are_refused() -> None:
    with pytest.raises(CommandError):
        compile_tags({"a": "CIO 0.01:float32"})
    with pytest.raises(CommandError):
        compile_tags({"a": "D0:nonsense"})


@given(
    st.lists(
        st.tuples(st.integers(0, 2000), st.sampled_from(["uint16", "int32", "float64", "bit"])),
        min_size=1,
        max_size=60,
    ),
    st.integers(0, 20),
    st.sampled_from([(999, 167), (269, 89), (10, 3)]),
)
def test_plan_never_exceeds_limits_and_covers_every_tag(
    items: list[tuple[int, str]], gap: int, limits: tuple[int, int]
) -> None:
    max_words, max_elements = limits
    tags = {}
    for i, (word, kind) in enumerate(items):
        tags[f"t{i}"] = f"D{word}.{i % 16:02d}" if kind == "bit" else f"D{word}:{kind}"
    plan = compile_tags(
        tags, max_gap=gap, max_read_words=max_words, max_multiple_elements=max_elements
    )
    assert all(1 <= r.count <= max_words for r in plan.runs)
    assert all(1 <= len(f) <= max_elements for f in plan.multiple)
    covered = {(r.area_code, r.word + i) for r in plan.runs for i in range(r.count)}
    elements = [(a.area_code, a.word) for f in plan.multiple for a in f]
    assert len(elements) == len(set(elements))  # each element read once
    assert not covered & set(elements)
    for word, kind in items:
        width = 1 if kind == "bit" else parse_value_type(kind).words
        for w in range(word, word + width):
            assert (0x82, w) in covered or (0x82, w) in set(elements)
    # Decoding a plan's own frames works for every tag.
    runs = [[0] * r.count for r in plan.runs]
    multi = [[0] * len(f) for f in plan.multiple]
    assert set(plan.decode(runs, multi)) == set(tags)


_KINDS = ["uint16", "int16", "uint32", "int32", "float32", "uint64", "int64", "float64", "bcd16"]


@given(
    st.lists(
        st.tuples(
            st.integers(0, 40),
            st.sampled_from([*_KINDS, "bit"]),
            st.sampled_from(["", ":CDAB", ":ABCD", ":BADC", ":DCBA"]),
        ),
        min_size=1,
        max_size=30,
    ),
    st.lists(st.integers(0, 0xFFFF), min_size=50, max_size=50),
    st.sampled_from([(999, 167), (5, 4)]),
)
def test_decode_matches_each_types_own_codec(
    items: list[tuple[int, str, str]], memory: list[int], limits: tuple[int, int]
) -> None:
    """The plan decodes its numbers in bulk where it can (Omron's word order), tag by tag
    elsewhere: every value equals its type's own decoding of the tag's words, in the tag
    list's order, whatever the tags' overlaps, orders and frames."""
    tags = {}
    for i, (word, kind, order) in enumerate(items):
        tags[f"t{i}"] = f"D{word}.{i % 16:02d}" if kind == "bit" else f"D{word}:{kind}{order}"
    plan = compile_tags(tags, max_read_words=limits[0], max_multiple_elements=limits[1])
    runs = [memory[r.word : r.word + r.count] for r in plan.runs]
    multi = [[memory[a.word] for a in frame] for frame in plan.multiple]
    expected: dict[str, object] = {}
    failed: set[str] = set()
    for tag in plan.tags:
        if tag.vtype.kind == "bit":
            expected[tag.name] = bool(memory[tag.address.word] >> tag.address.bit & 1)
            continue
        try:
            expected[tag.name] = tag.vtype.decode(
                memory[tag.address.word : tag.address.word + tag.vtype.words]
            )
        except DecodeError:
            failed.add(tag.name)
    errors: dict[str, str] = {}
    for _ in range(2):  # the first decode compiles the plan's steps, the second reuses them
        got = plan.decode(runs, multi, errors)
        assert repr(got) == repr(expected)  # (NaN equals itself here; the order counts too)
        assert set(errors) == failed
        # Without a dict: the same values in the tag list's order, or None (tag by tag).
        values = plan.decode_values(runs, multi)
        assert plan.tag_names.names == tuple(tags)
        if values is not None:
            assert not failed
            assert repr(values) == repr(tuple(expected[name] for name in tags))


def test_words_out_of_range_are_decoded_tag_by_tag() -> None:
    """Words that no reply carries (a hand-made list) still decode, each tag saying what
    its own words are."""
    plan = compile_tags({"temp": "D0:float32", "w": "D2"})
    assert plan.decode([[0, 0x3FC0, 7]], []) == {"temp": 1.5, "w": 7}
    with pytest.raises(DecodeError, match="word value 65536 out of range"):
        plan.decode([[0, 0x3FC0, 0x10000]], [])
