"""examples/trend.ipynb runs top to bottom in a Jupyter kernel (nbclient) against a virtual
PLC at ``PLC_URL``: a DataFrame of the polled values and a plotted trend; its outputs are
kept out of git."""

from __future__ import annotations

import json

import pytest

from aiofins.simulator import Mode, VirtualPLC
from tests.simulated import ROOT, simulated_plc

NOTEBOOK = ROOT / "examples" / "trend.ipynb"


def test_the_notebook_is_stored_without_outputs() -> None:
    cells = json.loads(NOTEBOOK.read_text())["cells"]
    code = [cell for cell in cells if cell["cell_type"] == "code"]
    assert code and all(not c["outputs"] and c["execution_count"] is None for c in code)


def test_the_notebook_polls_into_a_dataframe_and_plots_it(monkeypatch: pytest.MonkeyPatch) -> None:
    for module in ("pandas", "matplotlib", "ipykernel"):
        pytest.importorskip(module, reason="the notebook extra: pip install -e '.[notebook]'")
    nbformat = pytest.importorskip("nbformat", reason="the test extra runs notebooks")
    nbclient = pytest.importorskip("nbclient", reason="the test extra runs notebooks")
    notebook = nbformat.read(NOTEBOOK, as_version=4)
    with simulated_plc(VirtualPLC(mode=Mode.RUN)) as sim:
        sim.call(sim.plc.write_value, "D100", 64.5, "float32")
        sim.call(sim.plc.write_value, "D102", 101_325, "int32")
        monkeypatch.setenv("PLC_URL", sim.url)
        monkeypatch.setenv("MPLBACKEND", "module://matplotlib_inline.backend_inline")
        client = nbclient.NotebookClient(
            notebook, kernel_name="python3", resources={"metadata": {"path": str(ROOT)}}
        )
        client.execute()
    code = [cell for cell in notebook.cells if cell.cell_type == "code"]
    summary = code[1].outputs[0]["data"]["text/plain"]  # trend.describe()
    assert summary.split("\n")[0].split() == ["temperature", "pressure"]
    assert summary.split("\n")[1].split() == ["count", "20.0", "20.0"]
    assert summary.split("\n")[2].split() == ["mean", "64.5", "101325.0"]
    plots = [out for out in code[2].outputs if "image/png" in out.get("data", {})]
    assert len(plots) == 1
