"""``benchlab benchmark chart --whole``: the whole-chart finder over scales, rotations and JPEG.

Each trial renders the whole USAF 1951 chart (:mod:`benchlab.analysis.chart.whole_layout`,
groups -2 to 7) onto a 600 x 800 frame (:func:`benchlab.scenes.usaf.render_chart_image`): the
scale of a microscope's view of groups 4-7 (magnification 0.25) times a factor log-uniform in
0.2-10, any rotation, the chart centre up to 150 px off the frame centre, blur 0.5-1.5 px,
noise 0.5-2 % of full scale, positive or negative, 8-bit, half of the frames through JPEG
(quality 75-95). The finder (:func:`benchlab.analysis.chart.whole.find_whole_chart`) gets the
true magnification times a factor in 0.77-1.3 as its hint. Scored:

- frames with fewer than :data:`MIN_SETS_IN_VIEW` scored sets in view (the chart mostly off
  the frame at the largest scales) are counted, not scored;
- **found**: a chart found at all; **magnification**: the implied one within 1 % of the truth;
- **groups**: the groups named (``groups_found``) are those of the correctly placed sets;
- **sets**: of the sets wholly in the frame with at least 3 px per period and bars at least
  1.5 px wide, the share found with their centre within half a bar width of the truth
  (correctly labelled), and the found sets placed elsewhere (wrongly labelled);
- **time** of the finder per frame.
"""

from __future__ import annotations

import io
import math
import statistics
import time
from typing import Any

import numpy as np

from benchlab.analysis.chart.finder import ChartNotFoundError
from benchlab.analysis.chart.pose import ChartPose, posed_bar_set
from benchlab.analysis.chart.whole import find_whole_chart
from benchlab.analysis.chart.whole_layout import whole_chart_layout
from benchlab.scenes.usaf import render_chart_image

SHAPE = (600, 800)
MICROSCOPE_MAGNIFICATION = 0.25
SCALE_FACTORS = (0.2, 10.0)
HINT_FACTORS = (0.77, 1.3)
#: Sets scored: at least this many px per period and this bar width, wholly in the frame.
MIN_PX_PER_PERIOD = 3.0
MIN_BAR_PX = 1.5
#: Frames with fewer such sets in view (most of the chart off the frame) are not scored.
MIN_SETS_IN_VIEW = 3


def run_whole_chart_benchmark(frames: int = 40, seed: int = 0) -> dict[str, Any]:
    """Score the whole-chart finder on ``frames`` random frames (see the module docstring)."""
    from PIL import Image

    rng = np.random.default_rng(seed)
    found = mag_ok = groups_ok = imaged = correct = wrong = sparse = sparse_found = 0
    times: list[float] = []
    for _ in range(frames):
        scale = math.exp(rng.uniform(*np.log(SCALE_FACTORS)))
        m_true = MICROSCOPE_MAGNIFICATION / scale
        rot = float(rng.uniform(-180.0, 180.0))
        off = (float(rng.uniform(-150, 150)), float(rng.uniform(-150, 150)))
        origin = ((SHAPE[0] - 1) / 2.0, (SHAPE[1] - 1) / 2.0)
        lay = whole_chart_layout(m_true, origin_rc=origin)
        pose = ChartPose(off, 1.0, rot)
        img = render_chart_image(lay, pose, *SHAPE, blur_px=float(rng.uniform(0.5, 1.5)))
        if rng.random() < 0.5:
            img = 1.0 - img
        img = img + rng.normal(0.0, float(rng.uniform(0.005, 0.02)), img.shape)
        px = np.clip(np.round(img * 255), 0, 255).astype(np.uint8)
        if rng.random() < 0.5:
            buf = io.BytesIO()
            Image.fromarray(px).save(buf, format="JPEG", quality=int(rng.integers(75, 96)))
            buf.seek(0)
            px = np.asarray(Image.open(buf))
        truth = {}
        for g, e in lay.elements:
            for o in ("sagittal", "tangential"):
                t = posed_bar_set(lay, pose, g, e, o)  # type: ignore[arg-type]
                inside = all(0 <= r <= SHAPE[0] - 1 and 0 <= c <= SHAPE[1] - 1
                             for r, c in t.corners())
                truth[t.label] = (t, inside and t.px_per_period >= MIN_PX_PER_PERIOD
                                  and t.bar_width_px >= MIN_BAR_PX)
        n_imaged = sum(1 for _, ok in truth.values() if ok)
        hint = m_true * float(rng.uniform(*HINT_FACTORS))
        t0 = time.process_time()
        try:
            fit = find_whole_chart(px, hint)
        except ChartNotFoundError:
            fit = None
        times.append(time.process_time() - t0)
        if n_imaged < MIN_SETS_IN_VIEW:  # too little of the chart in view to score
            sparse += 1
            sparse_found += fit is not None
            continue
        imaged += n_imaged
        if fit is None:
            continue
        found += 1
        mag_ok += abs(fit.implied_magnification / m_true - 1.0) <= 0.01
        good_groups = set()
        for el in fit.found:
            t, scored = truth[el.label]
            d = math.hypot(el.posed.centre_rc[0] - t.centre_rc[0],
                           el.posed.centre_rc[1] - t.centre_rc[1])
            if d <= 0.5 * t.bar_width_px:
                good_groups.add(t.group)
                correct += scored
            else:
                wrong += 1
        groups_ok += set(fit.groups_found) == good_groups and bool(good_groups)
    return {"frames": frames, "seed": seed, "scored": frames - sparse, "sparse": sparse,
            "sparse_found": sparse_found, "found": found, "magnification_ok": mag_ok,
            "groups_ok": groups_ok, "imaged_sets": imaged, "correct_sets": correct,
            "wrong_sets": wrong,
            "time_median_s": statistics.median(times) if times else float("nan"),
            "time_max_s": max(times) if times else float("nan")}


def format_whole_chart_benchmark(s: dict[str, Any]) -> str:
    """The benchmark's summary as text."""
    n = max(s["scored"], 1)
    share = 100.0 * s["correct_sets"] / max(s["imaged_sets"], 1)
    return "\n".join([
        f"whole chart, {s['frames']} frames (seed {s['seed']}): scale 0.2-10x of a microscope's "
        "groups 4-7, any rotation, half JPEG, hint within 0.77-1.3x",
        f"scored frames         {s['scored']} ({s['sparse']} with < {MIN_SETS_IN_VIEW} sets in "
        f"view not scored; a chart found in {s['sparse_found']} of them)",
        f"chart found           {s['found']}/{s['scored']} ({100 * s['found'] / n:.0f} %)",
        f"magnification +-1 %   {s['magnification_ok']}/{s['scored']}",
        f"groups named right    {s['groups_ok']}/{s['scored']}",
        f"sets found, labelled  {s['correct_sets']}/{s['imaged_sets']} ({share:.1f} %) of the "
        f"sets in the frame with >= {MIN_PX_PER_PERIOD:g} px per period",
        f"sets misplaced        {s['wrong_sets']}",
        f"finder CPU time       median {s['time_median_s']:.2f} s, max {s['time_max_s']:.2f} s",
    ])
