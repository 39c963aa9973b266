"""Camera characterisation (EMVA 1288-style photon transfer) as a procedure: its steps
(:mod:`.steps`), parameters (:mod:`.params`), offline analysis (:mod:`.analysis`), the response
calibration file (:mod:`.calibration`) and what the simulated sensor should give (:mod:`.truth`).
"""
