"""The nominal chart's truth levels (the MTF session's ``simulator_truth``) read the centre and
the two spaces of a bar set in one array call (:meth:`UsafScene._profile_values`): the values
of the plain per-point evaluation it replaced, bit for bit (issue 39)."""

from __future__ import annotations

import dataclasses

import numpy as np

from benchlab.scenes.optics import BlurProfile, box_blurred_rect
from benchlab.scenes.usaf import UsafScene


def _profile_value(scene: UsafScene, bars, row: float, col: float) -> float:  # type: ignore[no-untyped-def]
    """A nominal chart's noise-free value (e-/ms) at one pixel centre, as the scene computed
    it point by point before issue 39."""
    assert scene.nominal
    sig_r, sig_c = scene.sigmas_px(bars)
    disc = scene._disc(np.array([row]), np.array([col]))[0]
    value = scene.bright_rate * disc
    r, c = np.array([row]), np.array([col])
    for top, left, bottom, right in bars.bars:
        fy = box_blurred_rect(r, top, bottom, sig_r)[0]
        fx = box_blurred_rect(c, left, right, sig_c)[0]
        value -= (scene.bright_rate - scene.dark_rate) * fy * fx
    return float(value)


def _plain_levels(scene: UsafScene, group: int, element: int, orientation: str
                  ) -> tuple[float, float]:
    """``truth_levels`` of a nominal chart as it was: three ``_profile_value`` calls."""
    bars = scene.bar_group(group, element, orientation)  # type: ignore[arg-type]
    cr, cc = bars.centre_rc
    w = bars.bar_width_px
    dark = _profile_value(scene, bars, cr, cc)
    if orientation == "sagittal":
        bright = 0.5 * (_profile_value(scene, bars, cr, cc - w)
                        + _profile_value(scene, bars, cr, cc + w))
    else:
        bright = 0.5 * (_profile_value(scene, bars, cr - w, cc)
                        + _profile_value(scene, bars, cr + w, cc))
    return dark, bright


def _scenes() -> list[UsafScene]:
    rng = np.random.default_rng(39)
    base = UsafScene()
    out = [base, dataclasses.replace(base, full_field=True)]
    for _ in range(8):
        blur = BlurProfile(image_height_mm=(0.0, 0.6, 1.2),
                           sigma_sagittal_px=tuple(float(v) for v in rng.uniform(0.1, 3, 3)),
                           sigma_tangential_px=tuple(float(v) for v in rng.uniform(0.1, 3, 3)))
        out.append(dataclasses.replace(
            base, blur=blur, defocus_px=float(rng.uniform(0, 4)),
            dark_dn8=float(rng.uniform(5, 60)), bright_dn8=float(rng.uniform(120, 250)),
            disc_edge_sigma_px=float(rng.uniform(0.5, 3))))
    return out


def test_truth_levels_are_the_per_point_values() -> None:
    for scene in _scenes():
        assert scene.nominal
        for g, e in scene.layout.elements:
            for o in ("sagittal", "tangential"):
                got = scene.truth_levels(g, e, o)  # type: ignore[arg-type]
                want = _plain_levels(scene, g, e, o)
                assert np.array(got).tobytes() == np.array(want).tobytes(), (g, e, o)


def test_profile_values_at_any_points_are_the_per_point_values() -> None:
    rng = np.random.default_rng(7)
    scene = _scenes()[3]
    for g, e in scene.layout.elements[::3]:
        bars = scene.bar_group(g, e, "tangential")
        cr, cc = bars.centre_rc
        rows = cr + rng.normal(0, 20, 17)
        cols = cc + rng.normal(0, 20, 17)
        got = scene._profile_values(bars, rows, cols)
        want = [_profile_value(scene, bars, float(r), float(c)) for r, c in zip(rows, cols,
                                                                            strict=True)]
        assert got.tobytes() == np.array(want).tobytes()
