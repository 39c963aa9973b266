"""Smoke test: the real ``benchlab --simulate`` program in tmux; read its screen, quit."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

TMUX = shutil.which("tmux")
#: This module's own tmux server, apart from other tmux tests running in parallel workers.
TMUX_SOCKET = f"benchlab-tui-{os.getpid()}"
BENCHLAB = Path(sys.executable).with_name("benchlab")

pytestmark = pytest.mark.skipif(
    TMUX is None or not BENCHLAB.exists(), reason="needs tmux and the benchlab console script"
)


def _tmux(*args: str) -> str:
    assert TMUX is not None
    return subprocess.run(
        [TMUX, "-L", TMUX_SOCKET, *args], capture_output=True, text=True, timeout=30,
        check=False
    ).stdout


def _wait_for_screen(session: str, predicate, timeout_s: float = 60.0) -> str:  # noqa: ANN001
    deadline = time.monotonic() + timeout_s
    screen = shown = ""
    while time.monotonic() < deadline:
        screen = _tmux("capture-pane", "-p", "-t", session)
        if predicate(screen):
            return screen
        shown = screen if screen.strip() else shown  # an ended session captures nothing
        time.sleep(0.3)
    # Say which it was: the program never got there, or its session ended (a crash shows its
    # text for the 30 s the command sleeps after it).
    raise AssertionError(f"screen never matched in {timeout_s:g} s; session alive: "
                         f"{_alive(session)}; last screen with text:\n{shown}")


def _alive(session: str) -> bool:
    assert TMUX is not None
    return subprocess.run([TMUX, "-L", TMUX_SOCKET, "has-session", "-t", session],
                          capture_output=True,
                          timeout=30, check=False).returncode == 0


@pytest.mark.slow
def test_benchlab_simulate_runs_in_tmux_and_quits(tmp_path: Path) -> None:
    session = f"benchlab-smoke-{uuid.uuid4().hex[:8]}"
    done = tmp_path / "exit-status"
    command = (
        f"cd {tmp_path} && TERM=xterm-256color {BENCHLAB} --simulate; echo $? > {done}; "
        "sleep 30"
    )
    _tmux("new-session", "-d", "-x", "100", "-y", "30", "-s", session, command)
    try:
        screen = _wait_for_screen(
            session, lambda s: "bench: connected" in s and "position" in s
        )
        lines = screen.splitlines()
        assert len(lines) >= 29 and any("benchlab" in line for line in lines[:2])
        assert "bench: connected (simulated)" in screen
        assert "SIM-130001" in screen  # the simulated camera's serial number
        assert "homed" in screen and "Quit" in screen
        _tmux("send-keys", "-t", session, "2")  # live view
        _wait_for_screen(session, lambda s: "modulation" in s and "sharpness" in s)
        _tmux("send-keys", "-t", session, "q")
        deadline = time.monotonic() + 30
        while not done.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert done.exists(), "benchlab did not exit after q"
        assert done.read_text().strip() == "0"
    finally:
        if _alive(session):
            _tmux("kill-session", "-t", session)


@pytest.mark.slow
def test_q_during_a_run_asks_before_quitting_in_tmux(tmp_path: Path) -> None:
    session = f"benchlab-quit-{uuid.uuid4().hex[:8]}"
    done = tmp_path / "exit-status"
    command = (
        f"cd {tmp_path} && TERM=xterm-256color {BENCHLAB} tui --simulate; echo $? > {done}; "
        "sleep 30"
    )
    _tmux("new-session", "-d", "-x", "80", "-y", "24", "-s", session, command)
    try:
        _wait_for_screen(session, lambda s: "bench: connected" in s)
        _tmux("send-keys", "-t", session, "3")
        _wait_for_screen(session, lambda s: "checklist (Table 4.10 steps)" in s)
        _tmux("send-keys", "-t", session, "s")
        _wait_for_screen(session, lambda s: "Done" in s and "Abort run" in s)  # first prompt
        _tmux("send-keys", "-t", session, "q")
        screen = _wait_for_screen(session, lambda s: "Quit while a run is active?" in s)
        assert "Keep running" in screen and not done.exists()
        _tmux("send-keys", "-t", session, "n")
        _wait_for_screen(session, lambda s: "Quit while a run is active?" not in s
                         and "Abort run" in s)
        assert not done.exists()
        _tmux("send-keys", "-t", session, "q")
        _wait_for_screen(session, lambda s: "Quit while a run is active?" in s)
        _tmux("send-keys", "-t", session, "y")
        deadline = time.monotonic() + 30
        while not done.exists() and time.monotonic() < deadline:
            time.sleep(0.2)
        assert done.exists() and done.read_text().strip() == "0"
        (folder,) = [p for p in (tmp_path / "sessions").iterdir() if p.is_dir()]  # + catalogue
        status = json.loads((folder / "session.json").read_text())["status"]
        assert status != "completed"  # aborted mid-run, resumable
    finally:
        if _alive(session):
            _tmux("kill-session", "-t", session)
