"""The fit's 95 % intervals cover the truth about 95 % of the time: exact dot images plus
Gaussian centroid noise, many seeds (no rendering, so it is fast)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from benchlab.analysis.fov import figures as fig
from benchlab.analysis.fov.disc import Disc
from benchlab.analysis.fov.dots import Dots
from benchlab.analysis.fov.fit import fit_views
from benchlab.scenes.dots import DotChart, DotGridScene, FovLens

SEEDS = 40
NOISE_PX = 0.03


@pytest.mark.slow
@pytest.mark.parametrize("lens", [FovLens(), FovLens(barrel=0.0, tilt_deg=2.0,
                                                      entrance_pupil_mm=4.0)],
                         ids=["equidistant", "rectilinear-tilted"])
def test_intervals_cover_about_95_percent(lens: FovLens) -> None:
    scene = DotGridScene(chart=DotChart(half_count=9), lens=lens)
    exact = {d: scene.dot_centres(d) for d in (15.0, 30.0)}
    cr, cc = scene.circles.centre_rc
    h = lens.height_mm()
    true_h = float(h(np.array([math.radians(16.0)]))[0])
    hits = {"pupil": 0, "dov": 0, "h16": 0, "dist20": 0}
    t20 = math.radians(20.0)
    true_dist = 100.0 * (float(h(np.array([t20]))[0]) - lens.focal_length_mm * t20) / (
        lens.focal_length_mm * t20)
    rng = np.random.default_rng(7)
    for _ in range(SEEDS):
        views = []
        for d, (ij, xy) in exact.items():
            inside = np.hypot(xy[:, 0] - cc, xy[:, 1] - cr) < 235.0
            noisy = xy[inside] + rng.normal(0.0, NOISE_PX, xy[inside].shape)
            views.append((d, Dots(ij[inside].astype(np.int64), noisy, int(inside.sum()))))
        centre = np.array([cc, cr]) + rng.normal(0.0, 0.002, 2)
        disc = Disc(float(centre[0]), float(centre[1]), 250.0,
                    np.diag([0.002 ** 2, 0.002 ** 2, 0.01 ** 2]), 190.0, 0.0, 700)
        fit = fit_views(views, disc, 1.0)
        p = fig.entrance_pupil(fit)
        dov = fig.direction_of_view(fit)[0]
        h16 = fig.image_height(fit, 16.0)
        dist = fig.local_distortion(fit, 20.0, "equidistant")
        hits["pupil"] += p.low <= lens.entrance_pupil_mm <= p.high
        hits["dov"] += dov.low <= lens.tilt_deg <= dov.high
        hits["h16"] += h16.low <= true_h <= h16.high
        hits["dist20"] += dist.low <= true_dist <= dist.high
    coverage = {k: v / SEEDS for k, v in hits.items()}
    # 95 % less 2.7 binomial standard deviations over 40 seeds
    assert all(0.86 <= c <= 1.0 for c in coverage.values()), coverage
