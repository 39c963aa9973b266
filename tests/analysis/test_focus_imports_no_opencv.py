"""The through-focus analysis (a depth session's) imports no OpenCV: only the live sharpness
figure needs it, imported when one is asked for (issue 39: ~50 ms of every `run depth` and depth
re-analysis)."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np

from benchlab.analysis.focus import sharpness


def test_the_depth_analysis_modules_import_no_opencv() -> None:
    code = ("import sys, json; import benchlab.analysis.focus.through_focus, "
            "benchlab.analysis.focus.criteria, benchlab.protocols.depth.analysis; "
            "from benchlab.analysis.focus import sharpness; "
            "print(json.dumps(sorted(sys.modules)))")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          check=True, timeout=120)
    loaded = json.loads(done.stdout.strip().splitlines()[-1])
    assert "cv2" not in loaded


def test_the_sharpness_figure_still_reads_a_frame() -> None:
    frame = np.zeros((16, 16))
    frame[:, 8:] = 100.0
    assert sharpness(frame) > sharpness(np.full((16, 16), 50.0)) == 0.0
