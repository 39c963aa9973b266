"""MTF arithmetic: Coltman's series (bar contrast <-> sine MTF), the bench's spatial frequencies,
the defocus disc spectrum, and averaged MTF compared with the thesis's Monte Carlo and simulated
curves.

May import: numpy and the analysis top-level helpers; nothing else of benchlab.
"""
