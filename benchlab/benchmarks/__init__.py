"""Speed and accuracy benchmarks: each prints a table per bucket (``benchlab benchmark ...``).

Bars (:mod:`.bars`), slanted edge (:mod:`.sfr`, :mod:`.sfr_oracle`, :mod:`.sfr_defects`,
:mod:`.sfr_bench`), chart finder (:mod:`.chart`), view synthesis (:mod:`.viewsynth`),
characterisation (:mod:`.characterise`), batch re-analysis and the catalogue (:mod:`.batch`).

May import anything below the command line: protocols, sessions, scenes, analysis,
:mod:`benchlab.synthetic`. Their synthetic truth comes from :mod:`benchlab.synthetic`.
"""
