"""Commands on measurement runs and their sessions: ``run``, ``resume``, ``analyze SESSION``
batches, ``report``, ``sessions``, the acceptance verdicts (``verify``, ``unit``, ``lot``...) and
the depth-of-field benchmark."""
