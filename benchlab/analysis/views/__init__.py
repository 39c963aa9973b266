"""The radial view: its ray-trace table (:mod:`.raytrace`), unwrapped and perspective views
(:mod:`.synthesis`), self-calibration from a ring target (:mod:`.calibrate`) and the metrics
of a synthesized view against a flat truth (:mod:`.metrics`).

May import: numpy, scipy, OpenCV and the analysis top-level helpers.
"""
