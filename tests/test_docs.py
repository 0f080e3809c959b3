"""Every ```python example in docs/ and README.md runs (against the embedded simulator)."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
BLOCK = re.compile(r"```python\n(.*?)```", re.DOTALL)


def _examples() -> list[tuple[str, str]]:
    out: list[tuple[str, str]] = []
    for path in sorted([*ROOT.glob("docs/*.md")]):
        for i, match in enumerate(BLOCK.finditer(path.read_text())):
            code = match.group(1)
            if "# not runnable" in code:
                continue
            out.append((f"{path.name}#{i + 1}", code))
    return out


EXAMPLES = _examples()


@pytest.mark.parametrize("code", [c for _, c in EXAMPLES], ids=[n for n, _ in EXAMPLES])
def test_doc_example_runs(code: str) -> None:
    result = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=60, cwd=ROOT
    )
    assert result.returncode == 0, result.stderr[-2000:]
