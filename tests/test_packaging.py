"""Release hygiene: the version, and a base install without the optional serial packages."""

from __future__ import annotations

import importlib.metadata
import re
import subprocess
import sys
from pathlib import Path

import pytest

import aiofins

ROOT = Path(__file__).resolve().parent.parent

#: Makes the serial packages unimportable, as on a base install (``pip install aiofins``).
WITHOUT_SERIAL = "import sys; sys.modules['serial'] = sys.modules['serial_asyncio_fast'] = None\n"


def _run(code: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", WITHOUT_SERIAL + code],
        capture_output=True,
        text=True,
        timeout=60,
        cwd=ROOT,
    )


def test_version_is_the_distributions() -> None:
    declared = re.search(r'^version = "([^"]+)"', (ROOT / "pyproject.toml").read_text(), re.M)
    assert declared is not None
    assert aiofins.__version__ == importlib.metadata.version("aiofins") == declared.group(1)
    out = subprocess.run(
        [sys.executable, "-m", "aiofins.cli", "--version"], capture_output=True, text=True
    )
    assert out.stdout.strip() == f"aiofins {aiofins.__version__}"


def test_serial_packages_are_an_extra() -> None:
    requires = importlib.metadata.requires("aiofins") or []
    base = [r for r in requires if "extra ==" not in r]
    assert not [r for r in base if "serial" in r], base
    assert any(r.startswith("pyserial-asyncio-fast") and 'extra == "serial"' in r for r in requires)


def test_the_core_depends_on_anyio_only() -> None:
    """The live view's terminal library and the notebook's pandas are extras."""
    requires = importlib.metadata.requires("aiofins") or []
    assert [r for r in requires if "extra ==" not in r] == ["anyio>=4.4"]
    extras = {
        (r.split(";")[0].split(">")[0], r.split('extra == "')[1].split('"')[0])
        for r in requires
        if 'extra == "' in r
    }
    assert {("rich", "watch"), ("pandas", "notebook"), ("matplotlib", "notebook")} <= extras


def test_the_quick_start_works_without_the_serial_packages() -> None:
    """``pip install -e .`` then ``aiofins demo``: the library, the simulator and the CLI."""
    result = _run(
        "import aiofins, aiofins.simulator, aiofins.sync\n"
        "from aiofins.cli import main\n"
        "sys.exit(main(['demo', '--duration', '0.3', '--interval', '0.1']))\n"
    )
    assert result.returncode == 0, result.stderr
    assert "done:" in result.stdout


@pytest.mark.parametrize("backend", ["asyncio", "trio"])
def test_a_serial_url_without_the_extra_says_what_to_install(backend: str) -> None:
    result = _run(
        "import anyio, aiofins\n"
        "async def main():\n"
        "    async with aiofins.connect('serial:///dev/null', timeout=0.5) as plc:\n"
        "        await plc.read('D0')\n"
        "try:\n"
        f"    anyio.run(main, backend={backend!r})\n"
        "except aiofins.CommandError as exc:\n"
        "    print(exc)\n"
        "    sys.exit(0)\n"
        "sys.exit('no CommandError')\n"
    )
    assert result.returncode == 0, result.stderr
    package = "pyserial-asyncio-fast" if backend == "asyncio" else "pyserial"
    assert f"needs {package}" in result.stdout
    assert "pip install -e '.[serial]' in a clone of aiofins" in result.stdout


def test_the_simulator_cannot_serve_a_serial_device_without_the_extra() -> None:
    result = _run(
        "from aiofins.cli import main\n"
        "sys.exit(main(['simulate', '--udp', '127.0.0.1:0', '--serial', '/dev/null']))\n"
    )
    assert result.returncode != 0
    assert "pip install -e '.[serial]' in a clone of aiofins" in result.stderr
