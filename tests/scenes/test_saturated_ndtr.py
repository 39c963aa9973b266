"""The field stop's rim is rendered with ``ndtr`` evaluated only where it is neither 0 nor 1,
bit for bit the full-frame ``ndtr``: a simulated frame is the same frame, cheaper."""

from __future__ import annotations

import math

import numpy as np
from scipy.special import ndtr

from benchlab.scenes.optics import NDTR_ONE_Z, NDTR_ZERO_Z, saturated_ndtr
from benchlab.scenes.usaf import UsafScene


def test_saturated_ndtr_is_ndtr_bit_for_bit() -> None:
    z = np.concatenate([np.linspace(-1e3, 1e3, 200_001), np.linspace(-45, 12, 100_003),
                        [NDTR_ONE_Z, NDTR_ZERO_Z, 8.3, -38.5, -0.0, np.inf, -np.inf, np.nan]])
    assert saturated_ndtr(z).tobytes() == ndtr(z).tobytes()
    grid = z[:600].reshape(20, 30)
    assert saturated_ndtr(grid).tobytes() == ndtr(grid).tobytes()


def test_the_chart_disc_is_the_full_frame_ndtr() -> None:
    scene = UsafScene()
    rows = np.arange(1024, dtype=np.float64)[:, None]
    cols = np.arange(1280, dtype=np.float64)[None, :]
    cr, cc = scene.circles.centre_rc
    edge = math.hypot(scene.disc_edge_sigma_px, scene.defocus_px)
    full = ndtr((scene.circles.disc_radius_px - np.hypot(rows - cr, cols - cc)) / edge)
    disc = scene._disc(rows, cols)
    assert disc.tobytes() == full.tobytes()
    # the rim is a small part of the frame: most of it is exactly 0 or 1
    assert ((full == 0.0) | (full == 1.0)).mean() > 0.5
