"""Synthetic truth: bar ROIs, slanted edges and three-bar sets rendered in closed form
(exact blur and pixel integration) with the answer each measurement should give.

Used by the simulated scenes, the tests and :mod:`benchlab.benchmarks`; never by an estimator.
May import: numpy, scipy and :mod:`benchlab.analysis` (its closed-form models).
"""
