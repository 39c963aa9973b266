"""Table 4.10 MTF test as a procedure: its steps (:mod:`.steps`), the analysis of a session's
frames into Tables 4.11-4.15 (:mod:`.analysis`) and the slanted-edge curves and three-way check
(:mod:`.edges`).
"""
