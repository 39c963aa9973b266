"""``tools/cost_ab.py`` (issue 39's interleaved costs): the process-tree CPU it counts and the
results comparison that stops it."""

from __future__ import annotations

import importlib.util
import json
import sys
from pathlib import Path

import pytest

TOOL = Path(__file__).resolve().parents[2] / "tools" / "cost_ab.py"


def _tool():  # type: ignore[no-untyped-def]
    spec = importlib.util.spec_from_file_location("cost_ab", TOOL)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_tree_cpu_counts_a_child_process(tmp_path: Path) -> None:
    tool = _tool()
    env = tool._env(TOOL.parents[1])
    # `benchlab --help`: the process's own CPU is counted (Python's start-up and benchlab's
    # imports are tens of ms at least)
    alone = tool._tree_cpu_s(sys.executable, ["--help"], env)
    assert 0.02 < alone < 30.0


def test_a_failing_command_names_itself(tmp_path: Path) -> None:
    tool = _tool()
    with pytest.raises(SystemExit, match="no-such-command failed"):
        tool._tree_cpu_s(sys.executable, ["no-such-command"], tool._env(TOOL.parents[1]))


def test_results_comparison_names_the_first_differing_csv(tmp_path: Path) -> None:
    tool = _tool()
    a, b = tmp_path / "a", tmp_path / "b"
    a.mkdir()
    b.mkdir()
    for folder in (a, b):
        (folder / "depth_chart.csv").write_text("x,y\n1,0.5\n")
        (folder / "summary.json").write_text(json.dumps({"created_at": folder.name}))
    tool._same_csvs(a, b)  # JSON timestamps differ; the CSVs are equal
    (b / "depth_curves.csv").write_text("z\n")
    with pytest.raises(SystemExit, match="different CSV files"):
        tool._same_csvs(a, b)
    (a / "depth_curves.csv").write_text("z\n")
    (b / "depth_chart.csv").write_text("x,y\n1,0.50000000001\n")
    with pytest.raises(SystemExit, match="depth_chart.csv"):
        tool._same_csvs(a, b)
