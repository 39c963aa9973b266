"""Forward view: a slanted-edge target (dark squares turned a few degrees) with a known MTF.

Geometry from :mod:`benchlab.analysis.sfr.target`; blur from the forward
:class:`~benchlab.scenes.optics.BlurProfile` at the image height of each side's midpoint (as the
USAF scene blurs each bar set at its own height), Gaussian with the sagittal width along x and
the tangential width along y. Along a side's normal at angle ``t`` that blur is a Gaussian of
variance ``sag^2 cos^2 t + tan^2 sin^2 t`` (+ defocus^2), and the pixel aperture projects to
``sinc(f cos t) sinc(f sin t)``: the edge's truth MTF (:meth:`EdgeScene.truth_mtf`).

Render: a square is the product of two blurred strips (across each pair of opposite sides),
each integrated over the pixel in closed form
(:func:`benchlab.synthetic.edges.pixel_integrated_step`). Along a side, away from the
corners, one strip is exactly 1 over the whole pixel, so the image there is the exact
pixel-integrated blurred edge; only within a few blur widths of a corner is the product an
approximation - the measurement ROIs keep clear of the corners.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np
import numpy.typing as npt

from benchlab.analysis.arrays import FloatArray
from benchlab.analysis.chart.layout import IMAGE_CENTRE_RC, RadialLayout
from benchlab.analysis.sfr.target import DEFAULT_SQUARES, EdgeSpec, SlantedSquare, edge_specs
from benchlab.drivers.sensor import PIXEL_PITCH_UM, AcquisitionState
from benchlab.scenes.optics import FORWARD_BLUR, BlurProfile, saturated_ndtr
from benchlab.scenes.printed import TwoLevelPrint
from benchlab.synthetic.edges import edge_truth_mtf, pixel_integrated_step


@dataclass(frozen=True)
class EdgeScene(TwoLevelPrint):
    """The forward-view slanted-edge target.

    Parameters
    ----------
    squares
        The dark squares (default :data:`~benchlab.analysis.sfr.target.DEFAULT_SQUARES`).
    circles
        Dual-view circles; only the forward disc is lit (for the target on its own).
    optical_centre_rc
        Optical centre, for image heights.
    blur
        Forward-view blur widths over image height.
    dark_dn8, bright_dn8, reference_exposure_ms, reference_gain
        Levels of the chrome and the clear glass at the reference acquisition (those of
        :class:`~benchlab.scenes.usaf.UsafScene`: the same chart glass).
    disc_edge_sigma_px
        Softness of the disc edge.
    defocus_px
        Extra isotropic Gaussian blur; ``state.bench["defocus_px"]`` overrides it.
    """

    squares: tuple[SlantedSquare, ...] = DEFAULT_SQUARES
    circles: RadialLayout = field(default_factory=RadialLayout)
    optical_centre_rc: tuple[float, float] = IMAGE_CENTRE_RC
    blur: BlurProfile = FORWARD_BLUR
    dark_dn8: float = 20.0
    bright_dn8: float = 190.0
    reference_exposure_ms: float = 300.0
    reference_gain: float = 1.0
    disc_edge_sigma_px: float = 1.5
    defocus_px: float = 0.0


    def edges(self) -> list[EdgeSpec]:
        """Every side of every square as a slanted edge with its measurement ROI."""
        return edge_specs(self.squares)

    def image_height_mm(self, point_rc: tuple[float, float]) -> float:
        """Image height of a point (row, col), mm."""
        r, c = point_rc
        h_px = math.hypot(r - self.optical_centre_rc[0], c - self.optical_centre_rc[1])
        return h_px * PIXEL_PITCH_UM / 1000.0

    def side_sigma_px(self, square: SlantedSquare, theta_rad: float) -> float:
        """Gaussian blur width (px) across the side of ``square`` whose outward normal is at
        ``theta_rad``, at the image height of that side's midpoint."""
        half = square.side_px / 2.0
        mid = (square.centre_rc[0] + half * math.sin(theta_rad),
               square.centre_rc[1] + half * math.cos(theta_rad))
        h = self.image_height_mm(mid)
        sag = float(self.blur.sagittal_px(h))
        tan = float(self.blur.tangential_px(h))
        c, s = math.cos(theta_rad), math.sin(theta_rad)
        return math.sqrt(sag * sag * c * c + tan * tan * s * s + self.defocus_px**2)

    def truth_mtf(self, edge: EdgeSpec, freqs_cycles_per_px: npt.ArrayLike) -> FloatArray:
        """Analytic MTF along an edge's normal: its Gaussian blur times the pixel aperture."""
        sigma = self.side_sigma_px(edge.square, edge.normal_theta_rad)
        return edge_truth_mtf(freqs_cycles_per_px, sigma, edge.normal_theta_rad)

    def __call__(self, state: AcquisitionState) -> FloatArray:
        """Electron-rate image (e-/ms) of the target alone in the forward disc (a fresh copy)."""
        scene = self._for_state(state)
        return _render(scene, state.height, state.width).copy()

    def darkening(self, state: AcquisitionState) -> FloatArray:
        """What the squares take away from a bright ground (e-/ms), read-only: composed with
        the USAF chart by :class:`~benchlab.scenes.world.SimWorld`."""
        return _darkening(self._for_state(state), state.height, state.width)

    def render(self, height: int, width: int) -> FloatArray:
        """The cached, read-only electron-rate image of a ``height x width`` frame."""
        return _render(self, height, width)

    def _for_state(self, state: AcquisitionState) -> EdgeScene:
        defocus = (state.bench or {}).get("defocus_px")
        if defocus is not None and abs(float(defocus)) != self.defocus_px:
            return dataclasses.replace(self, defocus_px=abs(float(defocus)))
        return self


def _strip(
    s: FloatArray, half: float, sigma_minus: float, sigma_plus: float, c: float, sn: float
) -> FloatArray:
    """Pixel-integrated blurred indicator of ``|s| <= half`` (``s`` along a unit direction
    with cosines ``c, sn`` to the pixel axes), each side blurred by its own width."""
    return pixel_integrated_step(s + half, sigma_minus, c, sn) - pixel_integrated_step(
        s - half, sigma_plus, c, sn
    )


@functools.lru_cache(maxsize=8)
def _darkening(scene: EdgeScene, height: int, width: int) -> FloatArray:
    out = np.zeros((height, width))
    depth = scene.bright_rate - scene.dark_rate
    for sq in scene.squares:
        half = sq.side_px / 2.0
        phi = math.radians(sq.rotation_deg)
        c, s = math.cos(phi), math.sin(phi)
        # Outward normals of the R, L, B, T sides: phi, phi + 180, phi + 90, phi + 270 deg.
        sig_r, sig_l = scene.side_sigma_px(sq, phi), scene.side_sigma_px(sq, phi + math.pi)
        sig_b = scene.side_sigma_px(sq, phi + math.pi / 2.0)
        sig_t = scene.side_sigma_px(sq, phi - math.pi / 2.0)
        reach = half * (abs(c) + abs(s)) + 6.0 * max(sig_r, sig_l, sig_b, sig_t) + 2.0
        r0 = max(int(math.floor(sq.centre_rc[0] - reach)), 0)
        r1 = min(int(math.ceil(sq.centre_rc[0] + reach)) + 1, height)
        c0 = max(int(math.floor(sq.centre_rc[1] - reach)), 0)
        c1 = min(int(math.ceil(sq.centre_rc[1] + reach)) + 1, width)
        if r0 >= r1 or c0 >= c1:
            continue
        y = np.arange(r0, r1, dtype=np.float64)[:, None] - sq.centre_rc[0]
        x = np.arange(c0, c1, dtype=np.float64)[None, :] - sq.centre_rc[1]
        s1 = x * c + y * s  # along the first normal (R/L sides)
        s2 = -x * s + y * c  # along the second normal (B/T sides)
        e1 = _strip(s1, half, sig_l, sig_r, c, s)
        e2 = _strip(s2, half, sig_t, sig_b, s, c)
        out[r0:r1, c0:c1] += depth * e1 * e2
    out.setflags(write=False)
    return out


@functools.lru_cache(maxsize=8)
def _render(scene: EdgeScene, height: int, width: int) -> FloatArray:
    rows = np.arange(height, dtype=np.float64)[:, None]
    cols = np.arange(width, dtype=np.float64)[None, :]
    cr, cc = scene.circles.centre_rc
    radius = np.hypot(rows - cr, cols - cc)
    edge = math.hypot(scene.disc_edge_sigma_px, scene.defocus_px)
    disc = saturated_ndtr((scene.circles.disc_radius_px - radius) / edge)
    img = scene.bright_rate * disc - _darkening(scene, height, width)
    np.maximum(img, 0.0, out=img)
    img.setflags(write=False)
    return img
