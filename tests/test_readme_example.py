"""The README's Python example runs as written (issue 26 item 5): its first ``python`` block is
executed in a fresh folder, and what it prints is checked against the session it wrote."""

from __future__ import annotations

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

README = Path(__file__).resolve().parents[1] / "README.md"


def readme_example() -> str:
    """The first fenced ``python`` block of README.md."""
    found = re.search(r"^```python\n(.*?)^```$", README.read_text(encoding="utf-8"),
                      re.MULTILINE | re.DOTALL)
    assert found is not None, f"{README}: no ```python block"
    return found.group(1)


def test_the_block_uses_only_the_public_api() -> None:
    code = readme_example()
    assert code.startswith("import benchlab\n")
    assert "from benchlab" not in code and "benchlab." in code
    used = set(re.findall(r"\bbenchlab\.(\w+)", code))
    assert used == {"open_bench", "run_procedure", "open_session", "measure_chart"}


@pytest.mark.slow
def test_the_readme_example_runs_and_prints_the_session(tmp_path: Path) -> None:
    done = subprocess.run([sys.executable, "-c", readme_example()], cwd=tmp_path,
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    lines = done.stdout.splitlines()
    assert len(lines) == 4, done.stdout
    # the session it made, read without the API
    (session,) = [p for p in (tmp_path / "sessions").iterdir() if p.is_dir()]
    assert json.loads((session / "session.json").read_text())["status"] == "completed"
    rows = json.loads((session / "results" / "v1" / "forward_view_modulation.json").read_text())
    for line, row in zip(lines[:3], rows[:3], strict=True):
        element, modulation, uncertainty = line.split()
        assert element == row["element"]
        assert float(modulation) == row["sagittal_modulation"]
        assert float(uncertainty) == row["sagittal_uncertainty"]
        assert 0.5 < float(modulation) < 1.0 and 0.0 < float(uncertainty) < 0.05
    assert [line.split()[0] for line in lines[:3]] == ["G1E5", "G1E6", "G2E1"]
    count = re.fullmatch(r"(\d+) bar sets read on the chart", lines[3])
    assert count is not None, lines[3]
    # as many as the run's own chart finder found in that frame
    summary = json.loads((session / "results" / "v1" / "summary.json").read_text())
    assert int(count.group(1)) == summary["summary"]["chart"]["found"] > 20
