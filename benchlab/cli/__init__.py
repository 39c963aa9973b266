"""The ``benchlab`` command line."""
