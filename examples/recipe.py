"""Read a recipe's setpoints, or load a recipe from a JSON file and read it back.

A recipe table in DM: recipe N (0-99) is 20 words from D1000 + 20*N, read (and written) in
one frame each way. Its fields, as a PLC program would declare them:

    name         D+0   string:16 (8 words)
    temperature  D+8   float32   setpoint, degrees C
    mix_time     D+10  uint16    seconds
    speed        D+11  int16     rpm, negative turns backwards
    pressure     D+12  int32     limit, Pa

    python examples/recipe.py 3                         # print recipe 3
    python examples/recipe.py 3 --load recipe3.json     # write it, then print it
    PLC_URL=udp://192.168.250.1 python examples/recipe.py 3

recipe3.json: {"name": "BROWN BREAD", "temperature": 182.5, "mix_time": 420, ...}; fields
it leaves out keep their values in the PLC.
"""

from __future__ import annotations

import argparse
import json
import os

import anyio

import aiofins

PLC_URL = os.environ.get("PLC_URL", "udp://127.0.0.1")

TABLE = 1000  # D1000: recipe 0
SIZE = 20  # words per recipe
FIELDS = {  # name: (offset in words, value type)
    "name": (0, "string:16"),
    "temperature": (8, "float32"),
    "mix_time": (10, "uint16"),
    "speed": (11, "int16"),
    "pressure": (12, "int32"),
}


def tags(recipe: int) -> dict[str, str]:
    """The recipe's fields as a tag list: ``{"temperature": "D1068:float32", ...}``."""
    base = TABLE + SIZE * recipe
    return {name: f"D{base + offset}:{vtype}" for name, (offset, vtype) in FIELDS.items()}


async def main(recipe: int, load: str | None) -> None:
    async with aiofins.connect(PLC_URL, timeout=2.0) as plc:
        if load is not None:
            with open(load) as file:
                values = json.load(file)
            unknown = set(values) - set(FIELDS)
            if unknown:
                raise SystemExit(f"{load}: unknown fields {sorted(unknown)}; known: {list(FIELDS)}")
            for name, value in values.items():
                offset, vtype = FIELDS[name]
                await plc.write_value(f"D{TABLE + SIZE * recipe + offset}", value, vtype)
        setpoints = await plc.read_tags(tags(recipe))  # one frame for the whole recipe
    print(f"recipe {recipe} at D{TABLE + SIZE * recipe}:")
    for name, value in setpoints.items():
        print(f"  {name:<12} {value!r}")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("recipe", type=int, choices=range(100), metavar="RECIPE", help="0-99")
    parser.add_argument("--load", metavar="FILE.json", help="write these setpoints first")
    args = parser.parse_args()
    anyio.run(main, args.recipe, args.load)
