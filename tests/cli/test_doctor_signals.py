"""`benchlab doctor` stopped by Ctrl-C or SIGTERM (a real process, a real signal) still writes
its report - the checks done so far and where it stopped - and the recording beside it."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

_RUN = "import sys; from benchlab.cli.main import main; sys.exit(main())"


@pytest.mark.parametrize(("sig", "status", "name"), [(signal.SIGTERM, 143, "SIGTERM"),
                                                       (signal.SIGINT, 130, "SIGINT")])
def test_a_stopped_bring_up_writes_what_it_did(
    sig: signal.Signals, status: int, name: str, tmp_path: Path
) -> None:
    report = tmp_path / "bringup-report.md"
    proc = subprocess.Popen(
        [sys.executable, "-c", _RUN, "doctor", "--simulate", "--report", str(report)],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        env={**os.environ, "PYTHONUNBUFFERED": "1"}, cwd=tmp_path)
    assert proc.stdout is not None
    seen = b""
    deadline = time.monotonic() + 60
    while b"[y/N]" not in seen:  # the first question (LED on for the camera checks) waits
        chunk = os.read(proc.stdout.fileno(), 4096)
        assert chunk and time.monotonic() < deadline, seen.decode()
        seen += chunk
    assert not report.exists()
    proc.send_signal(sig)
    out, err = proc.communicate(timeout=60)
    assert proc.returncode == status, (seen + out, err)
    text = report.read_text(encoding="utf-8")
    assert f"**Interrupted** ({name}) during 4 light for the camera checks" in text
    assert "| 3 camera enumerates and answers | ok |" in text
    assert "| 6 LED controller identity | ok |" in text
    assert "| 8 stage" not in text  # never reached
    assert (tmp_path / "bringup-report.cassette.jsonl.gz").stat().st_size > 0
    assert b"report written to" in seen + out
