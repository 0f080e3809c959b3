"""The examples at the end of each subcommand's ``--help``, in one table.

:func:`~aiofins.cli.build_parser` puts them in the parsers' epilogs (and gives a subcommand
without a description its one-line help as description), so every ``--help`` ends the same
way. Each line that starts with ``aiofins`` is a command line the parser accepts (the test
suite parses every one).
"""

from __future__ import annotations

import argparse

#: Examples by subcommand: ``aiofins ...`` command lines, each after a ``#`` comment line.
EXAMPLES: dict[str, str] = {
    "read": """
  # 10 words from D100, one bit, a float as JSON
  aiofins read udp://192.168.250.1 D100 10
  aiofins read udp://192.168.250.1 "CIO 0.01"
  aiofins read udp://192.168.250.1 D200 --type float32 --json
  # 32-bit integers, high word first, over FINS/TCP
  aiofins read tcp://192.168.250.1:9600 E3_100 4 --type int32:ABCD
  # a PLC whose FINS node is 5, not the last octet of its IP address
  aiofins read udp://10.0.0.5 D0 --dest 0.5.0 --timeout 0.5
""",
    "write": """
  # three words (0x.. is hex), then three bits
  aiofins write udp://192.168.250.1 D100 1 2 0x10
  aiofins write udp://192.168.250.1 "CIO 0.00" 1 0 1
  # typed values; -- before a value that starts with -
  aiofins write udp://192.168.250.1 D200 21.5 --type float32
  aiofins write udp://192.168.250.1 D20 --type float64 -- -1e10
""",
    "status": """
  # mode, error flags, error message
  aiofins status udp://192.168.250.1
  aiofins status udp://192.168.250.1 --json
""",
    "info": """
  # model, version, area sizes
  aiofins info udp://192.168.250.1
  aiofins info tcp://192.168.250.1 --json
""",
    "clock": """
  # the PLC's clock
  aiofins clock udp://192.168.250.1
  aiofins clock udp://192.168.250.1 --json
  # set it to this computer's local time, or to a given time, without asking
  aiofins clock udp://192.168.250.1 --set --yes
  aiofins clock udp://192.168.250.1 --set 2026-01-02T03:04:05 --yes
""",
    "ping": """
  # 4 round trips, in ms; 20 over FINS/TCP as JSON
  aiofins ping udp://192.168.250.1
  aiofins ping tcp://192.168.250.1 --count 20 --json
""",
    "run": """
  # MONITOR mode (asks first on a terminal); RUN mode without asking
  aiofins run udp://192.168.250.1
  aiofins run udp://192.168.250.1 --mode run --yes
""",
    "stop": """
  # PROGRAM mode, without asking
  aiofins stop udp://192.168.250.1 --yes
""",
    "poll": """
  # two tags every second, until Ctrl-C
  aiofins poll udp://192.168.250.1 D100 "CIO 0.01"
  # named, typed tags every 0.5 s
  aiofins poll udp://192.168.250.1 temp=D200:float32 run=CIO0.00 --interval 0.5
  # one JSON line per scan that changed something
  aiofins poll udp://192.168.250.1 temp=D200:float32 --changes-only --json
  # 10 scans, then exit
  aiofins poll udp://192.168.250.1 D0 --count 10
  # the tags of a CX-Programmer symbol table (or a name,address,type CSV)
  aiofins poll udp://192.168.250.1 --tags symbols.csv
""",
    "watch": """
  # values and a trend per tag, redrawn every 0.5 s, until Ctrl-C
  aiofins watch udp://127.0.0.1 temp=D100:float32 pressure=D102:int32 run="CIO 0.00"
  # a longer trend, one scan a second, the tags of a symbol table
  aiofins watch udp://192.168.250.1 --tags symbols.csv --interval 1 --history 60
""",
    "doctor": """
  # what is wrong with a connection, and the fix (exit code 0: nothing)
  aiofins doctor udp://192.168.250.1
  aiofins doctor tcp://192.168.250.1 --json
  # also see whether writes are refused (writes D100's own value back)
  aiofins doctor udp://192.168.250.1 --write-test --address D100
""",
    "backup": """
  # the program area (raw bytes), the parameter areas (JSON)
  aiofins backup udp://192.168.250.1 program.bin
  aiofins backup udp://192.168.250.1 params.json --what parameters
""",
    "restore": """
  # switch the PLC to PROGRAM mode, then write the backup back
  aiofins restore udp://192.168.250.1 program.bin --stop
  aiofins restore udp://192.168.250.1 params.json --what parameters --stop
""",
    "files": """
  # the memory card's root, EM file memory's LOGS directory
  aiofins files udp://192.168.250.1 list --json
  aiofins files udp://192.168.250.1 list --disk em --directory LOGS
  # copy a file from and to the PLC, delete one
  aiofins files udp://192.168.250.1 get RECIPE.CSV recipe.csv
  aiofins files udp://192.168.250.1 put RECIPE.CSV recipe.csv
  aiofins files udp://192.168.250.1 delete OLD.CSV
""",
    "simulate": """
  # UDP and TCP on 127.0.0.1:9600
  aiofins simulate
  # node 5 on another port, in PROGRAM mode
  aiofins simulate --udp 127.0.0.1:9601 --node 5 --mode program
  # a lossy, slow network (the same faults for the same seed)
  aiofins simulate --drop 0.1 --delay 5-50 --seed 1
  # every other response is end code 2101
  aiofins simulate --end-code 2101 --end-code-probability 0.5
""",
    "gateway": """
  # check a configuration, then run it
  aiofins gateway gateway.toml --check
  aiofins gateway gateway.toml
  # the first of three shards (or AIOFINS_SHARD=0/3)
  aiofins gateway gateway.toml --shard 0/3
""",
    "demo": """
  # 10 seconds of live values; a minute, polled every 0.2 s
  aiofins demo
  aiofins demo --duration 60 --interval 0.2
""",
}

#: The examples under ``aiofins --help``.
MAIN_EXAMPLES = """
  # see it work, no PLC needed
  aiofins demo
  # a virtual PLC on 127.0.0.1:9600, then a read from it
  aiofins simulate &
  aiofins read udp://127.0.0.1 D100 3 --json
  # each command's options and examples
  aiofins COMMAND --help
"""


def epilog(examples: str) -> str:
    """The ``examples:`` section of a help text."""
    return EPILOG_START + examples.rstrip()


EPILOG_START = "examples:"


class HelpFormatter(argparse.HelpFormatter):
    """argparse's formatter, but the examples keep their lines (descriptions still wrap)."""

    def _fill_text(self, text: str, width: int, indent: str) -> str:
        if text.startswith(EPILOG_START):
            return "".join(indent + line for line in text.splitlines(keepends=True))
        return super()._fill_text(text, width, indent)
