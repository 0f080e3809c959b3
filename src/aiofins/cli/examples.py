"""The examples at the end of each subcommand's ``--help``, in one table.

:func:`~aiofins.cli.build_parser` puts them in the parsers' epilogs (and gives a subcommand
without a description its one-line help as description), so every ``--help`` ends the same
way. Each line that starts with ``aiofins`` is a command line the parser accepts (the test
suite parses every one).
"""

from __future__ import annotations

import argparse

#: Examples by subcommand: lines of ``aiofins ...`` commands, each with a short comment.
EXAMPLES: dict[str, str] = {
    "read": """
  aiofins read udp://192.168.250.1 D100 10            # 10 words from D100
  aiofins read udp://192.168.250.1 "CIO 0.01"         # one bit (0 or 1)
  aiofins read udp://192.168.250.1 D200 --type float32 --json
  aiofins read tcp://plc.local:9600 E3_100 4 --type int32:ABCD
  aiofins read udp://10.0.0.5 D0 --dest 0.5.0 --timeout 0.5
""",
    "write": """
  aiofins write udp://192.168.250.1 D100 1 2 0x10     # three words
  aiofins write udp://192.168.250.1 "CIO 0.00" 1 0 1  # three bits
  aiofins write udp://192.168.250.1 D200 21.5 --type float32
  aiofins write udp://192.168.250.1 D20 --type float64 -- -1e10
  aiofins write udp://192.168.250.1 D0 0 0 0 --allow-split
""",
    "status": """
  aiofins status udp://192.168.250.1                  # mode, errors, message
  aiofins status udp://192.168.250.1 --json
""",
    "info": """
  aiofins info udp://192.168.250.1                    # model, version, area sizes
  aiofins info tcp://192.168.250.1 --json
""",
    "clock": """
  aiofins clock udp://192.168.250.1
  aiofins clock udp://192.168.250.1 --json
""",
    "ping": """
  aiofins ping udp://192.168.250.1                    # 4 round trips, in ms
  aiofins ping tcp://192.168.250.1 --count 20 --json
""",
    "run": """
  aiofins run udp://192.168.250.1                     # MONITOR mode (asks first)
  aiofins run udp://192.168.250.1 --mode run --yes    # RUN mode, no question
""",
    "stop": """
  aiofins stop udp://192.168.250.1 --yes              # switch to PROGRAM mode
""",
    "poll": """
  aiofins poll udp://192.168.250.1 D100 "CIO 0.01"
  aiofins poll udp://192.168.250.1 temp=D200:float32 run=CIO0.00 --interval 0.5
  aiofins poll udp://192.168.250.1 temp=D200:float32 --changes-only --json
  aiofins poll udp://192.168.250.1 D0 --count 10      # 10 scans, then exit
""",
    "backup": """
  aiofins backup udp://192.168.250.1 program.bin      # the program area, raw bytes
  aiofins backup udp://192.168.250.1 params.json --what parameters
""",
    "restore": """
  aiofins restore udp://192.168.250.1 program.bin --stop   # PROGRAM mode first
  aiofins restore udp://192.168.250.1 params.json --what parameters --stop
""",
    "files": """
  aiofins files udp://192.168.250.1 list --json       # the memory card's root
  aiofins files udp://192.168.250.1 list --disk em --directory LOGS
  aiofins files udp://192.168.250.1 get RECIPE.CSV recipe.csv
  aiofins files udp://192.168.250.1 put RECIPE.CSV recipe.csv
  aiofins files udp://192.168.250.1 delete OLD.CSV
""",
    "simulate": """
  aiofins simulate                                    # UDP and TCP 127.0.0.1:9600
  aiofins simulate --udp 127.0.0.1:9601 --node 5 --mode program
  aiofins simulate --drop 0.1 --delay 5-50 --seed 1   # a lossy, slow network
  aiofins simulate --end-code 2101 --end-code-probability 0.5
""",
    "demo": """
  aiofins demo                                        # 10 seconds of live values
  aiofins demo --duration 60 --interval 0.2
""",
}

#: The examples under ``aiofins --help``.
MAIN_EXAMPLES = """
  aiofins demo                                        # see it work, no PLC needed
  aiofins simulate &                                  # a virtual PLC on 127.0.0.1:9600
  aiofins read udp://127.0.0.1 D100 3 --json
  aiofins COMMAND --help                              # each command's options and examples
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
