"""The catalogue keeps no value for a reading that is not resolved or aliased (NULL, with its
text), trends never draw it as a measured 0, and a v2 catalogue is migrated to that."""

from __future__ import annotations

import json
import sqlite3
from pathlib import Path
from typing import Any

import matplotlib.pyplot as plt
import pytest
from many_sessions_helpers import copy_session, real_session
from sim_runs import reseal_results

from benchlab.catalog.index import CATALOG_FILE, Catalog
from benchlab.catalog.schema import migrate
from benchlab.cli.main import main


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return real_session(tmp_path_factory.mktemp("source"))


def _edit_g2e1(session: Path, **changes: Any) -> None:
    path = session / "results" / "v1" / "forward_view_modulation.json"
    rows = json.loads(path.read_text())
    for row in rows:
        if row["element"] == "G2E1":
            row.update(changes)
    path.write_text(json.dumps(rows))
    reseal_results(path.parent)


@pytest.fixture
def root(source: Path, tmp_path: Path) -> Path:
    """p0 measured, p1's G2E1 T not resolved (stored 0), p2's G2E1 aliased (stored 0)."""
    root = tmp_path / "root"
    for i in range(3):
        copy_session(source, root / f"p{i}", sample=f"lens-{i}",
                     started_at=f"2026-0{i + 1}-01T00:00:00+00:00")
    _edit_g2e1(root / "p0", tangential_modulation=0.47)
    _edit_g2e1(root / "p1", tangential_modulation=0.0, tangential_resolved=False)
    _edit_g2e1(root / "p2", tangential_modulation=0.0, tangential_resolved=False, aliased=True,
               sagittal_aliased=True, tangential_aliased=True)
    return root


@pytest.mark.slow
def test_trend_has_no_value_for_unresolved_and_aliased(
    root: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str],
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    with Catalog.open(root) as cat:
        points = cat.trend(view="forward", element="G2E1", orientation="T")
    assert [(p.session_id, p.value, p.text) for p in points] == [
        ("p0", 0.47, "resolved"), ("p1", None, "unresolved"), ("p2", None, "aliased")]

    drawn: list[Any] = []
    monkeypatch.setattr(plt, "close", lambda fig: drawn.append(fig))
    png, csv_out = tmp_path / "t.png", tmp_path / "t.csv"
    args = ["sessions", "trend", "--root", str(root), "--view", "forward", "--element", "G2E1",
            "--orientation", "T", "--plot", str(png)]
    assert main(args) == 0
    lines = capsys.readouterr().out.splitlines()[1:]
    assert lines[0].split()[-2:] == ["0.47", "resolved"]
    assert lines[1].split()[-3:] == ["not", "resolved", "unresolved"]
    assert lines[2].split()[-2:] == ["aliased", "aliased"]
    (fig,) = drawn
    ax = fig.axes[0]
    by_label = {line.get_label(): line for line in ax.lines}
    measured = by_label["G2E1 tangential"]
    assert list(measured.get_xdata()) == [0] and list(measured.get_ydata()) == [0.47]
    unresolved = by_label["not resolved (no value)"]
    aliased = by_label["aliased (no value)"]
    assert list(unresolved.get_xdata()) == [1] and list(aliased.get_xdata()) == [2]
    # Drawn along the bottom edge in axes coordinates: never at a data value of 0.
    assert unresolved.get_transform() is not ax.transData
    assert ax.get_ylim()[0] > 0.3  # the value axis is not stretched down to 0

    assert main([*args, "--plot", "", "--csv", str(csv_out)]) == 0
    rows = [r.split(",") for r in csv_out.read_text().splitlines()[1:]]
    assert [(r[8], r[9]) for r in rows] == [("0.47", "resolved"), ("", "unresolved"),
                                           ("", "aliased")]
    assert main([*args, "--plot", "", "--json"]) == 0
    got = json.loads(capsys.readouterr().out)
    assert [(p["value"], p["text"]) for p in got] == [
        (0.47, "resolved"), (None, "unresolved"), (None, "aliased")]


def test_show_names_aliased_readings_and_has_no_zero(
    root: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["sessions", "show", "p2", "--root", str(root), "--json"]) == 0
    figures = json.loads(capsys.readouterr().out)["figures"]
    g2e1 = {f["orientation"]: f for f in figures
            if f["element"] == "G2E1" and f["view"] == "forward"}
    assert (g2e1["sagittal"]["value"], g2e1["sagittal"]["text"]) == (None, "aliased")
    assert (g2e1["tangential"]["value"], g2e1["tangential"]["text"]) == (None, "aliased")
    assert main(["sessions", "show", "p1", "--root", str(root)]) == 0
    (line,) = [x for x in capsys.readouterr().out.splitlines()
               if x.startswith("forward") and "G2E1" in x and "tangential" in x]
    assert line.split()[-3:] == ["not", "resolved", "unresolved"]


def test_a_v2_catalogue_is_migrated_to_no_value(source: Path, tmp_path: Path) -> None:
    root = tmp_path / "root"
    root.mkdir()
    conn = sqlite3.connect(root / CATALOG_FILE, isolation_level=None)
    migrate(conn, target=2)
    conn.execute("INSERT INTO sessions (id, path, procedure, status, results_version, "
                 "indexed_at) VALUES ('old', '/gone', 'mtf', 'completed', 1, 'then')")
    conn.executemany(
        "INSERT INTO figures (session_id, version, view, element, orientation, "
        "freq_lp_per_mm, quantity, value, text) VALUES ('old', 1, ?, ?, ?, "
        "?, 'modulation', ?, ?)", [
            ("forward", "G2E1", "tangential", 65.2, 0.47, "resolved"),
            ("forward", "G2E5", "tangential", 103.5, 0.0, "unresolved"),
            ("radial", "4lp", "tangential", 70.0, 0.0, "unresolved"),
            ("radial", "4lp", "sagittal", 70.0, 0.778, "resolved"),
            # Table 4.15 averages: over the 0 above (60 vs 70 lp/mm: the 20 % match), and
            # one with both halves resolved.
            ("radial", "", "averaged", 60.0, 0.389, "between the 80% and 50% thresholds"),
            ("forward", "", "averaged", 40.0, 0.55, "above the 80% threshold"),
        ])
    conn.close()
    with Catalog.open(root) as cat:
        figures = {(f["view"], f["element"], f["orientation"]): (f["value"], f["text"])
                   for f in cat.show("old")["figures"]}
    assert figures[("forward", "G2E1", "tangential")] == (0.47, "resolved")
    assert figures[("forward", "G2E5", "tangential")] == (None, "unresolved")
    assert figures[("radial", "4lp", "tangential")] == (None, "unresolved")
    value, text = figures[("radial", "", "averaged")]
    assert value is None and text.startswith("not available: a half not resolved")
    assert figures[("forward", "", "averaged")] == (0.55, "above the 80% threshold")


def test_table_4_15_average_over_an_unresolved_reading_has_no_value() -> None:
    from benchlab.catalog.extract import figures_of

    old = {"view": "radial", "mc_freq_lp_per_mm": 60.0, "sagittal_modulation": 0.778,
           "tangential_modulation": 0.0, "averaged_modulation": 0.389,
           "verdict": "between the 80% and 50% thresholds (0.27 .. 0.45)"}
    new = {**old, "tangential_modulation": None, "tangential_resolved": False,
           "sagittal_resolved": True, "averaged_modulation": None,
           "verdict": "not available: T not resolved"}
    both = {**old, "tangential_modulation": 0.2, "averaged_modulation": 0.489,
            "verdict": "between the 80% and 50% thresholds (0.27 .. 0.45)"}
    got = [(f.value, f.text) for f in figures_of(1, {"table_4_15": [old, new, both]})]
    assert got == [(None, "not available: T not resolved")] * 2 + [
        (0.489, "between the 80% and 50% thresholds (0.27 .. 0.45)")]


def test_an_unreadable_latest_version_is_listed_not_hidden(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    import shutil

    from benchlab.catalog.index import record_session

    root = tmp_path / "root"
    s = copy_session(source, root / "s0")
    copy_session(source, root / "s1")
    shutil.copytree(s / "results" / "v1", s / "results" / "v2")
    broken = s / "results" / "v2" / "forward_view_modulation.json"
    broken.write_text("{not json")
    assert record_session(s)
    assert main(["sessions", "list", "--root", str(root), "--json"]) == 0
    rows = {r["id"]: r for r in json.loads(capsys.readouterr().out)}
    assert (rows["s0"]["results_version"], rows["s0"]["unreadable_version"]) == (1, 2)
    assert str(broken) in rows["s0"]["error"] and rows["s0"]["problem"] == "v2 unreadable"
    assert rows["s1"]["unreadable_version"] is None and rows["s1"]["problem"] == ""
    assert main(["sessions", "list", "--root", str(root)]) == 0
    out = capsys.readouterr().out.splitlines()
    (line,) = [x for x in out if x.startswith("s0 ")]
    assert line.rstrip().endswith("v2 unreadable")
    assert any(x.startswith(f"s0: v2 unreadable: {s / 'results' / 'v2'}") for x in out)
    with Catalog.open(root) as cat:  # no figures of an older version passed off as latest
        assert cat.show("s0")["figures"] == []
    from benchlab.tui.services import catalog_sessions

    tui = {x.path.name: x for x in catalog_sessions(root)}  # the TUI's listing says it too
    assert (tui["s0"].result_versions, tui["s0"].unreadable_version) == (1, 2)
    shutil.copy2(s / "results" / "v1" / broken.name, broken)  # repaired: listed normally
    assert record_session(s)
    with Catalog.open(root) as cat:
        (row,) = [r for r in cat.sessions() if r["id"] == "s0"]
        assert (row["results_version"], row["unreadable_version"], row["error"]) == (2, None, "")


@pytest.mark.parametrize("from_version", [2, 3])
def test_sessions_migrated_with_v2_labels_are_reread_from_their_folders(
        root: Path, from_version: int) -> None:
    # A v2 catalogue (and a v3 one migrated from it) called p2's aliased reading
    # "unresolved", with a stored 0; its folder says aliased.
    conn = sqlite3.connect(root / CATALOG_FILE, isolation_level=None)
    migrate(conn, target=from_version)
    for sid, path in (("p2", str((root / "p2").resolve())), ("gone", "/gone")):
        conn.execute("INSERT INTO sessions (id, path, procedure, status, results_version, "
                     "indexed_at) VALUES (?, ?, 'mtf', 'completed', 1, 'then')", (sid, path))
        conn.execute("INSERT INTO figures (session_id, version, view, element, orientation, "
                     "freq_lp_per_mm, quantity, value, text) VALUES (?, 1, 'forward', 'G2E1',"
                     " 'tangential', 65.2, 'modulation', ?, 'unresolved')",
                     (sid, 0.0 if from_version == 2 else None))  # v3 stores no value
    conn.close()
    with Catalog.open(root) as cat:
        g2e1 = {(f["element"], f["orientation"]): (f["value"], f["text"])
                for f in cat.show("p2")["figures"] if f["view"] == "forward"}
        assert g2e1[("G2E1", "tangential")] == (None, "aliased")  # was (None, "unresolved")
        assert g2e1[("G2E1", "sagittal")] == (None, "aliased")
        # a folder that is gone keeps what the migration made of its rows
        (gone,) = cat.show("gone")["figures"]
        assert (gone["value"], gone["text"]) == (None, "unresolved")
        marked = cat.conn.execute("SELECT count(*) FROM sessions WHERE needs_reindex = 1")
        assert marked.fetchone()[0] == 0  # done once, not at every open
        assert cat._reindex_marked() == 0
    with Catalog.open(root) as cat:  # p0 and p1 were never in this catalogue: not added
        assert sorted(s["id"] for s in cat.sessions()) == ["gone", "p2"]
