"""Depth of field on the bench: the stage carries the chart through focus (``run depth``)."""
