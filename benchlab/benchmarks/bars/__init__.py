"""``benchlab benchmark analysis``: the bar modulation estimators on seeded synthetic ROIs
(:mod:`.estimators`) and on the extremes a technician produces (:mod:`.extremes`)."""
