"""Acceptance testing per unit: a spec file, verdicts that respect the uncertainty, the stored
verdict versions, unit and lot statistics and the certificate.

:mod:`.spec` (the ``benchlab.spec`` TOML file), :mod:`.decide` (pure decision rules: the
interval of a reading and its verdict against a limit), :mod:`.verify` (one session against a
spec), :mod:`.store` (verdict versions in the session folder), :mod:`.lot` (yield, capability,
drift), :mod:`.certificate` (the unit's HTML certificate).

May import: :mod:`benchlab.report` helpers (the certificate only), :mod:`benchlab.catalog`,
:mod:`benchlab.session`, :mod:`benchlab.storage` - never a device or a procedure.
"""
