"""Field of view, direction of view, entrance pupil and image-height mapping of the forward
view, from a dot-grid chart imaged at two or more object distances (issue 41; thesis Tables
3.1 and 4.14; ISO 8600-3).

Modules: :mod:`.model` (the imaging geometry both the simulator and the fit use),
:mod:`.disc` (the forward disc's edge), :mod:`.dots` (dot centroids and their grid indices),
:mod:`.fit` (the joint fit over distances and its covariance), :mod:`.figures` (the figures
with 95 % intervals).
"""
