"""The docs site as a plant engineer meets it: no fonts fetched from the internet, a
previous/next footer, signatures formatted over lines, install lines that work from a
clone while there is no release."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
#: An install line that needs the package on PyPI (there is no release yet).
FROM_PYPI = re.compile(r"pip install ['\"]?aiofins\b")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("site")
    result = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        env={"NO_MKDOCS_2_WARNING": "1", "PATH": str(Path(sys.executable).parent)},
        timeout=600,
    )
    assert result.returncode == 0, result.stderr[-3000:]
    return out


def test_no_page_fetches_fonts_from_the_internet(site: Path) -> None:
    """Material loads Google Fonts unless told not to: an air-gapped plant waits for them."""
    pages = list(site.rglob("*.html"))
    assert len(pages) > 20
    for page in pages:
        text = page.read_text()
        assert "fonts.googleapis.com" not in text and "fonts.gstatic.com" not in text, page


def test_pages_have_a_previous_and_next_footer(site: Path) -> None:
    text = (site / "client" / "index.html").read_text()
    assert "md-footer__link--prev" in text and "md-footer__link--next" in text


def test_long_signatures_are_formatted_over_lines(site: Path) -> None:
    """``connect``'s 19 parameters were one scrolling line: a formatter (ruff, in the docs
    extra) puts one parameter a line."""
    text = (site / "api" / "client" / "index.html").read_text()
    start = text.index('id="aiofins.connect"')
    signature = text[text.index("<code>", text.index('class="doc-signature', start)) :]
    signature = re.sub(r"<[^>]+>", "", signature[: signature.index("</code>")])
    lines = [line.strip() for line in signature.splitlines() if line.strip()]
    assert lines[0] == "connect("
    assert any(line.startswith("breaker_threshold: int | None = None") for line in lines)
    assert len(lines) > 15


def test_install_lines_work_from_a_clone() -> None:
    """Until a release is on PyPI, ``pip install 'aiofins[gateway]'`` fails for everyone
    who copies it: docs, README and messages say ``pip install -e '.[gateway]'``."""
    changelog = (ROOT / "CHANGELOG.md").read_text()
    if re.search(r"^## \[\d", changelog, re.MULTILINE):
        pytest.skip("released: PyPI install lines are right")
    files = [
        *ROOT.glob("docs/**/*.md"),
        ROOT / "README.md",
        *ROOT.glob("src/**/*.py"),
        *ROOT.glob("examples/**/*.py"),
    ]
    wrong = [
        f"{path.relative_to(ROOT)}:{number}"
        for path in files
        if path.name != "changelog.md"
        for number, line in enumerate(path.read_text().splitlines(), 1)
        if FROM_PYPI.search(line)
    ]
    assert not wrong, wrong
