"""``benchlab benchmark journal``: the cost of saving a frame as a session grows.

Saves many small frames into one session the way a procedure does (``Session.save_frame``,
one step per few frames, ``step_frames`` asked before each step as resume does) and times
each block of frames. The session's bookkeeping is linear in its frames when the time per
frame of the last block equals that of the first.
"""

from __future__ import annotations

import tempfile
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from benchlab.session import Session


@dataclass(frozen=True)
class JournalBenchmark:
    """Time per saved frame, block by block."""

    n_frames: int
    block: int
    ms_per_frame: tuple[float, ...]  # wall time, one entry per block of ``block`` frames
    cpu_ms_per_frame: tuple[float, ...]  # this process's CPU time, likewise
    journal_bytes: int

    @property
    def last_to_first(self) -> float:
        """CPU time per frame of the last block over that of the first (1.0: flat). CPU, not
        wall time: the fsyncs' waits vary with the disk and whatever else writes to it."""
        return self.cpu_ms_per_frame[-1] / self.cpu_ms_per_frame[0]


def run_journal_benchmark(n_frames: int = 10_000, *, block: int = 1000,
                          frames_per_step: int = 4, shape: tuple[int, int] = (8, 8),
                          root: Path | None = None) -> JournalBenchmark:
    """Save ``n_frames`` frames of ``shape`` into one new session and time each block.

    Parameters
    ----------
    n_frames
        Frames to save (rounded down to whole blocks; at least one block).
    block
        Frames per timed block.
    frames_per_step
        Frames each step saves (a through-focus position, a characterisation exposure).
    shape
        Frame size in pixels: small, so the time is the bookkeeping, not the pixels.
    root
        Sessions folder (default: a temporary folder, removed afterwards).
    """
    if block < 1 or n_frames < block:
        raise ValueError(f"need at least one block of {block} frames, got {n_frames}")
    with tempfile.TemporaryDirectory(prefix="benchlab-journal-") as tmp:
        session = Session.create(Path(root or tmp), procedure="journal", params={},
                                 operator="benchmark", devices={}, software_version="bench")
        try:
            pixels = np.zeros(shape, np.uint8)
            for k in range(frames_per_step):  # warm-up: imports, first file in the folder
                session.save_frame("warm-up", f"f{k}", pixels, {"exposure_ms": 1.0, "bits": 8})
            times: list[float] = []
            cpu: list[float] = []
            start, start_cpu = time.perf_counter(), time.process_time()
            for i in range(n_frames // block * block):
                step = f"s{i // frames_per_step:05d}"
                if i % frames_per_step == 0:
                    session.step_frames(step)  # what resume asks before a step
                pixels[0, 0] = i % 251
                session.save_frame(step, f"f{i % frames_per_step}", pixels,
                                   {"exposure_ms": 1.0, "bits": 8})
                if (i + 1) % block == 0:
                    now, now_cpu = time.perf_counter(), time.process_time()
                    times.append((now - start) * 1e3 / block)
                    cpu.append((now_cpu - start_cpu) * 1e3 / block)
                    start, start_cpu = now, now_cpu
            size = session.events_path.stat().st_size
        finally:
            session.release()
    return JournalBenchmark(len(times) * block, block, tuple(times), tuple(cpu), size)


def format_journal_benchmark(result: JournalBenchmark) -> str:
    """The table ``benchlab benchmark journal`` prints."""
    lines = [f"Saving {result.n_frames} frames of one session "
             f"(journal {result.journal_bytes / 1e6:.1f} MB at the end)",
             "", f"{'frames':>13}  {'wall ms per frame':>17}  {'CPU ms per frame':>16}"]
    for i, (ms, cpu_ms) in enumerate(zip(result.ms_per_frame, result.cpu_ms_per_frame,
                                         strict=True)):
        lines.append(f"{i * result.block + 1:>6}-{(i + 1) * result.block:<6}  {ms:>17.3f}  "
                     f"{cpu_ms:>16.3f}")
    lines += ["", f"CPU per frame, last block / first block: {result.last_to_first:.2f} "
              "(1.00: a frame costs the same whatever the frames before it)"]
    return "\n".join(lines)
