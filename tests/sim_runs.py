"""Shared helpers for the procedure, bench, report and end-to-end tests (no tests here)."""

from __future__ import annotations

import json
from collections.abc import Callable
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
