"""The session catalogue: an SQLite index of session folders (rebuildable; folders stay the truth).

:mod:`.index` (the :class:`~benchlab.catalog.index.Catalog`), :mod:`.extract` (what one folder
contributes), :mod:`.schema` (tables and migrations).

May import: :mod:`benchlab.session`, :mod:`benchlab.storage`, :mod:`benchlab.analysis`.
"""
