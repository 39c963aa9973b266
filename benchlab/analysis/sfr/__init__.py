"""Slanted-edge SFR (ISO 12233 e-SFR): the sine-wave MTF from one edge.

:mod:`.measure` (the pipeline and :func:`~benchlab.analysis.sfr.measure.measure_sfr`), the
refusals once the ESF is read (:mod:`.refusals`), the parametric LSF (:mod:`.model`), shading
removal (:mod:`.shading`), refusals that name the structure found (:mod:`.structure`), several
frames of one edge (:mod:`.frames`), and where the slanted-edge target falls in the forward
view (:mod:`.target`).

May import: numpy, scipy and :mod:`benchlab.analysis.mtf`.
"""
