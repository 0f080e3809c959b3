"""``aiofins restore``: what the command line says about the PLC's mode."""

from __future__ import annotations

from pathlib import Path

import pytest

from aiofins.cli import main
from aiofins.simulator import VirtualPLC
from aiofins.simulator.state import Mode


@pytest.mark.parametrize("what", ["program", "parameters"])
def test_restore_in_run_mode_says_which_option_to_use(
    what: str, url: str, plc: VirtualPLC, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    backup = tmp_path / "backup"
    assert main(["backup", url, str(backup), "--what", what]) == 0
    before = bytes(plc.program) if what == "program" else None
    capsys.readouterr()

    assert main(["restore", url, str(backup), "--what", what]) == 1
    err = capsys.readouterr().err
    assert "the PLC is in RUN mode; restoring needs PROGRAM mode: add --stop" in err
    assert "client.stop()" not in err
    assert plc.mode is Mode.RUN  # nothing was changed
    if before is not None:
        assert bytes(plc.program) == before

    assert main(["restore", url, str(backup), "--what", what, "--stop"]) == 0
    assert Mode(plc.mode) is Mode.PROGRAM  # --stop switched modes first
