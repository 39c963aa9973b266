"""The report's radiometry overlay is the analysis mask: drawn on the image the reading
averaged (linearised by the session's response calibration when it has one) and computed on
that same image - never a mask of the raw codes over a linearised reading."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from sim_runs import RAD_SMALL

from benchlab.bench import BenchConfig
from benchlab.calibration import FORMAT, set_camera_reference
from benchlab.cli.main import main
from benchlab.protocols.radiometry import reading_mask_of
from benchlab.report.render import radiometry_overlays, render_report, report_context


def _nonlinear_bench(folder: Path) -> Path:
    """A bench file whose response calibration is far from linear (codes 100 -> 150)."""
    (folder / "calibration").mkdir(parents=True)
    (folder / "calibration" / "response-v1.json").write_text(json.dumps({
        "format": FORMAT, "version": 1, "curves": [
            {"gain": 1.0, "bits": 8, "black_level_dn": 0.0,
             "measured_dn": [0.0, 10.0, 100.0, 255.0], "linear_dn": [0.0, 4.0, 150.0, 400.0]}]}))
    text = Path(str(BenchConfig.load(None, simulate=True).source)).read_text()
    bench = folder / "bench.toml"
    bench.write_text(set_camera_reference(text, "calibration/response-v1.json"))
    return bench


@pytest.fixture(scope="module")
def linearised_session(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("lin")
    bench = _nonlinear_bench(folder)
    assert main(["run", "radiometry", "--simulate", "--config", str(bench), "--yes",
                 "--params", str(RAD_SMALL), "--out", str(folder / "s")]) == 0
    (session,) = (folder / "s").glob("*_radiometry")
    return session


@pytest.mark.slow
def test_overlay_mask_is_the_analysis_mask(linearised_session: Path) -> None:
    ctx = report_context(linearised_session)
    assert ctx.summary["linearised"] is not None
    rows = {r["position_mm"]: r for r in ctx.tables["table_4_16"]}
    overlays = radiometry_overlays(ctx)
    assert [o.position_mm for o in overlays] == [15.0, 18.0, 25.0]
    raw_differs = 0
    for o in overlays:
        assert o.linearised
        # the analysis's own number of mask pixels, and the mask it averaged
        assert int(o.mask.sum()) == rows[o.position_mm]["mask_pixels"]
        sid = f"position-{o.position_mm:g}"
        mask_f, _ = ctx.session.load_frame(sid, "mask")
        meas_f, _ = ctx.session.load_frame(sid, "measurement")
        assert np.array_equal(o.mask, reading_mask_of(mask_f, o.image, 0.5))
        assert not np.array_equal(o.image, meas_f)  # the linearised image, not the codes
        raw = reading_mask_of(mask_f, meas_f, 0.5)
        raw_differs += int(not np.array_equal(raw, o.mask))
    assert raw_differs > 0  # the curve moves the mask: a raw-code overlay would be wrong
    page = render_report(linearised_session)
    assert "linearised with the response calibration" in page


@pytest.mark.slow
def test_overlay_of_an_uncalibrated_session_says_raw_codes(tmp_path: Path) -> None:
    assert main(["run", "radiometry", "--simulate", "--yes", "--params", str(RAD_SMALL),
                 "--out", str(tmp_path / "s")]) == 0
    (session,) = (tmp_path / "s").glob("*_radiometry")
    ctx = report_context(session)
    rows = {r["position_mm"]: r for r in ctx.tables["table_4_16"]}
    overlays = radiometry_overlays(ctx)
    assert len(overlays) == 3
    for o in overlays:
        assert not o.linearised
        assert int(o.mask.sum()) == rows[o.position_mm]["mask_pixels"]
        meas_f, _ = ctx.session.load_frame(f"position-{o.position_mm:g}", "measurement")
        assert np.array_equal(o.image, meas_f)
    assert "raw camera codes" in render_report(session)


def test_masks_are_not_drawn_when_the_calibration_cannot_be_rebuilt(
        linearised_session: Path, tmp_path: Path) -> None:
    """The session's calibration copy changed: no mask of another image is drawn; the
    section says why."""
    import shutil

    copy = tmp_path / "copy"
    shutil.copytree(linearised_session, copy)
    curve = copy / "calibration" / "response-v1.json"
    curve.write_text(curve.read_text().replace("150.0", "151.0"))
    page = render_report(copy)
    assert "LED masks not drawn" in page and "response-v1.json" in page
