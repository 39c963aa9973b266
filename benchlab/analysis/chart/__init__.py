"""The USAF 1951 chart: where it falls (:mod:`.layout`), finding it in a frame (:mod:`.finder`),
its pose (:mod:`.pose`), reading every found set (:mod:`.reading`), what a three-bar set should
read given the edge MTF (:mod:`.threebar`), and the grey-level morphology the finder uses.

May import: numpy, OpenCV, :mod:`benchlab.analysis.bars`, :mod:`benchlab.analysis.mtf`,
:mod:`benchlab.analysis.sfr`.
"""
