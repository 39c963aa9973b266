"""The terminal UI's signal matrix (issue 38): screen x way of ending x trial.

Starts ``benchlab --simulate`` in a pseudo-terminal that is its controlling terminal, opens a
screen (Devices, Live, Sessions, the radiometry's set-up prompt unanswered, or Run
mid-radiometry), then either closes the terminal (the master side: the kernel hangs up the
session, SIGHUP) or sends SIGTERM, and measures how long
the process takes to end and with which status. On the prompt and Run screens it also reads the
session's journal: status ``interrupted`` with the signal's name. Optionally keeps the cores busy.

    python tools/tui_signal_matrix.py [--trials 20] [--busy 2] [--screens live,run]

Prints one line per case and exits 1 if any trial took 5 s or more, ended with a status other
than 128 + signal, or left a journal that does not say interrupted.
"""

from __future__ import annotations

import argparse
import fcntl
import json
import os
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
        note = ""
        if screen in RUNS:
            journal = _journal(sessions)
            reasons = [e.get("reason") for e in journal if e["kind"] == "interrupted"]
            last = " > ".join(e["kind"] for e in journal[-3:])
            note = ("interrupted " + ",".join(map(str, reasons)) if reasons
                    else f"NOT interrupted (journal ends: {last})")
        return took, proc.returncode, note


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--trials", type=int, default=20, help="trials per case (20)")
    parser.add_argument("--busy", type=int, default=0, help="busy loops to run alongside (0)")
    parser.add_argument("--screens", default=",".join(SCREENS), help="comma-separated screens")
    args = parser.parse_args()
    busy = [subprocess.Popen([sys.executable, "-c", "while True: pass"])
            for _ in range(args.busy)]
    bad = 0
    try:
        print(f"{'screen':9} {'ended by':8} {'trials':>6} {'ok':>4} {'median s':>9} "
              f"{'max s':>6}  journal")
        for screen in args.screens.split(","):
            for how in ("SIGHUP", "SIGTERM"):
                want = 128 + getattr(signal, how)
                results = [trial(screen, how) for _ in range(args.trials)]
                ok = [r for r in results if r[0] < DEADLINE_S and r[1] == want
                      and (screen not in RUNS or r[2] == f"interrupted {how}")]
                bad += len(results) - len(ok)
                times = sorted(r[0] for r in results)
                notes = sorted({r[2] for r in results if r[2]})
                print(f"{screen:9} {how:8} {len(results):>6} {len(ok):>4} "
                      f"{times[len(times) // 2]:>9.2f} {times[-1]:>6.2f}  {'; '.join(notes)}",
                      flush=True)
    finally:
        for p in busy:
            p.kill()
            p.wait()
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
