"""CLI tables fit an 80-column terminal: ``benchlab run characterise`` (its 8-bit rows' "n/a"
reasons as one footnote) and ``benchlab sessions list`` at ``COLUMNS=80``; ``--wide`` and
``--csv`` keep every column."""

from __future__ import annotations

import csv
import io
from pathlib import Path

import pytest

from benchlab.cli.main import main
from benchlab.report.text_table import fit_table

FIXTURES = Path(__file__).resolve().parents[2] / "fixtures" / "params"
#: Prose the run prints around its tables (warnings, paths): a terminal wraps it by words.
PROSE = ("warning", "referenced by", "response calibration", "session:", "results:")


@pytest.fixture(scope="module")
def characterised(tmp_path_factory: pytest.TempPathFactory) -> tuple[Path, str]:
    """One simulated characterisation run (two configurations, 12- and 8-bit) at 80 columns."""
    root = tmp_path_factory.mktemp("sessions")
    mp = pytest.MonkeyPatch()
    mp.setenv("COLUMNS", "80")
    out = io.StringIO()
    mp.setattr("sys.stdout", out)
    try:
        code = main(["run", "characterise", "--simulate", "--yes", "--out", str(root),
                     "--params", str(FIXTURES / "characterise-small.toml")])
    finally:
        mp.undo()
    assert code == 0
    return root, out.getvalue()


@pytest.mark.slow
def test_characterise_tables_fit_80_columns_with_one_footnote(
        characterised: tuple[Path, str]) -> None:
    _, text = characterised
    lines = text.splitlines()
    table = [line for line in lines if not line.startswith(PROSE)]
    assert max(map(len, table)) <= 80, [line for line in table if len(line) > 80]
    assert "Camera characterisation (EMVA 1288 photon transfer)" in text
    # the 8-bit row's reason is said once, as a footnote; its cells point to it
    assert "n/a (unresolved" not in text
    notes = [line for line in lines if line.startswith("[1] n/a: unresolved:")]
    assert len(notes) == 1, notes  # measured table only: the simulator's truth has all numbers
    assert sum(line.count("n/a [1]") for line in lines) == 4  # noise DN, e-, dark, DSNU
    # every block of columns is led by gain and bits, which name the row
    heads = [line for line in lines if line.lstrip().startswith("gain")]
    assert len(heads) >= 4 and all(h.split()[:2] == ["gain", "bits"] for h in heads)
    assert any("dark e-/s" in h for h in heads) and any("PRNU %" in h for h in heads)


@pytest.mark.slow
def test_sessions_list_fits_80_columns_and_wide_keeps_every_column(
        characterised: tuple[Path, str], monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    root, _ = characterised
    monkeypatch.setenv("COLUMNS", "80")
    assert main(["sessions", "list", "--root", str(root)]) == 0
    narrow = capsys.readouterr().out.splitlines()
    assert max(map(len, narrow)) <= 80, narrow
    assert narrow[0].split() == ["id", "status", "sample", "operator", "ver", "estimator"]
    assert narrow[1].endswith("_characterise  completed                    1    photon-transfer")
    assert main(["sessions", "list", "--root", str(root), "--wide"]) == 0
    wide = capsys.readouterr().out.splitlines()
    assert len(wide) == 2 and max(map(len, wide)) > 80  # one line per session, every column
    assert wide[0].split() == ["id", "procedure", "status", "sample", "operator", "started_at",
                               "results_version", "estimator", "serials"]
    assert "camera:SIM-" in wide[1]
    assert main(["sessions", "list", "--root", str(root), "--csv", "-"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(rows) == 1 and rows[0]["serials"].startswith("camera:SIM-")


def test_fit_table_folds_columns_into_blocks_keeping_every_value() -> None:
    header = ["name", *(f"column {i}" for i in range(10))]
    body = [[f"row{r}", *(f"{r}.{i:0>6}" for i in range(10))] for r in range(3)]
    text = fit_table(header, body, width=40)
    lines = text.splitlines()
    assert max(map(len, lines)) <= 40
    for r, row in enumerate(body):
        mine = [line.split() for line in lines if line.startswith(f"row{r}")]
        assert [v for cells in mine for v in cells[1:]] == row[1:]  # all values, in order
    assert fit_table(header, body, width=200).count("\n") == 3  # fits: one line per row
