"""Pure analysis functions: arrays in, numbers out. No devices, no files (except reading the
thesis tables and user-supplied comparison tables on request).

Vocabulary: ``modulation`` is always the Eq. 2.9 bar (square-wave) contrast; the sine-wave
quantities are ``fundamental_modulation`` and the MTF from :func:`ctf_to_mtf`.

Subpackages, one per measurement: :mod:`~benchlab.analysis.bars` (bar modulation),
:mod:`~benchlab.analysis.sfr` (slanted edge), :mod:`~benchlab.analysis.chart` (USAF chart),
:mod:`~benchlab.analysis.camera` (photon transfer), :mod:`~benchlab.analysis.views` (radial view
synthesis), :mod:`~benchlab.analysis.mtf` (Coltman, frequencies, comparisons). Imports allowed:
numpy/scipy/scikit-image/OpenCV and :mod:`benchlab.drivers` constants only - no device, no
session, no file (except the thesis tables shipped as package data).

The public names are listed once, in ``__init__.pyi``; lazy_loader imports each on first use,
so ``import benchlab.analysis`` costs nothing.
"""

import lazy_loader as lazy

__getattr__, __dir__, __all__ = lazy.attach_stub(__name__, __file__)
