"""The terminal UI's signal matrix (issue 38): screen x way of ending x trial.

Starts ``benchlab --simulate`` in a pseudo-terminal that is its controlling terminal, opens a
screen (Devices, Live, Sessions, the radiometry's set-up prompt unanswered, or Run
mid-radiometry), then either closes the terminal (the master side: the kernel hangs up the
session, SIGHUP) or sends SIGTERM, and measures how long
the process takes to end and with which status. On the prompt and Run screens it also reads the
session's journal: status ``interrupted`` with the signal's name. Optionally keeps the cores busy.

    python tools/tui_signal_matrix.py [--trials 20] [--busy 2] [--screens live,run] [--tmux]

``--tmux`` adds, per screen, the program run as a tmux pane's process (its own ``-L`` server)
ended by ``tmux kill-session``: tmux reaps the process, so its status is not read there (the
pseudo-terminal cases read it), only the time it took and the journal.

Prints one line per case and exits 1 if any trial took 5 s or more, ended with a status other
than 128 + signal, or left a journal that does not say interrupted.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
import shutil
import signal
import struct
import subprocess
import sys
import tempfile
import termios
import time
from pathlib import Path

DEADLINE_S = 5.0
#: screen -> the keys that open it (and start the radiometry on the Run screen).
SCREENS = {"devices": b"", "live": b"2", "sessions": b"4", "prompt": b"3p", "run": b"3p"}
#: Screens whose case starts the radiometry, so the journal must say interrupted.
RUNS = ("prompt", "run")
RADIOMETRY = Path(__file__).resolve().parents[1] / "fixtures" / "params" / "radiometry-small.toml"


def _ctty() -> None:
    fcntl.ioctl(0, termios.TIOCSCTTY, 0)


def _drain(master: int, buf: bytearray) -> None:
    try:
        while chunk := os.read(master, 65536):
            buf += chunk
    except OSError:
        pass


def _journal(sessions: Path) -> list[dict]:
    for folder in sessions.iterdir():
        events = folder / "events.jsonl"
        if events.is_file():
            return [json.loads(line) for line in events.read_text().splitlines() if line.strip()]
    return []


def trial(screen: str, how: str) -> tuple[float, int | None, str]:
    """One trial: (seconds to end, exit status, journal note)."""
    with tempfile.TemporaryDirectory() as tmp:
        sessions = Path(tmp) / "sessions"
        sessions.mkdir()
        master, slave = os.openpty()
        fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 30, 100, 0, 0))
        proc = subprocess.Popen(
            [sys.executable, "-m", "benchlab.cli.main", "--simulate", "--sessions",
             str(sessions), "--radiometry-params", str(RADIOMETRY)],
            stdin=slave, stdout=slave, stderr=slave, cwd=tmp, start_new_session=True,
            preexec_fn=_ctty, env={**os.environ, "TERM": "xterm-256color"})  # noqa: PLW1509
        os.close(slave)
        os.set_blocking(master, False)
        buf = bytearray()
        deadline = time.monotonic() + 90
        while b"connected (simulated)" not in buf and time.monotonic() < deadline:
            _drain(master, buf)
            time.sleep(0.05)
        for key in SCREENS[screen]:
            os.write(master, bytes([key]))
            time.sleep(1.0)
        if screen == "prompt":  # the set-up prompt on screen, not answered
            os.write(master, b"s")
            while time.monotonic() < deadline and not any(
                    e["kind"] == "prompt" for e in _journal(sessions)):
                _drain(master, buf)
                time.sleep(0.1)
            time.sleep(0.5)  # the dialog composed
        if screen == "run":
            os.write(master, b"s")
            while time.monotonic() < deadline and not any(
                    e["kind"] == "step_started" and "position" in str(e.get("step", ""))
                    for e in _journal(sessions)):
                os.write(master, b"y")  # confirms the set-up prompt
                _drain(master, buf)
                time.sleep(0.3)
        _drain(master, buf)
        start = time.monotonic()
        if how == "SIGHUP":
            os.close(master)
        else:
            proc.send_signal(signal.SIGTERM)
        while proc.poll() is None and time.monotonic() - start < DEADLINE_S + 10:
            if how != "SIGHUP":
                _drain(master, buf)
            time.sleep(0.02)
        took = time.monotonic() - start
        if proc.poll() is None:
            proc.kill()
            proc.wait()
        if how != "SIGHUP":
            os.close(master)
        return took, proc.returncode, _journal_note(screen, sessions)


TMUX_SOCKET = f"benchlab-matrix-{os.getpid()}"


def _tmux(*args: str) -> str:
    tmux = shutil.which("tmux")
    assert tmux is not None, "--tmux needs tmux"
    return subprocess.run([tmux, "-L", TMUX_SOCKET, *args], capture_output=True, text=True,
                          timeout=30, check=False).stdout


def _running(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except (OSError, IndexError):
        return False
    return state != "Z"


def trial_tmux(screen: str) -> tuple[float, int | None, str]:
    """One trial in a tmux pane ended by ``kill-session``: (seconds to end, None, journal)."""
    with tempfile.TemporaryDirectory() as tmp:
        sessions = Path(tmp) / "sessions"
        sessions.mkdir()
        # exec: the program is the pane's process, as when started from a shell whose window
        # is then closed.
        command = (f"cd {tmp} && TERM=xterm-256color exec {sys.executable} -m "
                   f"benchlab.cli.main --simulate --sessions {sessions} "
                   f"--radiometry-params {RADIOMETRY}")
        name = "matrix"
        _tmux("new-session", "-d", "-x", "100", "-y", "30", "-s", name, command)
        try:
            deadline = time.monotonic() + 90
            while ("connected (simulated)" not in _tmux("capture-pane", "-p", "-t", name)
                   and time.monotonic() < deadline):
                time.sleep(0.1)
            pid = int(_tmux("list-panes", "-t", name, "-F", "#{pane_pid}").split()[0])
            for key in SCREENS[screen].decode():
                _tmux("send-keys", "-t", name, key)
                time.sleep(1.0)
            if screen in RUNS:
                _tmux("send-keys", "-t", name, "s")
            while screen in RUNS and time.monotonic() < deadline:
                journal = _journal(sessions)
                if screen == "prompt" and any(e["kind"] == "prompt" for e in journal):
                    time.sleep(0.5)  # the dialog composed
                    break
                if screen == "run" and any(e["kind"] == "step_started" and "position" in
                                           str(e.get("step", "")) for e in journal):
                    break
                if screen == "run":
                    _tmux("send-keys", "-t", name, "y")  # confirms the set-up prompt
                time.sleep(0.3)
            _tmux("kill-session", "-t", name)
            start = time.monotonic()
            while _running(pid) and time.monotonic() - start < DEADLINE_S + 10:
                time.sleep(0.02)
            took = time.monotonic() - start
            if _running(pid):
                os.kill(pid, signal.SIGKILL)
        finally:
            _tmux("kill-server")
        return took, None, _journal_note(screen, sessions)


def _journal_note(screen: str, sessions: Path) -> str:
    if screen not in RUNS:
        return ""
    journal = _journal(sessions)
    reasons = [e.get("reason") for e in journal if e["kind"] == "interrupted"]
    last = " > ".join(e["kind"] for e in journal[-3:])
    return ("interrupted " + ",".join(map(str, reasons)) if reasons
            else f"NOT interrupted (journal ends: {last})")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20, help="trials per case (20)")
    parser.add_argument("--busy", type=int, default=0, help="busy loops to run alongside (0)")
    parser.add_argument("--screens", default=",".join(SCREENS), help="comma-separated screens")
    parser.add_argument("--tmux", action="store_true",
                        help="also end each screen by tmux kill-session (a tmux pane)")
    parser.add_argument("--only-tmux", action="store_true",
                        help="only the tmux kill-session cases")
    args = parser.parse_args()
    ways = (() if args.only_tmux else ("SIGHUP", "SIGTERM")) + (
        ("tmux-kill",) if args.tmux or args.only_tmux else ())
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(args.busy)]
    bad = 0
    try:
        print(f"{'screen':9} {'ended by':9} {'trials':>6} {'ok':>4} {'median s':>9} "
              f"{'max s':>6}  journal")
        for screen in args.screens.split(","):
            for how in ways:
                sig = "SIGHUP" if how == "tmux-kill" else how
                want = None if how == "tmux-kill" else 128 + getattr(signal, sig)
                results = [trial_tmux(screen) if how == "tmux-kill" else trial(screen, how)
                           for _ in range(args.trials)]
                ok = [r for r in results if r[0] < DEADLINE_S and r[1] == want
                      and (screen not in RUNS or r[2] == f"interrupted {sig}")]
                bad += len(results) - len(ok)
                times = sorted(r[0] for r in results)
                notes = sorted({r[2] for r in results if r[2]})
                print(f"{screen:9} {how:9} {len(results):>6} {len(ok):>4} "
                      f"{times[len(times) // 2]:>9.2f} {times[-1]:>6.2f}  {'; '.join(notes)}",
                      flush=True)
    finally:
        for p in busy:
            p.kill()
            p.wait()
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
