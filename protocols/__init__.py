"""Measurement procedures: Table 4.10 MTF and section 4.4 relative radiometry."""
