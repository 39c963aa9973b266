"""A warning raised in the forward-view analysis of ``benchlab analyze SESSION`` is printed
once (issue 29: with the forward view computed in a second process as well, it could print
twice - once per process). Run as the ``benchlab`` program runs, in a real subprocess, the
warning lines of its stderr counted."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest
from sim_runs import MTF_SMALL, run_sim

#: Run as the ``benchlab`` console script does (``main()`` with ``sys.argv``), with the
#: forward view's analysis wrapped to raise a numpy warning first, on whichever thread or
#: process computes it.
_PROGRAM = """
import sys, threading
import numpy as np
import benchlab.protocols.mtf.analysis as mtf
from benchlab.cli.main import main

real = mtf.analyze_forward_frame

def warning_first(*args, **kwargs):
    print("forward view on " + threading.current_thread().name, file=sys.stderr)
    np.float64(1.0) / np.float64(0.0)  # RuntimeWarning: divide by zero
    return real(*args, **kwargs)

mtf.analyze_forward_frame = warning_first
sys.argv = ["benchlab", "analyze", sys.argv[1]]
sys.exit(main())
"""


@pytest.fixture(scope="module")
def small_mtf(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return run_sim("mtf", tmp_path_factory.mktemp("mtf"), MTF_SMALL).session_path


@pytest.mark.slow
def test_a_forward_view_warning_is_printed_once(small_mtf: Path) -> None:
    done = subprocess.run([sys.executable, "-c", _PROGRAM, str(small_mtf)],
                          capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    # the analysis completed: the run's own results byte for byte (matched v1, none added)
    assert "identical to v1" in done.stdout, done.stdout
    assert sorted(p.name for p in (small_mtf / "results").iterdir()) == ["v1"]
    lines = done.stderr.splitlines()
    # computed once, beside the radial frames (not on the main thread)
    ran = [line for line in lines if line.startswith("forward view on ")]
    assert len(ran) == 1 and ran[0] != "forward view on MainThread", done.stderr
    warned = [line for line in lines if "RuntimeWarning: divide by zero" in line]
    assert len(warned) == 1, done.stderr
