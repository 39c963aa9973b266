"""A clipped radiometry row (Table 4.16 holds no number for it) is in the catalogue as
"clipped" - queryable in a trend, with its clipped pixel count - never silently missing; a v4
catalogue that listed it with no value and no text is re-read from the folder."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path

import pytest
from sim_runs import RAD_SMALL, run_sim

from benchlab.catalog.index import CATALOG_FILE, Catalog
from benchlab.cli.main import main


@pytest.fixture(scope="module")
def clipped_root(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One simulated radiometry session at 50 mA: the 18 mm position clips at 255."""
    root = tmp_path_factory.mktemp("clip") / "sessions"
    params = root.parent / "i50.toml"
    params.write_text(RAD_SMALL.read_text().replace("current_ma = 20.0", "current_ma = 50.0"))
    out = run_sim("radiometry", root, params)
    assert out.summary["summary"]["clipped_positions_mm"] == [18.0]
    return root


@pytest.mark.slow
def test_clipped_position_is_recorded_as_clipped(clipped_root: Path) -> None:
    with Catalog.open(clipped_root) as cat:
        cat.reindex()
        (clipped,) = cat.trend(view="radiometry", element="18mm",
                               quantity="measured_normalised")
        (clean,) = cat.trend(view="radiometry", element="15mm", quantity="measured_normalised")
        (count,) = cat.trend(view="radiometry", element="18mm", quantity="clipped_pixels")
        (none,) = cat.trend(view="radiometry", element="15mm", quantity="clipped_pixels")
        found = cat.conn.execute(
            "SELECT DISTINCT element FROM figures WHERE view = 'radiometry' AND text = 'clipped'"
        ).fetchall()
    assert (clipped.value, clipped.text) == (None, "clipped")
    assert (clean.value, clean.text) == (1.0, "")
    assert count.text == "clipped" and count.value is not None and count.value > 100
    assert (none.value, none.text) == (0.0, "")
    assert [tuple(r) for r in found] == [("18mm",)]


def test_trend_command_shows_clipped(clipped_root: Path, tmp_path: Path,
                                     capsys: pytest.CaptureFixture[str]) -> None:
    capsys.readouterr()
    assert main(["sessions", "trend", "--root", str(clipped_root), "--view", "radiometry",
                 "--element", "18mm", "--quantity", "measured_normalised",
                 "--plot", str(tmp_path / "t.png")]) == 0
    out = capsys.readouterr().out
    assert "clipped" in out and (tmp_path / "t.png").is_file()
    assert main(["sessions", "trend", "--root", str(clipped_root), "--view", "radiometry",
                 "--element", "18mm", "--quantity", "measured_normalised", "--json",
                 "--plot", ""]) == 0
    (point,) = json.loads(capsys.readouterr().out)
    assert point["value"] is None and point["text"] == "clipped"


def test_v4_catalogue_rows_without_text_are_reread(clipped_root: Path, tmp_path: Path) -> None:
    root = tmp_path / "root"
    root.mkdir()
    (session,) = clipped_root.glob("*_radiometry")
    with Catalog.open(root) as cat:
        cat.record(session)
    conn = sqlite3.connect(root / CATALOG_FILE, isolation_level=None)
    conn.execute("DELETE FROM figures WHERE quantity = 'clipped_pixels'")
    conn.execute("UPDATE figures SET text = '' WHERE view = 'radiometry'")  # what v4 wrote
    for statement in ("DROP TABLE verdicts", "DROP INDEX sessions_by_lot",  # what v6 added
                      "ALTER TABLE sessions DROP COLUMN lot"):
        conn.execute(statement)
    conn.execute("PRAGMA user_version = 4")
    conn.close()
    with Catalog.open(root) as cat:
        (point,) = cat.trend(view="radiometry", element="18mm", quantity="measured_normalised")
        assert cat.conn.execute("PRAGMA user_version").fetchone()[0] == 7
    assert (point.value, point.text) == (None, "clipped")
