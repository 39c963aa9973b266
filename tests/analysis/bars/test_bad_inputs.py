"""Every bad input gets ``benchlab: error: ...`` and changes nothing (issue 10, item 3)."""

from __future__ import annotations

import builtins
import errno
import io
import json
import os
import shutil
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import numpy as np
import pytest
import tifffile

from benchlab.cli.main import main
from benchlab.drivers.mightex import protocol as mightex_protocol
from benchlab.protocols import params as params_mod
from benchlab.protocols.params import load_params
from benchlab.session import Session, SessionError, check_sessions_root
from benchlab.storage import save_frame_tiff
from benchlab.synthetic.bars import bar_roi
from benchlab.tui.services import plain_error

ROOT = Path(__file__).resolve().parents[3]
RAD_SMALL = ROOT / "fixtures" / "params" / "radiometry-small.toml"
README = ROOT / "README.md"


def _snapshot(path: Path) -> dict[str, bytes]:
    return {p.relative_to(path).as_posix(): p.read_bytes()
            for p in sorted(path.rglob("*")) if p.is_file()}


@pytest.fixture
def read_only() -> Iterator[Callable[[Path], None]]:
    """Make folders read-only as a normal user sees them. Permission bits do not bind root
    (this suite may run as root in containers), so writes under the folder also get the
    EACCES a non-root user gets, at the OS calls benchlab uses."""
    roots: list[Path] = []
    patch = pytest.MonkeyPatch()

    def under(path: Any) -> bool:
        try:
            p = Path(os.fsdecode(path)).absolute()
        except TypeError:
            return False
        return any(p == r or r in p.parents for r in roots)

    def denied(path: Any) -> PermissionError:
        return PermissionError(errno.EACCES, os.strerror(errno.EACCES), os.fsdecode(path))

    real_open, real_mkdir, real_access = os.open, os.mkdir, os.access
    real_builtin_open = builtins.open

    def os_open(path: Any, flags: int, *a: Any, **kw: Any) -> int:
        if under(path) and flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT):
            raise denied(path)
        return real_open(path, flags, *a, **kw)

    def mkdir(path: Any, *a: Any, **kw: Any) -> None:
        if under(path):
            raise denied(path)
        real_mkdir(path, *a, **kw)

    def access(path: Any, mode: int, *a: Any, **kw: Any) -> bool:
        if under(path) and mode & os.W_OK:
            return False
        return real_access(path, mode, *a, **kw)

    def b_open(file: Any, mode: str = "r", *a: Any, **kw: Any) -> Any:
        if isinstance(file, str | bytes | os.PathLike) and under(file) and set(mode) & set("wax+"):
            raise denied(file)
        return real_builtin_open(file, mode, *a, **kw)

    patch.setattr(os, "open", os_open)
    patch.setattr(os, "mkdir", mkdir)
    patch.setattr(os, "access", access)
    patch.setattr(builtins, "open", b_open)
    patch.setattr(io, "open", b_open)

    def make(path: Path) -> None:
        path.chmod(0o555)
        roots.append(path.absolute())

    yield make
    patch.undo()
    for r in roots:
        r.chmod(0o755)


# ---- run --out -------------------------------------------------------------------------------
def test_run_out_on_a_file_is_refused(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    target = tmp_path / "notes.txt"
    target.write_text("keep me")
    assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(RAD_SMALL),
                 "--out", str(target)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("benchlab: error: ") and "is a file, not a folder" in err
    assert target.read_text() == "keep me"


def test_run_out_with_missing_parent_creates_nothing(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    typo = tmp_path / "sesions" / "today"
    assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(RAD_SMALL),
                 "--out", str(typo)]) == 1
    err = capsys.readouterr().err
    assert f"parent folder {typo.parent} does not exist" in err
    assert list(tmp_path.iterdir()) == []


def test_only_the_last_level_is_created(tmp_path: Path) -> None:
    assert check_sessions_root(tmp_path / "new") == tmp_path / "new"
    assert (tmp_path / "new").is_dir()
    with pytest.raises(SessionError, match="does not exist"):
        check_sessions_root(tmp_path / "a" / "b")
    assert not (tmp_path / "a").exists()


def test_run_out_read_only(
    tmp_path: Path, read_only: Callable[[Path], None], capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "ro"
    out.mkdir()
    read_only(out)
    assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(RAD_SMALL),
                 "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert err.startswith("benchlab: error: ") and "not writable" in err
    assert list(out.iterdir()) == []


# ---- read-only sessions ----------------------------------------------------------------------
@pytest.fixture(scope="module")
def done_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    root = tmp_path_factory.mktemp("done")
    assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(RAD_SMALL),
                 "--out", str(root)]) == 0
    (path,) = [p for p in root.iterdir() if (p / "session.json").is_file()]
    return path


@pytest.mark.slow
@pytest.mark.parametrize("argv", [["analyze"], ["report"], ["resume", "--simulate", "--yes"],
                                  ["report", "--out"]], ids=["analyze", "report", "resume",
                                                             "report-out"])
def test_read_only_session_is_a_clean_error(
    done_session: Path, tmp_path: Path, read_only: Callable[[Path], None], argv: list[str],
    capsys: pytest.CaptureFixture[str],
) -> None:
    path = Path(shutil.copytree(done_session, tmp_path / done_session.name))
    # an interrupted session, so resume has work to do (a complete one changes nothing anyway)
    meta = json.loads((path / "session.json").read_text())
    (path / "session.json").write_text(json.dumps({**meta, "status": "interrupted"}))
    before = _snapshot(path)
    for folder in [path, *[p for p in path.rglob("*") if p.is_dir()]]:
        read_only(folder)
    if argv == ["report", "--out"]:
        # beside the session's files (results/ is refused before any write: issue 38)
        args = ["report", str(path), "--out", str(path / "r.html")]
    else:
        args = [argv[0], str(path), *argv[1:]]
    assert main(args) == 1
    err = capsys.readouterr().err
    assert err.startswith("benchlab: error: ") and "Traceback" not in err
    assert "permission" in err.lower() or "read-only" in err.lower()
    assert _snapshot(path) == before


def test_tui_says_read_only_in_plain_words(tmp_path: Path) -> None:
    exc = PermissionError(errno.EACCES, "Permission denied", str(tmp_path / "report.html"))
    text = plain_error(exc)
    assert "read-only or you have no permission" in text and "report.html" in text
    assert "PermissionError" not in text


# ---- session.json with wrong types ----------------------------------------------------------
@pytest.mark.slow
@pytest.mark.parametrize("field,value", [("params", "not a table"), ("procedure", 7),
                                         ("status", ["running"]), ("started_at", None)])
def test_session_json_with_wrong_types(
    done_session: Path, tmp_path: Path, field: str, value: Any,
    capsys: pytest.CaptureFixture[str],
) -> None:
    path = Path(shutil.copytree(done_session, tmp_path / done_session.name))
    meta = json.loads((path / "session.json").read_text())
    (path / "session.json").write_text(json.dumps({**meta, field: value}))
    before = _snapshot(path)
    with pytest.raises(SessionError, match=f"field '{field}' must be"):
        Session.open(path)
    for cmd in (["analyze", str(path)], ["report", str(path)],
                ["resume", str(path), "--simulate", "--yes"]):
        assert main(cmd) == 1
        err = capsys.readouterr().err
        assert err.startswith("benchlab: error: ") and f"field '{field}' must be" in err
    assert _snapshot(path) == before


# ---- analyze IMAGE: colour TIFF, 12-bit codes, option values ----------------------------------
@pytest.fixture(scope="module")
def bars() -> np.ndarray:
    roi, _ = bar_roi(0, shape=(40, 50), px_per_period=16.0, noise_sigma=1.5)
    img = np.full((200, 240), 100, np.uint8)
    img[50:90, 60:110] = roi
    return img


def test_rgb_tiff_is_refused(tmp_path: Path, bars: np.ndarray,
                             capsys: pytest.CaptureFixture[str]) -> None:
    rgb = np.stack([bars, bars // 2, bars // 3], axis=-1)
    path = tmp_path / "colour.tiff"
    tifffile.imwrite(path, rgb, photometric="rgb")
    assert main(["analyze", str(path), "--roi", "50,60,90,110"]) == 1
    assert "colour TIFF (3 samples per pixel)" in capsys.readouterr().err
    grey = tmp_path / "grey-as-rgb.tiff"  # three equal channels are a grey image
    tifffile.imwrite(grey, np.stack([bars] * 3, axis=-1), photometric="rgb")
    assert main(["analyze", str(grey), "--roi", "50,60,90,110", "--json"]) == 0


def test_12_bit_metadata_with_larger_codes_is_refused(
    tmp_path: Path, bars: np.ndarray, capsys: pytest.CaptureFixture[str]
) -> None:
    pixels = bars.astype(np.uint16) * 64
    assert pixels.max() > 4095
    path = tmp_path / "f.tiff"
    save_frame_tiff(path, pixels, {"bits": 12})
    assert main(["analyze", str(path), "--roi", "50,60,90,110"]) == 1
    err = capsys.readouterr().err
    assert f"metadata says 12-bit but the frame holds codes up to {int(pixels.max())}" in err
    ok = tmp_path / "ok.tiff"
    save_frame_tiff(ok, bars.astype(np.uint16) * 16, {"bits": 12})
    assert main(["analyze", str(ok), "--roi", "50,60,90,110", "--json"]) == 0


@pytest.mark.parametrize("option", [["--freq", "0"], ["--freq", "-3"], ["--freq", "nan"],
                                    ["--bootstrap", "0"], ["--bootstrap", "-1"]])
def test_meaningless_option_values_are_usage_errors(
    tmp_path: Path, bars: np.ndarray, option: list[str], capsys: pytest.CaptureFixture[str]
) -> None:
    path = tmp_path / "bars.tiff"
    tifffile.imwrite(path, bars)
    assert main(["analyze", str(path), "--roi", "50,60,90,110", *option]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"benchlab: error: {option[0]} must be")


def test_roi_on_a_session_folder_is_a_usage_error(
    done_session: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    before = _snapshot(done_session)
    assert main(["analyze", str(done_session), "--roi", "1,2,3,4"]) == 2
    assert "--roi: for one image only" in capsys.readouterr().err
    assert _snapshot(done_session) == before


# ---- benchlab --simulate --sessions DIR (the README's TUI options) ----------------------------
@pytest.mark.parametrize("extra", [["--sessions", "DIR"], ["--operator", "ana"],
                                   ["--config", "bench.toml"], ["--mtf-params", "m.toml"]])
def test_top_level_tui_options_reach_the_tui(extra: list[str],
                                             monkeypatch: pytest.MonkeyPatch) -> None:
    seen: dict[str, Any] = {}
    monkeypatch.setattr("benchlab.cli.tui.run_tui", lambda args: seen.update(vars(args)) or 0)
    assert main(["--simulate", *extra]) == 0
    assert seen["simulate"] is True and seen["command"] == "tui"
    key = extra[0].lstrip("-").replace("-", "_")
    assert str(seen[key]) == extra[1]


def test_help_and_version_are_still_benchlab_s(capsys: pytest.CaptureFixture[str]) -> None:
    with pytest.raises(SystemExit) as info:
        main(["--help"])
    assert info.value.code == 0 and "usage: benchlab" in capsys.readouterr().out


# ---- camera limits: one source of truth; what the camera applies is recorded ----------------
def test_params_use_the_driver_s_camera_limits() -> None:
    from benchlab.protocols.characterise import params as characterise_params

    assert characterise_params._EXPOSURE_RANGE_MS == params_mod.EXPOSURE_RANGE_MS
    assert characterise_params._GAIN_RANGE == params_mod.GAIN_RANGE
    spec = mightex_protocol.SPECS["MCE-B013-U"]
    assert params_mod.EXPOSURE_RANGE_MS == (mightex_protocol.EXPOSURE_STEP_MS,
                                            spec.exposure_max_ms)
    assert params_mod.GAIN_RANGE == (spec.gain_raw_min / 8, spec.gain_raw_max / 8) == (0.125, 8.0)
    assert params_mod.FRAME_SHAPE_PX == (spec.max_height, spec.max_width)


def _mtf_file(tmp_path: Path, camera: str) -> Path:
    text = (ROOT / "fixtures" / "params" / "mtf-small.toml").read_text()
    text = text.replace("exposure_ms = 300.0\ngain = 1.0", camera)
    assert camera in text
    path = tmp_path / "mtf.toml"
    path.write_text(text)
    return path


def test_exposure_and_gain_are_recorded_as_the_camera_applies_them(tmp_path: Path) -> None:
    p = load_params("mtf", _mtf_file(tmp_path, "exposure_ms = 300.03\ngain = 0.125"))
    assert p.exposure_ms == 300.05 and p.gain == 0.125  # 0.05 ms steps; gain 0.125 is valid
    long = load_params("mtf", _mtf_file(tmp_path, "exposure_ms = 750.0\ngain = 1.0"))
    assert long.exposure_ms == 750.0  # the MCE-B013-U's 2-byte exposure field (issue 31)
    with pytest.raises(params_mod.ParamsError, match=r"camera.exposure_ms: must be in \[0.05, "
                                                      r"750"):
        load_params("mtf", _mtf_file(tmp_path, "exposure_ms = 1000.0\ngain = 1.0"))


# ---- exit statuses are documented ------------------------------------------------------------
def test_readme_documents_exit_statuses() -> None:
    text = README.read_text(encoding="utf-8")
    folded = " ".join(text.split())
    assert "Exit status: 0 success, 1 runtime error, 2 usage error, 128 + signal" in folded


def test_report_out_creates_only_the_last_level(
    done_session: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    deep = tmp_path / "typo" / "reports" / "r.html"
    assert main(["report", str(done_session), "--out", str(deep)]) == 1
    assert capsys.readouterr().err.startswith("benchlab: error: ")
    assert not (tmp_path / "typo").exists()
    one = tmp_path / "reports" / "r.html"
    assert main(["report", str(done_session), "--out", str(one)]) == 0
    assert one.is_file()


@pytest.mark.parametrize(("argv", "says"), [
    (["simulate", "--time-scale", "0", "--for-s", "0.1"], "--time-scale: must be a finite"),
    (["simulate", "--channels", "0", "--for-s", "0.1"], "--channels: must be >= 1"),
    (["simulate", "--for-s", "nan"], "--for-s: must be a finite"),
    (["benchmark", "serial", "--repeat", "0"], "--repeat: must be >= 1"),
    (["benchmark", "camera", "--frames", "-3"], "--frames: must be >= 1"),
    (["benchmark", "report", "x", "--repeats", "0"], "--repeats: must be >= 1"),
    (["benchmark", "analysis", "--cases", "two"], "--cases: not a whole number: 'two'"),
    (["sfr", "x.tiff", "--roi", "0,0,9,9", "--bootstrap", "-1"], "--bootstrap: must be >= 0"),
])
def test_counts_and_scales_out_of_range_are_usage_errors(
    argv: list[str], says: str, capsys: pytest.CaptureFixture[str]
) -> None:
    """A count below 1 (or a bootstrap below 0, a time scale not above 0) is a usage error
    naming the option, exit 2, before anything runs - not a traceback or a negative fps."""
    with pytest.raises(SystemExit) as exc:
        main(argv)
    assert exc.value.code == 2
    err = capsys.readouterr().err
    assert says in err and "Traceback" not in err


def test_simulated_stage_start_outside_its_travel_is_a_usage_error(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["simulate", "--initial-position-mm", "999", "--for-s", "0.1"]) == 2
    assert "--initial-position-mm 999 is outside the travel 0 .. 50 mm" in capsys.readouterr().err
    assert main(["simulate", "--travel-mm", "5", "5", "--for-s", "0.1"]) == 2
    assert "LOW must be below HIGH" in capsys.readouterr().err
