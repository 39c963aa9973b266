"""``benchlab run --serial --lot``: the unit's identity is stored in session.json at the start,
and the catalogue lists the unit."""

from __future__ import annotations

import json
from pathlib import Path

import pytest
from sim_runs import RAD_SMALL, only_session

from benchlab.cli.main import main


@pytest.mark.slow
def test_run_stores_serial_and_lot(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "sessions"
    assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(RAD_SMALL),
                 "--out", str(out), "--serial", "OBJ-0042", "--lot", "2026-W48"]) == 0
    meta = json.loads((only_session(out) / "session.json").read_text())
    assert (meta["sample"], meta["lot"]) == ("OBJ-0042", "2026-W48")
    capsys.readouterr()
    assert main(["units", "--root", str(out), "--json"]) == 0
    (unit,) = json.loads(capsys.readouterr().out)
    assert (unit["serial"], unit["lot"], unit["verdicts"]) == ("OBJ-0042", "2026-W48", {})
