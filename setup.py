"""Build of the optional compiled kernels (everything else is in pyproject.toml).

``benchlab.analysis.bars._histkernels`` speeds up the histogram-peak method; ``optional=True``: on a
machine without a C compiler the install still succeeds and the numpy code runs instead
(``benchlab.analysis.bars.kernels`` picks the path; ``benchlab benchmark analysis`` names it).
"""

import sys

from setuptools import Extension, setup

# Plain IEEE arithmetic: a contracted a * b + c (fused multiply-add) would round differently
# from the numpy reference the kernels reproduce.
FLAGS = [] if sys.platform == "win32" else ["-O3", "-Wall", "-ffp-contract=off"]

setup(
    ext_modules=[
        Extension(
            "benchlab.analysis.bars._histkernels",
            ["benchlab/analysis/bars/_histkernels.c"],
            extra_compile_args=FLAGS,
            optional=True,
        )
    ]
)
