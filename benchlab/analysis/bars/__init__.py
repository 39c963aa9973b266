"""Bar modulation (Eq. 2.9) of one ROI of a bar pattern, at any angle.

ROI preparation (:mod:`.roi`), projection across the bars (:mod:`.projection`), the bars'
direction, period and phase (:mod:`.geometry`), the imaged pattern in closed form (:mod:`.model`),
the estimators - histogram peaks (:mod:`.histogram`), profile fit (:mod:`.profilefit`), known
three-bar geometry (:mod:`.knownbars`) - their registry (:mod:`.estimators`), the result type
(:mod:`.result`) and the bootstrap interval (:mod:`.uncertainty`).

May import: numpy, scipy, :mod:`benchlab.analysis.mtf` and the analysis top-level helpers.
"""
