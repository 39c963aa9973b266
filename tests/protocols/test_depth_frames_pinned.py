"""A small `run depth` on the simulated bench gives the frames and results tables it gave before
the speed work on the simulated camera (issue 39): every frame's pixels and every results CSV
are compared, as SHA-256, with ``tests/data/depth_small_pinned.json``.

The expected digests were computed once by the code before that work (main 59e6bb1: the sensor
model's plain full-frame expressions, the chart's disc evaluated at every stage position, the
composed scene on a copy), with :func:`digest` below. The speed-ups must keep every byte:
frames are raw data, and a result that moved would have to be shown more right first.

Pixels, not files: a frame file also holds its acquisition time, so its bytes (and the hash
the journal records over them) differ between any two runs. The same numpy and scipy on one
CPU give the same bits; another CPU's SIMD kernels could move a float in its last bit and, if it
sat on a quantisation boundary, a code - regenerate the file with :func:`digest` on the code
before a change, never after it.
"""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from sim_runs import FIXTURES, run_sim

from benchlab.storage import load_frame_tiff

PINNED = Path(__file__).resolve().parents[1] / "data" / "depth_small_pinned.json"


def digest(session: Path, results: Path) -> dict[str, str]:
    """``frame file name -> sha256 of its pixels (dtype, shape, bytes)`` and ``csv name ->
    sha256 of the file`` for one depth session."""
    out: dict[str, str] = {}
    for path in sorted((session / "frames").glob("*.tiff")):
        pixels = np.ascontiguousarray(load_frame_tiff(path)[0])
        head = f"{pixels.dtype.str} {pixels.shape}\n".encode()
        out[f"frame:{path.name}"] = hashlib.sha256(head + pixels.tobytes()).hexdigest()
    for path in sorted(results.glob("*.csv")):
        out[f"csv:{path.name}"] = hashlib.sha256(path.read_bytes()).hexdigest()
    return out


@pytest.mark.slow
def test_small_depth_run_keeps_every_pixel_and_table(tmp_path: Path) -> None:
    out = run_sim("depth", tmp_path, FIXTURES / "depth-small.toml")
    got = digest(out.session_path, out.results_path)
    want = json.loads(PINNED.read_text())["digests"]
    assert sorted(got) == sorted(want)
    assert sum(k.startswith("frame:") for k in got) == 11  # 9 distances, 60 and 62 mm twice
    changed = sorted(k for k in want if got[k] != want[k])
    assert changed == []
