"""Issue 36's fallback, checked line by line (issue 42): when the configured camera profile's
frames do not come as set, the doctor tries the other known profiles, says which one fits and
goes on with the camera opened with it.

``camera-exposure-4byte-ignored-length``: the simulated firmware reads a 4-byte exposure field
whatever the command's length byte says, so the MCE-B013-U profile's 2-byte exposure is misread
(its frames carry another exposure); the v1.0.6 profile's 4-byte field round-trips.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from benchlab.cli.main import main

FITS = ("| 4 exposure unit and linearity | ok | profile MCE-B013-U/v1.0.6 fits (frame period "
        "100 ms) |  |")
TODO = ('set [camera] model = "MCE-B013-U/v1.0.6" (in your bench file; `benchlab doctor '
        '--config FILE` writes it)')


def test_the_other_profile_is_tried_and_the_one_that_fits_is_named(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    report = tmp_path / "bringup-report.md"
    rc = main(["doctor", "--simulate", "--yes", "--inject",
               "camera-exposure-4byte-ignored-length", "--report", str(report)])
    out = capsys.readouterr().out
    assert rc == 1, out
    lines = report.read_text(encoding="utf-8").splitlines()
    # the configured profile's FAIL says what differs and names the one that fits ...
    fail = [ln for ln in lines if ln.startswith("| 4 exposure unit and linearity | FAIL |")]
    assert len(fail) == 1, lines
    assert ("| profile MCE-B013-U does not fit: camera frames disagree with the MCE-B013-U "
            "profile: 3 frames in a row carry exposure 131073024 counts") in fail[0]
    assert fail[0].endswith(f"| {TODO} |")
    # ... the profile tried next is the one that fits, with the frame period it gave ...
    assert FITS in lines
    # ... and the bit depths were read with the camera opened with it
    depths = [ln for ln in lines if ln.startswith("| 5 bit depths decode |")]
    assert depths == ["| 5 bit depths decode | ok | 2 depths plausible, 8-bit again after them "
                      "(means on the 12-bit scale: 8-bit 1630, 12-bit 1638) |  |"]
    assert '- [camera] model = "MCE-B013-U/v1.0.6"' in lines
    assert "[FAIL] 4 exposure unit and linearity: profile MCE-B013-U does not fit" in out
    assert "[  ok] 4 exposure unit and linearity: profile MCE-B013-U/v1.0.6 fits" in out
