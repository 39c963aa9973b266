"""The camera itself: photon transfer (EMVA 1288 linear model) from pairs of flat frames.

May import: numpy and the analysis top-level helpers.
"""
