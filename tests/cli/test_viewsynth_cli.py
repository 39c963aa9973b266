"""benchlab unwrap / perspective / viewpoint / calibrate radial on files and on a session, the
ring self-calibration, and the report's unwrapped section."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import tifffile
from sim_runs import MTF_SMALL, run_sim

from benchlab.analysis.views.calibrate import calibrate_from_rings, compare_tables
from benchlab.analysis.views.raytrace import read_raytrace_table
from benchlab.analysis.views.synthesis import fov_centre_of_frame
from benchlab.benchmarks.viewsynth import _render, expose_dn8
from benchlab.cli.main import main
from benchlab.protocols import RunOutcome
from benchlab.radial_views import load_view_tiff
from benchlab.scenes.card import CardScene
from benchlab.scenes.radial import RadialScene
from benchlab.session import Session, read_results
from benchlab.storage import save_frame_tiff, sha256_file

TABLE = read_raytrace_table()


@pytest.fixture(scope="module")
def frames(tmp_path_factory: pytest.TempPathFactory) -> dict[str, Path]:
    root = tmp_path_factory.mktemp("frames")
    out = {}
    for name, scene, seed in (("card", CardScene(), 1),
                              ("rings", RadialScene(1.0, "tangential"), 2)):
        path = root / f"{name}.tiff"
        save_frame_tiff(path, expose_dn8(_render(scene), seed), {"note": name})
        out[name] = path
    return out


@pytest.mark.slow
def test_unwrap_frame_writes_view_mask_and_mapping(frames: dict[str, Path], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    src = frames["card"]
    before = sha256_file(src)
    out = tmp_path / "u.tiff"
    assert main(["unwrap", str(src), "--out", str(out), "--px-per-mm", "10",
                 "--azimuth-deg=-90:90", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    view, valid, meta = load_view_tiff(out)
    assert view.dtype == np.uint8 and view.shape == valid.shape
    assert view.shape[1] == round(np.pi * 19.88 * 10)
    assert meta["table_sha256"] == TABLE.sha256 and meta["object_radius_mm"] == 19.88
    assert meta["px_per_mm"] == 10 and meta["azimuth_deg"] == [-90, 90]
    assert meta["centre_rc"] == pytest.approx([560.5, 646.0], abs=0.5)
    assert meta["source_sha256"] == before == sha256_file(src)  # the frame is untouched
    assert info["out"] == str(out) and not info["extrapolated"]
    with tifffile.TiffFile(out) as tif:
        assert len(tif.pages) == 2
    # the same output again is refused unless --overwrite
    assert main(["unwrap", str(src), "--out", str(out)]) == 2  # a usage error (issue 38)
    assert f"--out {out}: already exists" in capsys.readouterr().err
    assert main(["unwrap", str(src), "--out", str(out), "--overwrite"]) == 0


def test_unwrap_errors_name_the_problem(frames: dict[str, Path], tmp_path: Path,
                                        capsys: pytest.CaptureFixture[str]) -> None:
    src = str(frames["card"])
    cases = [
        (["unwrap", src, "--depth-mm", "30", "--out", str(tmp_path / "a.tiff")],
         "outside the table's 15.88-24.88 mm"),
        (["unwrap", src, "--centre", "12", "--out", str(tmp_path / "b.tiff")], "--centre '12'"),
        (["unwrap", src, "--azimuth-deg", "90:10"], "need 0 < END - START <= 360"),
        (["unwrap", str(tmp_path / "none.tiff")], "none.tiff: no such frame file"),
        (["unwrap", src, "--out", src, "--force"], "is the input frame"),
        (["unwrap", src, "--table", str(tmp_path / "t.csv")], "t.csv: cannot read"),
    ]
    for argv, message in cases:
        assert main(argv) == 1, argv
        err = capsys.readouterr().err
        assert err.startswith("benchlab: error:") and message in err, err
    assert not (tmp_path / "a.tiff").exists() and not (tmp_path / "b.tiff").exists()
    with pytest.raises(SystemExit) as exc:  # usage error: exit 2
        main(["perspective", src, "--out", str(tmp_path / "p.tiff")])
    assert exc.value.code == 2


def test_extrapolated_depth_is_flagged(frames: dict[str, Path], tmp_path: Path,
                                       capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "x.tiff"
    assert main(["unwrap", str(frames["card"]), "--depth-mm", "26", "--allow-extrapolation",
                 "--px-per-mm", "5", "--out", str(out)]) == 0
    assert "EXTRAPOLATED" in capsys.readouterr().out
    assert load_view_tiff(out)[2]["extrapolated"] is True


def test_perspective_and_viewpoint_commands(frames: dict[str, Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "p.tiff"
    assert main(["perspective", str(frames["card"]), "--yaw-deg", "-40", "--pitch-deg", "45",
                 "--fov-deg", "90", "--size", "160x120", "--out", str(out)]) == 0
    view, valid, meta = load_view_tiff(out)
    assert view.shape == (120, 160) and meta["viewpoint_z_mm"] == pytest.approx(-6.4, abs=0.01)
    assert 0.2 < valid.mean() < 1.0
    capsys.readouterr()
    assert main(["viewpoint", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["svp_spread_um"] < 20 and info["effective_viewpoint_z_mm"] == pytest.approx(
        -6.4, abs=0.01)
    assert any(r["curved"] for r in info["rows"]) and not all(r["curved"] for r in info["rows"])
    assert main(["viewpoint"]) == 0
    text = capsys.readouterr().out
    assert "effective viewpoint z = -6.399" in text and "SVP spread 16." in text


@pytest.mark.slow
def test_ring_calibration_recovers_the_table(frames: dict[str, Path], tmp_path: Path,
                                            capsys: pytest.CaptureFixture[str]) -> None:
    pixels = tifffile.imread(frames["rings"])
    centre, _ = fov_centre_of_frame(pixels)
    cal = calibrate_from_rings(pixels, object_lp_per_mm=1.0, object_radius_mm=19.88,
                               centre_rc=centre)
    assert cal.ring_radius_mm.size >= 18
    cmp = compare_tables(cal.table, TABLE, 19.88, 2.4826)
    assert cmp["rms_axial_um"] < 10 and abs(cmp["magnification_error_pct"]) < 0.5
    # the figure can fail: the wrong frequency is a 2x magnification error
    wrong = calibrate_from_rings(pixels, object_lp_per_mm=0.5, object_radius_mm=19.88,
                                 centre_rc=centre)
    assert compare_tables(wrong.table, TABLE, 19.88)["magnification_error_pct"] == pytest.approx(
        100.0, rel=0.02)
    with pytest.raises(ValueError, match="dark rings"):
        calibrate_from_rings(np.zeros_like(pixels) + 100, object_lp_per_mm=1.0,
                             object_radius_mm=19.88, centre_rc=centre)
    with pytest.raises(ValueError, match="beyond the side wall"):
        calibrate_from_rings(pixels, object_lp_per_mm=1.0, object_radius_mm=10.0,
                             centre_rc=centre)
    # CLI: writes a table unwrap accepts at that depth, and says how far it is from the shipped
    table_csv = tmp_path / "cal.csv"
    assert main(["calibrate", "radial", str(frames["rings"]), "--object-lp-per-mm", "1",
                 "--depth-mm", "19.88", "--out", str(table_csv), "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["comparison"]["rms_axial_um"] < 10
    assert "SELF-CALIBRATED" in table_csv.read_text()
    out = tmp_path / "u.tiff"
    assert main(["unwrap", str(frames["card"]), "--table", str(table_csv), "--px-per-mm", "5",
                 "--out", str(out)]) == 0
    assert load_view_tiff(out)[1].mean() > 0.5
    assert main(["unwrap", str(frames["card"]), "--table", str(table_csv), "--depth-mm", "21",
                 "--out", str(tmp_path / "v.tiff")]) == 1
    assert "one depth" in capsys.readouterr().err


@pytest.fixture(scope="module")
def mtf_run(tmp_path_factory: pytest.TempPathFactory) -> RunOutcome:
    return run_sim("mtf", tmp_path_factory.mktemp("mtf"), MTF_SMALL)


@pytest.mark.slow
def test_unwrap_session_adds_a_results_version_frames_untouched(
        mtf_run: RunOutcome, capsys: pytest.CaptureFixture[str]) -> None:
    session = Session.open(mtf_run.session_path)
    before_versions = session.result_versions()
    before_frames = session.frames()
    prev_tables, _ = read_results(session.latest_results())  # type: ignore[arg-type]
    assert main(["unwrap", str(session.path), "--px-per-mm", "6", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    session = Session.open(mtf_run.session_path)
    assert session.result_versions() == [*before_versions, before_versions[-1] + 1]
    assert session.verify_frames() == [] and session.frames() == before_frames
    tables, doc = read_results(session.latest_results())  # type: ignore[arg-type]
    radial_frames = [f for f in before_frames if "radial" in f]
    assert len(tables["unwrap"]) == len(radial_frames) == len(info["unwrap"]) > 0
    for name, rows in prev_tables.items():  # the version stays a complete snapshot
        assert tables[name] == rows
    assert doc["summary"]["unwrap"]["table_sha256"] == TABLE.sha256
    first = session.latest_results() / tables["unwrap"][0]["file"]  # type: ignore[operator]
    view, valid, meta = load_view_tiff(first)
    assert meta["source"].startswith("frames/") and valid.mean() > 0.5
    assert len(tables["viewpoint"]) > 10
    # the report shows them
    from benchlab.report.render import render_report

    page = render_report(session.path)
    assert "Unwrapped radial view" in page and "Effective viewpoint" in page
    assert page.count("data:image/png") >= len(radial_frames) + 1


def test_no_centre_and_no_radial_frames_are_clear_errors(
        tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    dark = tmp_path / "dark.tiff"
    save_frame_tiff(dark, np.zeros((1024, 1280), np.uint8), {})
    assert main(["unwrap", str(dark)]) == 1
    assert "cannot find the optical centre" in capsys.readouterr().err
    assert main(["unwrap", str(dark), "--centre", "560.5,646", "--px-per-mm", "4"]) == 0
    session = Session.create(tmp_path / "s", procedure="mtf", params={}, operator="t",
                             devices={}, software_version="test")
    session.save_frame("forward", "forward", np.zeros((64, 64), np.uint8),
                       {"bench": {"target": "usaf"}})
    assert main(["unwrap", str(session.path)]) == 1  # the writer still holds it
    assert "session is in use by" in capsys.readouterr().err
    session.release()
    assert main(["unwrap", str(session.path)]) == 1
    assert "no radial frames to unwrap" in capsys.readouterr().err
    assert Session.open(session.path).result_versions() == []
    assert main(["unwrap", str(tmp_path)]) == 1  # a folder that is not a session
    assert "not a session" in capsys.readouterr().err


def test_unwrap_of_a_session_frame_never_writes_into_its_frames_folder(
        mtf_run: RunOutcome, tmp_path: Path, monkeypatch: pytest.MonkeyPatch,
        capsys: pytest.CaptureFixture[str]) -> None:
    session = Session.open(mtf_run.session_path)
    frames_dir = session.path / "frames"
    before = sorted(p.name for p in frames_dir.iterdir())
    src = next(p for p in sorted(frames_dir.glob("*radial*.tiff")))
    monkeypatch.chdir(tmp_path)
    # Default --out: the current folder, not beside the raw frame.
    assert main(["unwrap", str(src), "--px-per-mm", "4", "--json"]) == 0
    info = json.loads(capsys.readouterr().out)
    assert info["out"] == f"{src.stem}.unwrap.tiff" and (tmp_path / info["out"]).is_file()
    # An explicit --out into frames/ is refused, naming it; nothing written.
    bad = frames_dir / "view.tiff"
    assert main(["unwrap", str(src), "--px-per-mm", "4", "--out", str(bad)]) == 2
    err = capsys.readouterr().err
    assert err.startswith(f"benchlab: error: --out {bad}: is part of frames/ of session")
    assert main(["perspective", str(src), "--yaw-deg", "0", "--pitch-deg", "45", "--fov-deg",
                 "60", "--size", "40x30", "--out", str(bad), "--force"]) == 2
    assert "is part of frames/ of session" in capsys.readouterr().err
    assert sorted(p.name for p in frames_dir.iterdir()) == before
    assert Session.open(mtf_run.session_path).verify_frames() == []


def test_rgb_tiff_is_read_as_colour_not_as_a_stack(frames: dict[str, Path], tmp_path: Path,
                                                   capsys: pytest.CaptureFixture[str]) -> None:
    mono = tifffile.imread(frames["card"])
    grey, colour = tmp_path / "grey.tiff", tmp_path / "colour.tiff"
    tifffile.imwrite(grey, np.stack([mono] * 3, -1), photometric="rgb")
    tinted = np.stack([mono, mono // 2, mono], -1)
    tifffile.imwrite(colour, tinted, photometric="rgb")
    planar = tmp_path / "planar.tiff"  # RGB stored as separate colour planes: (3, rows, cols)
    tifffile.imwrite(planar, np.stack([mono] * 3), photometric="rgb", planarconfig="separate")
    args = ["--px-per-mm", "4", "--centre", "560.5,646"]
    assert main(["unwrap", str(frames["card"]), *args, "--out", str(tmp_path / "m.tiff")]) == 0
    # Before: the RGB frame was averaged over its rows into a 1280x3 "frame", a blank view.
    assert main(["unwrap", str(grey), *args, "--out", str(tmp_path / "g.tiff")]) == 0
    view_m, valid_m, _ = load_view_tiff(tmp_path / "m.tiff")
    view_g, valid_g, _ = load_view_tiff(tmp_path / "g.tiff")
    assert np.array_equal(view_g, view_m) and valid_g.mean() > 0.9 and view_g.max() > 100
    assert main(["unwrap", str(planar), *args, "--out", str(tmp_path / "p.tiff")]) == 0
    assert np.array_equal(load_view_tiff(tmp_path / "p.tiff")[0], view_m)
    capsys.readouterr()
    assert main(["unwrap", str(colour), *args, "--out", str(tmp_path / "c.tiff")]) == 1
    assert f"{colour}: colour image" in capsys.readouterr().err
    assert not (tmp_path / "c.tiff").exists()
    # A TIFF stack of 3 frames stays a stack (averaged), not colour.
    stack = tmp_path / "stack.tiff"
    tifffile.imwrite(stack, np.stack([mono] * 3), photometric="minisblack")
    assert main(["unwrap", str(stack), *args, "--out", str(tmp_path / "s.tiff")]) == 0
    view_s = load_view_tiff(tmp_path / "s.tiff")[0]  # float32: the stack's mean
    assert view_s.dtype == np.float32 and np.abs(view_s - view_m).max() <= 0.5


def test_a_view_with_no_valid_pixel_is_refused(frames: dict[str, Path], tmp_path: Path,
                                               capsys: pytest.CaptureFixture[str]) -> None:
    out = tmp_path / "far.tiff"
    assert main(["unwrap", str(frames["card"]), "--centre", "5000,5000", "--px-per-mm", "4",
                 "--out", str(out)]) == 1
    assert "(0 % valid)" in capsys.readouterr().err and not out.exists()
