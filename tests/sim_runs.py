"""Shared helpers for the procedure, bench, report and end-to-end tests (no tests here)."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import tempfile
import time
from collections.abc import Callable, Sequence
from pathlib import Path
from typing import Any

from benchlab.bench import Bench, BenchConfig
from benchlab.protocols import RunOutcome, start_run
from benchlab.session import read_results

FIXTURES = Path(__file__).resolve().parents[1] / "fixtures" / "params"
MTF_SMALL = FIXTURES / "mtf-small.toml"
RAD_SMALL = FIXTURES / "radiometry-small.toml"


def yes(step: Any, message: str) -> bool:
    return True


def run_sim(
    procedure: str, root: Path, params: Path | None = None, *, noise: bool = True,
    prompt: Callable[[Any, str], bool] = yes, **kwargs: Any,
) -> RunOutcome:
    """A complete run on a fresh simulated bench."""
    with Bench.open(BenchConfig.load(None, simulate=True), simulate=True, noise=noise) as bench:
        runner = start_run(procedure, bench=bench, params=params, root=root, operator="test",
                           prompt=prompt, **kwargs)
        return runner.run()


def only_session(root: Path) -> Path:
    (path,) = [p for p in root.iterdir() if (p / "session.json").is_file()]
    return path


def events(session: Path) -> list[dict[str, Any]]:
    lines = (session / "events.jsonl").read_text().splitlines()
    return [json.loads(line) for line in lines if line.strip()]


def completed_steps(session: Path) -> int:
    """Steps the journal says completed (0 while the journal is still being created)."""
    try:
        return sum(1 for e in events(session) if e["kind"] == "step_completed")
    except (OSError, ValueError):
        return 0


def signal_mid_run(args: Sequence[str], root: Path, *, after_steps: int, sig: int,
                   timeout_s: float = 120.0) -> tuple[int, str, str]:
    """Run ``benchlab ARGS --out ROOT`` in a real process and send it ``sig`` once its session
    has completed ``after_steps`` steps; returns (exit status, stdout, stderr)."""
    cmd = [sys.executable, "-m", "benchlab.cli.main", *args, "--out", str(root)]
    with tempfile.TemporaryFile("w+") as out, tempfile.TemporaryFile("w+") as err:
        proc = subprocess.Popen(cmd, stdout=out, stderr=err, text=True)
        try:
            deadline = time.monotonic() + timeout_s
            while time.monotonic() < deadline:
                sessions = [p for p in root.iterdir() if (p / "events.jsonl").is_file()]
                if sessions and completed_steps(sessions[0]) >= after_steps:
                    break
                assert proc.poll() is None, "the run ended before the signal"
                time.sleep(0.005)
            os.kill(proc.pid, sig)
            proc.wait(timeout=60)
        finally:
            if proc.poll() is None:
                proc.kill()
                proc.wait()
        out.seek(0)
        err.seek(0)
        return proc.returncode, out.read(), err.read()


def tables_of(results: Path) -> dict[str, Any]:
    """The tables of a results folder, read back from disk under their thesis labels."""
    return read_results(results)[0]


#: One small characterise plan (the procedure and the TUI tests share it).
TINY = """procedure = "characterise"
[camera]
gains = [1.0]
bits = [12]
width = 32
height = 32
[sweep]
log_steps = 3
linear_steps = 6
near_saturation_steps = 4
[spatial]
stack_frames = 3
"""


def reseal_results(version: Path) -> None:
    """Record the current hashes of a results version's files in its ``summary.json``: after a
    test edits a table to fabricate another lens or an older layout, the version reads as if
    it had been written so (an edit without this is refused, naming the file)."""
    import hashlib
    import json

    summary = version / "summary.json"
    doc = json.loads(summary.read_text(encoding="utf-8"))
    if "files_sha256" in doc:
        doc["files_sha256"] = {
            p.name: hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(version.iterdir()) if p.is_file() and p.name != "summary.json"}
        summary.write_text(json.dumps(doc, indent=2), encoding="utf-8")
