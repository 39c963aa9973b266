"""``benchlab report SESSION``: one self-contained HTML page, one module per section.

:mod:`.render` assembles the page from its sections (``SECTIONS``); :mod:`.html` holds the small
building blocks; :mod:`.tables` says how each results table is shown.

May import: :mod:`benchlab.session`, :mod:`benchlab.storage`, :mod:`benchlab.analysis`,
:mod:`benchlab.scenes` - never a device or a procedure.
"""
