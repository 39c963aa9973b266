"""The session catalogue: hooks, queries, trends, rebuild, migration, concurrent writers."""

from __future__ import annotations

import json
import os
import sqlite3
import subprocess
import sys
from pathlib import Path

import pytest
from many_sessions_helpers import copy_session, real_session
from sim_runs import reseal_results

import benchlab.session as session_mod
import benchlab.session.results as session_results
from benchlab.catalog.index import CATALOG_FILE, Catalog, record_session
from benchlab.catalog.schema import SCHEMA_VERSION, migrate
from benchlab.cli.main import main
from benchlab.protocols.batch import run_batch
from benchlab.protocols.runs import reanalyze


@pytest.fixture(scope="module")
def source(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return real_session(tmp_path_factory.mktemp("source"))


def _set_modulation(session: Path, element: str, value: float) -> None:
    """Give a copy its own measured value (as a different lens would)."""
    latest = max((session / "results").iterdir(), key=lambda p: int(p.name[1:]))
    path = latest / "forward_view_modulation.json"  # Table 4.11
    rows = json.loads(path.read_text())
    for row in rows:
        if row["element"] == element:
            row["sagittal_modulation"] = value
    path.write_text(json.dumps(rows))
    reseal_results(path.parent)


def _unlike_any_reanalysis(session: Path) -> None:
    """Every stored version given a value a re-analysis does not repeat, so that one adds a
    version (an identical re-analysis matches the version it repeats and adds none)."""
    for version in (session / "results").iterdir():
        path = version / "forward_view_modulation.json"
        rows = json.loads(path.read_text())
        rows[0]["sagittal_modulation"] = 0.5
        path.write_text(json.dumps(rows))
        reseal_results(version)


@pytest.mark.slow
def test_a_run_an_analysis_and_a_report_update_the_catalogue(
    source: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = source.parent
    assert (root / CATALOG_FILE).is_file()  # written by the run itself
    assert main(["sessions", "list", "--root", str(root), "--json"]) == 0
    (row,) = json.loads(capsys.readouterr().out)
    assert (row["id"], row["status"], row["sample"], row["operator"]) == (
        source.name, "completed", "LENS-7", "ana")
    assert row["results_version"] == 1 and row["estimator"] == "histogram"
    assert "camera:SIM-130001" in row["serials"] and row["devices"]["camera"]["model"]
    assert row["finished_at"] and row["software_version"]

    reanalyze(source, estimator="sinefit")
    assert main(["report", str(source)]) == 0
    capsys.readouterr()
    assert main(["sessions", "show", source.name, "--root", str(root), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert [(r["version"], r["estimator"]) for r in info["results"]] == [
        (1, "histogram"), (2, "sinefit")]
    assert info["results_version"] == 2 and info["report"] == "report.html"
    forward = {(f["element"], f["orientation"]): f for f in info["figures"]
               if f["view"] == "forward"}
    rows = json.loads((source / "results" / "v2" / "forward_view_modulation.json").read_text())
    for r in rows:  # the catalogue holds exactly the numbers of the results files
        assert forward[(r["element"], "sagittal")]["value"] == r["sagittal_modulation"]
        assert forward[(r["element"], "tangential")]["value"] == r["tangential_modulation"]
    assert main(["sessions", "show", source.name, "--root", str(root)]) == 0
    text = capsys.readouterr().out
    assert "sinefit" in text and "LENS-7" in text and "G2E1" in text


def test_list_filters_and_csv(source: Path, tmp_path: Path,
                              capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "root"
    for i, (sample, day) in enumerate([("A", "2026-01-05"), ("B", "2026-02-05"),
                                       ("A", "2026-03-05")]):
        copy_session(source, root / f"s{i}", sample=sample, started_at=f"{day}T10:00:00+00:00")
    assert main(["sessions", "reindex", "--root", str(root)]) == 0
    assert "3 sessions indexed" in capsys.readouterr().out
    with Catalog.open(root) as cat:
        assert [r["id"] for r in cat.sessions()] == ["s2", "s1", "s0"]
        assert [r["id"] for r in cat.sessions(sample="A", descending=False)] == ["s0", "s2"]
        assert [r["id"] for r in cat.sessions(since="2026-02-01")] == ["s2", "s1"]
        assert cat.sessions(procedure="radiometry") == []
        assert len(cat.sessions(status="completed", limit=2)) == 2
        assert [r["id"] for r in cat.sessions(sort="sample", descending=False)][2] == "s1"
    out = tmp_path / "list.csv"
    assert main(["sessions", "list", "--root", str(root), "--sample", "A", "--csv",
                 str(out)]) == 0
    lines = out.read_text().splitlines()
    assert lines[0].startswith("id,procedure,status,sample") and len(lines) == 3


def test_trend_table_csv_and_png(source: Path, tmp_path: Path,
                                 capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "root"
    values = [0.61, 0.55, 0.70]
    for i, v in enumerate(values):
        s = copy_session(source, root / f"p{i}", sample=f"proto-{i}",
                         started_at=f"2026-0{i + 1}-01T00:00:00+00:00")
        _set_modulation(s, "G2E1", v)
    png = tmp_path / "t.png"
    csv_out = tmp_path / "t.csv"
    args = ["sessions", "trend", "--root", str(root), "--view", "forward", "--element",
            "G2E1", "--orientation", "S", "--plot", str(png)]
    assert main(args) == 0
    text = capsys.readouterr().out
    assert [line.split()[0] for line in text.splitlines()[1:]] == ["p0", "p1", "p2"]
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and png.stat().st_size > 5000
    assert main([*args, "--csv", str(csv_out), "--force"]) == 0  # the plot again (issue 38)
    rows = csv_out.read_text().splitlines()
    assert [float(r.split(",")[8]) for r in rows[1:]] == values
    with Catalog.open(root) as cat:
        near = cat.trend(view="forward", freq_lp_per_mm=64.0, orientation="S")
        assert [p.element for p in near] == ["G2E1"] * 3  # 65.2 lp/mm, within 20 %
        assert [p.value for p in near] == values
        assert cat.trend(view="forward", freq_lp_per_mm=20.0, orientation="S") == []
        assert len(cat.trend(view="forward", element="G2E1")) == 6  # S and T per session
        assert [p.value for p in cat.trend(view="forward", element="G2E1", orientation="S",
                                           sample="proto-1")] == [0.55]


def test_bad_queries_are_clean_errors(source: Path, tmp_path: Path,
                                      capsys: pytest.CaptureFixture[str]) -> None:
    root = tmp_path / "root"
    copy_session(source, root / "s0")
    base = ["sessions", "trend", "--root", str(root), "--view", "forward"]
    for extra, message in ([[], "needs --element or --freq"],
                           [["--element", "G2E1", "--orientation", "X"], "--orientation 'X'"],
                           [["--freq", "-3"], "--freq must be a number > 0"],
                           [["--element", "G2E1", "--since", "soon"], "--since 'soon'"]):
        assert main([*base, *extra]) == 2  # a value that cannot be meant: usage, exit 2
        assert message in capsys.readouterr().err
    assert main(["sessions", "show", "nope", "--root", str(root)]) == 1
    assert "no session 'nope'" in capsys.readouterr().err
    assert main(["sessions", "list", "--root", str(root), "--sort", "path;drop"]) == 2
    assert "--sort 'path;drop': choose" in capsys.readouterr().err
    with pytest.raises(SystemExit) as exc:
        main(["sessions", "trend", "--root", str(root)])  # --view is required: usage
    assert exc.value.code == 2
    assert main(["sessions", "list", "--root", str(tmp_path / "nowhere")]) == 1
    assert "no such sessions folder" in capsys.readouterr().err
    assert not (tmp_path / "nowhere").exists()


def test_deleted_or_corrupt_or_newer_catalogue_is_rebuilt(source: Path, tmp_path: Path) -> None:
    root = tmp_path / "root"
    for i in range(2):
        copy_session(source, root / f"s{i}")
    db = root / CATALOG_FILE
    assert not db.exists()
    with Catalog.open(root) as cat:  # missing: built from the folders
        assert {r["id"] for r in cat.sessions()} == {"s0", "s1"}
    db.unlink()
    assert record_session(root / "s0")  # a hook on a deleted catalogue rebuilds all of it
    with Catalog.open(root) as cat:
        assert {r["id"] for r in cat.sessions()} == {"s0", "s1"}
    db.write_bytes(b"this is not a database" * 100)
    with Catalog.open(root) as cat:
        assert {r["id"] for r in cat.sessions()} == {"s0", "s1"}
    with sqlite3.connect(db) as conn:
        conn.execute(f"PRAGMA user_version = {SCHEMA_VERSION + 5}")
    with Catalog.open(root) as cat:
        assert {r["id"] for r in cat.sessions()} == {"s0", "s1"}
        assert cat.conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION


def test_a_catalogue_that_cannot_be_rebuilt_is_a_clean_error(
    source: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    root = tmp_path / "root"
    s0 = copy_session(source, root / "s0")
    (root / CATALOG_FILE).mkdir()  # in the way: neither a database nor removable as a file
    assert main(["sessions", "list", "--root", str(root)]) == 1
    assert "cannot open or rebuild the catalogue" in capsys.readouterr().err
    assert record_session(s0) is False  # a run or an analysis is never stopped by it


def test_older_schema_is_migrated_keeping_its_rows(source: Path, tmp_path: Path) -> None:
    root = tmp_path / "root"
    copy_session(source, root / "s0", sample="LENS-9")
    conn = sqlite3.connect(root / CATALOG_FILE, isolation_level=None)
    migrate(conn, target=1)  # the v1 schema: no sample column
    conn.execute("INSERT INTO sessions (id, path, procedure, status, indexed_at) VALUES "
                 "('old', '/gone', 'mtf', 'completed', 'then')")
    conn.close()
    with Catalog.open(root) as cat:
        assert cat.conn.execute("PRAGMA user_version").fetchone()[0] == SCHEMA_VERSION == 7
        (row,) = cat.sessions()
        assert row["id"] == "old" and row["sample"] == ""  # kept; not rebuilt
        cat.record(root / "s0")
        assert {r["id"]: r["sample"] for r in cat.sessions()} == {"old": "", "s0": "LENS-9"}
        cat.reindex()  # reindex drops what no folder backs
        assert [r["id"] for r in cat.sessions()] == ["s0"]


_WRITER = """
import json, os, shutil, sys
from pathlib import Path
from benchlab.catalog.index import record_session
source, root, n, prefix = Path(sys.argv[1]), Path(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
meta = json.loads((source / "session.json").read_text())
for i in range(n):
    dst = root / f"{prefix}{i:02d}"
    dst.mkdir()
    shutil.copy2(source / "events.jsonl", dst / "events.jsonl")
    shutil.copytree(source / "frames", dst / "frames", copy_function=os.link)
    (dst / "session.json").write_text(json.dumps({**meta, "status": "running"}))
    assert record_session(dst)                       # a run starts
    shutil.copytree(source / "results", dst / "results")
    (dst / "session.json").write_text(json.dumps({**meta, "status": "completed"}))
    assert record_session(dst)                       # ... and finishes
"""


@pytest.mark.slow
def test_concurrent_runs_write_while_a_batch_reads(source: Path, tmp_path: Path) -> None:
    root = tmp_path / "root"
    batch = [copy_session(source, root / f"b{i}") for i in range(4)]
    for s in batch:
        _unlike_any_reanalysis(s)
    v = len(list((source / "results").iterdir()))  # results versions of every copy
    Catalog.open(root).close()
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(sys.path)}
    # Two processes start and finish runs (as ``record_session`` does after each) meanwhile.
    writers = [subprocess.Popen([sys.executable, "-c", _WRITER, str(source), str(root), "8",
                                 prefix], env=env) for prefix in ("w", "x")]
    seen: list[int] = []

    def read(done: int, total: int, item: object) -> None:
        with Catalog.open(root) as cat:  # a reader in the middle of the writers
            seen.append(len(cat.sessions()))

    report = run_batch(batch, jobs=2, progress=read)
    assert [w.wait(timeout=120) for w in writers] == [0, 0]
    assert [i.outcome for i in report.items] == ["analysed"] * 4 and len(seen) == 4
    folders = sorted(p.name for p in root.iterdir() if (p / "session.json").is_file())
    assert len(folders) == 4 + 8 + 8
    with Catalog.open(root) as cat:
        assert cat.conn.execute("PRAGMA integrity_check").fetchone()[0] == "ok"
        rows = {r["id"]: r for r in cat.sessions()}
        assert sorted(rows) == folders  # nothing lost
        for name, r in rows.items():
            assert r["status"] == "completed", name
            assert r["results_version"] == (v + 1 if name[0] == "b" else v), name
        stored = {r["id"]: (r["results_version"], r["status"]) for r in rows.values()}
        n_figures = cat.conn.execute("SELECT COUNT(*) FROM figures").fetchone()[0]
        cat.reindex()  # what the writers stored is what the folders hold
        assert {r["id"]: (r["results_version"], r["status"]) for r in cat.sessions()} == stored
        assert cat.conn.execute("SELECT COUNT(*) FROM figures").fetchone()[0] == n_figures


def test_results_are_fsynced_once_per_version_with_the_same_bytes(
    source: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import benchlab.storage as storage_mod

    calls: list[int] = []
    syncfs_calls: list[int] = []
    real = os.fsync
    real_syncfs = storage_mod._syncfs
    monkeypatch.setattr(os, "fsync", lambda fd: (calls.append(fd), real(fd))[1])
    monkeypatch.setattr(storage_mod, "_syncfs",
                        lambda fd: (syncfs_calls.append(fd), real_syncfs(fd))[1])
    got = {}
    for policy in ("per-file", "per-version", "syncfs"):
        monkeypatch.setattr(session_results, "RESULTS_FSYNC", policy)
        s = session_mod.Session.open(copy_session(source, tmp_path / policy))
        calls.clear()
        syncfs_calls.clear()
        out = s.write_results({"t": [{"a": 1.5}], "u": [{"b": None}]}, summary={"k": 1},
                              estimator="x")
        got[policy] = (len(calls), {p.name: p.read_bytes() for p in out.iterdir()
                                    if p.name != "summary.json"}, len(syncfs_calls))
    # per-file: 5 files x (file + folder) + the rename; per-version: 5 files + 2 folders;
    # syncfs: one file-system flush + the rename (Linux has syncfs)
    assert got["per-file"][0] == 11 and got["per-version"][0] == 7
    assert got["syncfs"][0] == 1 and got["syncfs"][2] == 1
    assert got["per-file"][2] == got["per-version"][2] == 0
    assert got["per-file"][1] == got["per-version"][1] == got["syncfs"][1]
    # without syncfs (not Linux) the policy falls back to one fsync per file
    monkeypatch.setattr(storage_mod, "_libc", lambda: None)
    calls.clear()
    s.write_results({"t": [{"a": 1.5}]}, summary={"k": 1}, estimator="x")
    assert len(calls) == 5  # 3 files + the folder, then the rename
    calls.clear()
    s.log_event("note", durable=False)
    assert calls == []
    s.log_event("step_completed", step_id="x")  # resume depends on these: fsync'd
    assert len(calls) == 1


def test_a_failed_file_system_flush_is_an_error_and_leaves_no_version(
    source: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    import errno

    import benchlab.storage as storage_mod

    class FailingLibc:
        def syncfs(self, fd: int) -> int:
            import ctypes

            ctypes.set_errno(errno.EIO)
            return -1

    monkeypatch.setattr(storage_mod, "_libc", lambda: FailingLibc())
    monkeypatch.setattr(session_results, "RESULTS_FSYNC", "syncfs")
    s = session_mod.Session.open(copy_session(source, tmp_path / "s"))
    before = s.result_versions()
    with pytest.raises(OSError) as info:
        s.write_results({"t": [{"a": 1.5}]}, summary={"k": 1}, estimator="x")
    assert info.value.errno == errno.EIO
    assert s.result_versions() == before
    assert not [p for p in s.results_dir.iterdir() if p.name.startswith(".v-")]


def test_a_batch_parent_records_each_root_once(
    source: Path, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
    caplog: pytest.LogCaptureFixture,
) -> None:
    from benchlab.catalog import index as catalog_mod
    from benchlab.catalog.index import session_recorder

    a = [copy_session(source, tmp_path / "a" / f"s{i}") for i in range(3)]
    b = copy_session(source, tmp_path / "b" / "s")
    for s in (*a, b):
        _unlike_any_reanalysis(s)
    v = len(list((source / "results").iterdir()))
    Catalog.open(tmp_path / "a").close()  # indexes the copies as they are: version v
    for s in (*a, b):
        reanalyze(s, catalogue=False)  # a batch worker: analysed, not catalogued
    with Catalog.open(tmp_path / "a") as cat:
        assert {r["results_version"] for r in cat.sessions()} == {v}
    assert not (tmp_path / "b" / CATALOG_FILE).exists()
    opened: list[Path] = []
    real_open = catalog_mod.Catalog.open
    monkeypatch.setattr(catalog_mod.Catalog, "open",
                        lambda root: (opened.append(Path(root)), real_open(root))[1])
    with session_recorder() as record:
        assert all(record(s) for s in (*a, b))
        assert record(tmp_path / "not-a-session") is False
    assert sorted(opened) == [(tmp_path / "a").resolve(), (tmp_path / "b").resolve()]
    monkeypatch.setattr(catalog_mod.Catalog, "open", real_open)
    for root, names in ((tmp_path / "a", ["s0", "s1", "s2"]), (tmp_path / "b", ["s"])):
        with Catalog.open(root) as cat:
            rows = {r["id"]: r["results_version"] for r in cat.sessions()}
        assert rows == dict.fromkeys(names, v + 1)
    # a catalogue that cannot be written is a warning, never an error (it is a cache)
    monkeypatch.setattr(catalog_mod.Catalog, "record",
                        lambda self, folder: (_ for _ in ()).throw(sqlite3.OperationalError("x")))
    with session_recorder() as record:
        assert record(a[0]) is False
    assert "catalogue not updated" in caplog.text


def test_figures_of_every_known_table_and_any_other() -> None:
    from benchlab.catalog.extract import figures_of

    tables = {
        "table_4_15": [{"view": "radial", "mc_freq_lp_per_mm": 60.0, "averaged_modulation": 0.35,
                        "verdict": "exceeds the 80 % threshold (0.27)"}],
        "table_4_16": [{"position_mm": 15.0, "measured_normalised": 1.0, "difference": 0.0,
                        "measured_mean_gray": 180.5}],
        "table_4_13": [{"view": "forward", "image_height_mm": 0.69}],  # geometry: not a figure
        "characterisation": [{"quantity": "gain", "value": 0.42, "ok": True, "n": float("nan")}],
        "table_sfr_edges": [{"edge": "E0R", "orientation": "sagittal", "status": "ok",
                             "mtf50_lp_per_mm": 103.1, "mtf_nyquist": 0.55, "contrast": 0.81}],
        "table_sfr_vs_bars": [{"element": "G1E5", "orientation": "sagittal", "edge_mtf": 0.82,
                               "image_lp_per_mm": 51.7, "bar_mtf_coltman": 0.77,
                               "verdict": "agree"}],
        "table_sfr_curves": [{"edge": "E0R", "freq_lp_per_mm": 0.0, "mtf": 1.0}],
        "some_curve": [{"x": float(i), "y": 1.0} for i in range(101)],  # too long: a curve
    }
    got = {(f.view, f.element, f.orientation, f.quantity): (f.value, f.text)
           for f in figures_of(3, tables)}
    assert got == {
        ("radial", "", "averaged", "modulation"): (0.35, "exceeds the 80 % threshold (0.27)"),
        ("radiometry", "15mm", "", "measured_normalised"): (1.0, ""),
        ("radiometry", "15mm", "", "difference"): (0.0, ""),
        ("radiometry", "15mm", "", "measured_mean_gray"): (180.5, ""),
        ("characterisation", "gain", "", "value"): (0.42, ""),  # booleans and NaN left out
        ("sfr", "E0R", "sagittal", "mtf50_lp_per_mm"): (103.1, "ok"),
        ("sfr", "E0R", "sagittal", "mtf_nyquist"): (0.55, "ok"),
        ("sfr", "E0R", "sagittal", "contrast"): (0.81, "ok"),
        ("sfr_vs_bars", "G1E5", "sagittal", "edge_mtf"): (0.82, "agree"),
        ("sfr_vs_bars", "G1E5", "sagittal", "bar_mtf_coltman"): (0.77, "agree"),
    }
