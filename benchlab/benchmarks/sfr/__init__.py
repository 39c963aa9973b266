"""``benchlab benchmark sfr``: the slanted-edge SFR on clean synthetic edges (:mod:`.edges`),
under real-looking defects (:mod:`.defects`), against a true-model ceiling (:mod:`.oracle`) and
on the simulated bench (:mod:`.bench`)."""
