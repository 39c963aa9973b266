""":func:`benchlab.analysis.sfr.target.edge_spec` is :func:`edge_specs`' entry of that label,
computed alone (issue 39: the depth truth asks for one edge at many distances)."""

from __future__ import annotations

import numpy as np
import pytest

from benchlab.analysis.chart.pose import ChartPose
from benchlab.analysis.sfr.target import (
    DEFAULT_SQUARES,
    SlantedSquare,
    edge_spec,
    edge_specs,
    posed_squares,
    scaled_squares,
)
from benchlab.scenes.edge import EdgeScene
from benchlab.scenes.focus import DefocusedEdgeScene, ThroughFocusLens, edges_at, scenes_at
from benchlab.scenes.usaf import UsafScene
from benchlab.synthetic.edges import edge_truth_mtf


def _square_sets() -> list[tuple[SlantedSquare, ...]]:
    rng = np.random.default_rng(39)
    sets = [DEFAULT_SQUARES]
    for _ in range(40):
        sets.append(scaled_squares(float(rng.uniform(0.3, 3.0))))
        pose = ChartPose(scale=float(rng.uniform(0.5, 2.0)), rotation_deg=float(
            rng.uniform(-30, 30)), offset_rc=(float(rng.normal(0, 20)), float(rng.normal(0, 20))))
        sets.append(posed_squares(pose, (512.0, 640.0)))
    # two squares sharing a label: the first one's sides, as a scan of edge_specs finds them
    sets.append(DEFAULT_SQUARES + (SlantedSquare("E0", (100.0, 100.0), 40.0, 3.0),))
    return sets


def test_each_edge_alone_is_the_entry_of_all_edges() -> None:
    for squares in _square_sets():
        specs = edge_specs(squares)
        for label in {s.label for s in specs}:
            first = next(s for s in specs if s.label == label)
            assert edge_spec(label, squares) == first
    with pytest.raises(KeyError):
        edge_spec("E9R")


def test_the_defocused_target_and_its_truth_mtf_are_unchanged() -> None:
    lens = ThroughFocusLens()
    freqs = np.linspace(0.0, 0.5, 11)
    for z in (40.0, 60.0, 61.5, 95.0):
        alone = edges_at(lens, z, EdgeScene())
        assert alone == scenes_at(lens, z, UsafScene(), EdgeScene())[1]
        for e in alone.edges():
            want = DefocusedEdgeScene.side_sigma_px(alone, e.square, e.normal_theta_rad)
            got = alone.truth_mtf_at(e.label, freqs)
            assert got.tobytes() == edge_truth_mtf(freqs, want, e.normal_theta_rad).tobytes()
    with pytest.raises(KeyError, match="no edge"):
        edges_at(lens, 60.0, EdgeScene()).truth_mtf_at("E7B", freqs)
