"""Sessions tell the truth (issue 10, item 2): a dead writer's session is interrupted, two
processes never write one session, resume of a complete session changes nothing, temporary
files of a killed write are cleaned by resume, analysis of an incomplete session is partial."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import textwrap
import time
from collections.abc import Iterator
from pathlib import Path

import pytest

from benchlab.cli.main import main
from benchlab.session import Session, SessionBusyError, session_holder
from benchlab.tui import services

ROOT = Path(__file__).resolve().parents[2]
RAD_SMALL = ROOT / "fixtures" / "params" / "radiometry-small.toml"


def _snapshot(path: Path) -> dict[str, bytes]:
    return {p.relative_to(path).as_posix(): p.read_bytes()
            for p in sorted(path.rglob("*")) if p.is_file() and p.name != "owner.lock"}


def _frames_saved(path: Path) -> int:
    try:
        text = (path / "events.jsonl").read_text(encoding="utf-8")
    except OSError:
        return 0
    return text.count('"kind": "frame_saved"')


@pytest.fixture(scope="module")
def killed_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """A radiometry run killed with SIGKILL after its third frame (session.json: running)."""
    root = tmp_path_factory.mktemp("killed")
    proc = subprocess.Popen(
        [sys.executable, "-m", "benchlab.cli.main", "run", "radiometry", "--simulate", "--yes",
         "--params", str(RAD_SMALL), "--out", str(root)],
        stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    try:
        deadline = time.monotonic() + 60
        while True:
            found = [p for p in root.iterdir() if (p / "events.jsonl").is_file()]
            if found and _frames_saved(found[0]) >= 3:
                break
            assert proc.poll() is None and time.monotonic() < deadline, "run ended too soon"
            time.sleep(0.005)
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    (path,) = found
    assert json.loads((path / "session.json").read_text())["status"] == "running"
    return path


def _copy(src: Path, dst: Path) -> Path:
    import shutil

    return Path(shutil.copytree(src, dst / src.name))


@pytest.mark.slow
def test_dead_writer_shows_interrupted_everywhere(
    killed_session: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    path = _copy(killed_session, tmp_path)
    assert session_holder(path) is None
    assert Session.open(path).status == "interrupted"  # the Python API
    (listed,) = services.list_sessions(tmp_path)  # the TUI's sessions list
    assert listed.status == "interrupted"
    assert main(["analyze", str(path)]) == 0
    out = capsys.readouterr().out
    assert "[PARTIAL: session incomplete]" in out
    assert "session interrupted: " in out and "tables are partial" in out
    summary = json.loads((path / "results" / "v1" / "summary.json").read_text())
    assert summary["partial"] is True and summary["session_status"] == "interrupted"
    assert 0 < summary["steps_done"] < summary["steps_total"]
    assert main(["report", str(path)]) == 0
    html = (path / "report.html").read_text(encoding="utf-8")
    assert "interrupted - results PARTIAL" in html


@pytest.mark.slow
def test_complete_session_analysis_is_not_partial(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(RAD_SMALL),
                 "--out", str(tmp_path)]) == 0
    (path,) = [p for p in tmp_path.iterdir() if (p / "session.json").is_file()]
    summary = json.loads((path / "results" / "v1" / "summary.json").read_text())
    assert summary["partial"] is False
    assert Session.open(path).status == "completed"

    # resume of a completed session: says so, exit 0, not one byte changed
    before = _snapshot(path)
    capsys.readouterr()
    rc = main(["resume", str(path), "--simulate", "--yes"])
    assert rc == 0
    assert "session is complete; nothing to resume" in capsys.readouterr().out
    assert _snapshot(path) == before


_HOLDER = textwrap.dedent("""
    import sys, time
    from benchlab.session import Session
    s = Session.open(sys.argv[1])
    s.hold(command="benchlab run radiometry")
    print("held", flush=True)
    time.sleep(60)
""")


@pytest.fixture
def held(killed_session: Path, tmp_path: Path) -> Iterator[tuple[Path, int]]:
    path = _copy(killed_session, tmp_path)
    proc = subprocess.Popen([sys.executable, "-c", _HOLDER, str(path)], stdout=subprocess.PIPE,
                            text=True)
    assert proc.stdout is not None and proc.stdout.readline().strip() == "held"
    yield path, proc.pid
    proc.kill()
    proc.wait()


@pytest.mark.slow
def test_second_writer_is_refused_naming_the_holder(
    held: tuple[Path, int], capsys: pytest.CaptureFixture[str]
) -> None:
    path, pid = held
    before = _snapshot(path)
    assert Session.open(path).status == "running"  # its writer is alive
    for argv in (["resume", str(path), "--simulate", "--yes"], ["analyze", str(path)]):
        assert main(argv) == 1
        err = capsys.readouterr().err
        assert err.startswith("benchlab: error: ")
        assert f"in use by pid {pid} on " in err and "benchlab run radiometry" in err
    with pytest.raises(SessionBusyError, match=f"pid {pid}"):
        Session.open(path).hold()
    assert _snapshot(path) == before


def test_resume_removes_temporary_files_of_a_killed_write(
    killed_session: Path, tmp_path: Path
) -> None:
    path = _copy(killed_session, tmp_path)
    frames = path / "frames"
    real = {p.name: p.read_bytes() for p in frames.glob("*.tiff")}
    tmp_frame = frames / ".position-25__frame.tiff.k1ll3d.tmp"
    tmp_frame.write_bytes(b"II*\0half a frame")
    assert main(["resume", str(path), "--simulate", "--yes"]) == 0
    assert not tmp_frame.exists()
    assert {n: (frames / n).read_bytes() for n in real} == real  # real frames untouched
    events = [json.loads(line) for line in (path / "events.jsonl").read_text().splitlines()]
    removed = [e for e in events if e["kind"] == "temporary_files_removed"]
    assert removed == [{**removed[0], "files": ["frames/.position-25__frame.tiff.k1ll3d.tmp"]}]
    assert Session.open(path).status == "completed"


@pytest.mark.slow
@pytest.mark.asyncio
async def test_tui_lists_a_dead_writer_s_session_as_interrupted_with_partial_results(
    killed_session: Path, tmp_path: Path
) -> None:
    from textual.widgets import DataTable, Static

    from benchlab.tui.app import BenchlabApp
    from benchlab.tui.sessions import SessionsScreen

    root = tmp_path / "sessions"
    root.mkdir()
    path = _copy(killed_session, root)
    assert main(["analyze", str(path)]) == 0
    app = BenchlabApp(simulate=True, sessions_dir=root, autoconnect=False)
    async with app.run_test(size=(110, 32)) as pilot:
        await pilot.press("4")
        screen = app.screen
        assert isinstance(screen, SessionsScreen)
        for _ in range(200):
            if len(screen.sessions) == 1:
                break
            await pilot.pause(0.05)
        row = [str(c) for c in screen.query_one("#session-list", DataTable).get_row_at(0)]
        assert row[:3] == [path.name, "radiometry", "interrupted"]
        await pilot.press("enter")
        info = screen.query_one("#session-info", Static)
        for _ in range(200):
            if "PARTIAL results" in str(info.render()):
                break
            await pilot.pause(0.05)
        assert "PARTIAL results: the session was interrupted" in str(info.render())
