"""mypy sees the installed layout: a wrong call from one layer into another fails the check.

`drivers/` and `protocols/` install as `benchlab.drivers` / `benchlab.protocols`; the
symlinks `benchlab/drivers` and `benchlab/protocols` give mypy (and IDEs) the same layout,
so these imports resolve to real types instead of `Any`.
"""

from __future__ import annotations

from pathlib import Path

import pytest
from mypy import api

ROOT = Path(__file__).resolve().parents[1]

PROBE = '''\
from benchlab.drivers.mightex.camera import MightexCamera
from benchlab.protocols.mtf.params import UsafElement


def right() -> None:
    MightexCamera.open(serial="SIM-130001")
    UsafElement.parse("4-2")


def wrong() -> None:
    MightexCamera.open(serial=123, nonexistent=1)
    UsafElement.parse(42)
'''


def test_layout_symlinks_point_at_top_level_folders() -> None:
    for name in ("drivers", "protocols"):
        link = ROOT / "benchlab" / name
        assert link.is_symlink(), f"benchlab/{name} must be a symlink to ../{name}"
        assert link.resolve() == (ROOT / name).resolve()


def _mypy(probe: Path) -> tuple[str, str, int, list[str]]:
    """mypy on one probe file with the project's own configuration (mypy_path, per-module
    ignores); a shared cache keeps repeat runs fast. Returns stdout, stderr, status, errors."""
    stdout, stderr, status = api.run([
        "--config-file", str(ROOT / "pyproject.toml"),
        "--cache-dir", str(ROOT / ".mypy_cache"),
        "--no-error-summary", "--hide-error-context", "--show-error-codes",
        str(probe),
    ])
    return stdout, stderr, status, [line for line in stdout.splitlines() if ": error:" in line]


@pytest.mark.slow
def test_wrong_cross_layer_call_is_a_type_error(tmp_path: Path) -> None:
    probe = tmp_path / "probe_cross_layer.py"
    probe.write_text(PROBE, encoding="utf-8")
    stdout, stderr, status, errors = _mypy(probe)
    lines = sorted({int(line.split(":")[1]) for line in errors})
    assert status == 1, stdout + stderr
    # Only the three wrong arguments in wrong(); right() type-checks.
    assert lines == [11, 12], stdout
    text = "\n".join(errors)
    assert 'Unexpected keyword argument "nonexistent" for "open" of "MightexCamera"' in text
    assert 'Argument "serial" to "open" of "MightexCamera" has incompatible type "int"' in text
    assert 'Argument 1 to "parse" of "UsafElement" has incompatible type "int"' in text


TYPO_PROBE = '''\
import numpy as np

import benchlab
from benchlab.protocols.runs import reanalyze


def right(bench: benchlab.Bench) -> None:
    benchlab.run_procedure(bench, "mtf")
    benchlab.measure_bars(np.zeros((8, 8)), orientation="sagittal", estimator="auto")
    reanalyze("s", estimator="histogram")


def typos(bench: benchlab.Bench) -> None:
    benchlab.run_procedure(bench, "mft")
    benchlab.measure_bars(np.zeros((8, 8)), orientation="sagital")
    benchlab.measure_bars(np.zeros((8, 8)), estimator="histgram")
    reanalyze("s", estimator="sine")
'''


@pytest.mark.slow
def test_a_mistyped_option_string_is_a_type_error(tmp_path: Path) -> None:
    """Procedure, orientation and estimator names are ``Literal`` types (issue 42)."""
    probe = tmp_path / "probe_typos.py"
    probe.write_text(TYPO_PROBE, encoding="utf-8")
    stdout, stderr, status, errors = _mypy(probe)
    assert status == 1, stdout + stderr
    assert sorted({int(line.split(":")[1]) for line in errors}) == [14, 15, 16, 17], stdout
    assert all("[arg-type]" in line for line in errors), stdout
