"""The report's "measured vs simulated bar contrast" figure compares like with like, read from
the figure's own artists (not pixels): no simulated square-wave curve above 1, each legend
outside the data area and on no measured point, the measured points drawn above the curves."""

from __future__ import annotations

import math
from typing import Any

import matplotlib
import numpy as np
import pytest

matplotlib.use("Agg")
from matplotlib.collections import LineCollection  # noqa: E402
from matplotlib.figure import Figure  # noqa: E402
from matplotlib.lines import Line2D  # noqa: E402

import benchlab.report.mtf as report_mtf  # noqa: E402
from benchlab.analysis.mtf.coltman import mtf_to_ctf, signed_mtf  # noqa: E402
from benchlab.analysis.mtf.compare import SimulatedCurve  # noqa: E402
from benchlab.protocols.mtf.curves import load_curves  # noqa: E402

#: Table 4.11 / 4.12 of the thesis (image lp/mm, S and T modulation): points over the whole axis.
FORWARD = [(51.671, 0.82, 0.82), (58.028, 0.83, 0.80), (65.2, 0.78, 0.69), (73.187, 0.76, 0.69),
           (82.152, 0.61, 0.58), (92.258, 0.62, 0.46), (103.505, 0.35, 0.49),
           (116.219, 0.46, 0.40), (130.4, 0.38, 0.26)]
RADIAL = [(0.5, 8.75, 0.75, 0.38), (1, 17.5, 0.74, 0.38), (2, 35, 0.66, 0.18),
          (3, 52.5, 0.60, 0.0), (4, 70, 0.58, 0.0), (5, 87.5, 0.56, 0.0), (6, 105, 0.46, 0.0)]


def _tables() -> dict[str, list[dict[str, Any]]]:
    forward = [{"element": f"set{i}", "image_lp_per_mm": f, "sagittal_modulation": s,
                "tangential_modulation": t, "sagittal_uncertainty": 0.02,
                "tangential_uncertainty": 0.02} for i, (f, s, t) in enumerate(FORWARD)]
    radial = [{"object_lp_per_mm": o, "image_lp_per_mm": f, "sagittal_modulation": s,
               "tangential_modulation": t, "tangential_resolved": t > 0}
              for o, f, s, t in RADIAL]
    return {"table_4_11": forward, "table_4_12": radial,
            "table_4_13": [{"view": "forward", "nearest_field_deg": 0.0},
                           {"view": "radial", "nearest_field_deg": -30.0}]}


@pytest.fixture(scope="module")
def figure() -> Figure:
    captured: list[Figure] = []
    mp = pytest.MonkeyPatch()
    mp.setattr(report_mtf, "figure_img", lambda fig, alt: captured.append(fig) or "")
    try:
        report_mtf.ctf_figure(_tables(), load_curves(None))
    finally:
        mp.undo()
    (fig,) = captured
    fig.canvas.draw()  # legends and texts get their extents
    return fig


def _curves(ax: Any) -> list[Line2D]:
    return [ln for ln in ax.get_lines() if str(ln.get_label()).startswith("simulated CTF")]


def _points(ax: Any) -> list[Line2D]:
    """The measured markers (resolved, not resolved, aliased) of a panel."""
    return [ln for ln in ax.get_lines() if ln.get_marker() not in (None, "None", "")
            and ln.get_linestyle() in ("None", "none", "")]


@pytest.mark.slow
def test_no_simulated_square_wave_curve_exceeds_one(figure: Figure) -> None:
    curves = [ln for ax in figure.axes for ln in _curves(ax)]
    assert len(curves) == 16  # 4 forward + 4 radial field points, S and T each
    for ln in curves:
        y = np.asarray(ln.get_ydata(), dtype=float)
        assert y.max() <= 1.0, ln.get_label()
        assert y[0] > 0.99  # a square wave at low frequency: contrast ~1 (like the points)


def test_legends_are_outside_the_data_area_and_on_no_point(figure: Figure) -> None:
    renderer = figure.canvas.get_renderer()  # type: ignore[attr-defined]
    legends = [ax.get_legend() for ax in figure.axes]
    assert all(leg is not None for leg in legends)
    boxes = [leg.get_window_extent(renderer) for leg in legends]
    for ax in figure.axes:
        area = ax.get_window_extent(renderer)
        for box in boxes:
            assert not box.overlaps(area), "a legend on a panel's data area"
        for ln in _points(ax):
            xy = ax.transData.transform(np.column_stack([ln.get_xdata(), ln.get_ydata()]))
            for box in boxes:
                assert not any(box.contains(x, y) for x, y in xy)
    for a, b in zip(boxes, boxes[1:], strict=False):
        assert not a.overlaps(b)


def test_measured_points_are_drawn_above_the_curves(figure: Figure) -> None:
    for ax in figure.axes:
        points = _points(ax)
        assert points
        bars = [c for c in ax.collections if isinstance(c, LineCollection)]  # error bars
        top_curve = max(ln.get_zorder() for ln in _curves(ax))
        assert min(p.get_zorder() for p in [*points, *bars]) > top_curve


def _otf(f: Any) -> Any:
    """A uniform blur 12 um wide and a Gaussian one (a non-negative point spread): its OTF
    has negative lobes (zeros at 83.3, 166.7, ... lp/mm) and vanishes by 400 lp/mm."""
    fa = np.asarray(f, dtype=float)
    return np.sinc(0.012 * fa) * np.exp(-((fa / 150.0) ** 2))


def test_a_modulus_export_gets_its_contrast_reversals_back() -> None:
    f = np.arange(0.0, 400.0 + 1e-9, 2.0)
    otf = _otf(f)
    curve = SimulatedCurve("forward", 0.0, "S", f, np.abs(otf))  # as a design program exports
    signed = signed_mtf(f, curve.mtf)
    np.testing.assert_allclose(signed, otf, atol=0.02)  # each lobe's sign, 2 lp/mm samples
    assert (np.sign(signed[(f > 86) & (f < 165)]) == -1).all()
    grid = np.linspace(1.0, 120.0, 80)
    ctf = report_mtf.simulated_ctf(curve, grid)
    exact = mtf_to_ctf(_otf, grid, max_harmonic=2001)
    np.testing.assert_allclose(ctf, np.clip(exact, 0.0, 1.0), atol=0.01)
    # Coltman's series on the bare modulus would promise more than a square wave can give.
    modulus = mtf_to_ctf(lambda x: np.interp(x, f, curve.mtf, right=0.0), grid, 2001)
    assert modulus.max() > 1.05


def test_the_shipped_curves_need_no_clip_beyond_their_rounding() -> None:
    for curve in load_curves(None):
        grid = np.linspace(0.5, 130.0, 200)
        mtf_at, _ = report_mtf.extended_mtf(curve)
        raw = mtf_to_ctf(mtf_at, grid, max_harmonic=2001)
        assert raw.max() <= 1.0025, (curve.view, curve.direction, curve.field_angle_deg)
        assert math.isclose(float(report_mtf.simulated_ctf(curve, grid[:1])[0]), 1.0,
                            abs_tol=2e-3)
