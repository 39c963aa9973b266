"""Speed and accuracy benchmarks: each prints a table per bucket (``benchlab benchmark ...``).

Bars (:mod:`.bars`), slanted edge (:mod:`.sfr`), chart finder (:mod:`.chart`), view synthesis
(:mod:`.viewsynth`), characterisation (:mod:`.characterise`), batch re-analysis and the
catalogue (:mod:`.batch`), depth of field (:mod:`.depth`), the live focus aid
(:mod:`.focus_aid`), acceptance decisions (:mod:`.acceptance`).

May import anything below the command line: protocols, sessions, scenes, analysis,
:mod:`benchlab.synthetic`. Their synthetic truth comes from :mod:`benchlab.synthetic`.
"""
