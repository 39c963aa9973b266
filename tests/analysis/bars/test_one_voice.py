"""One voice per result: over the extremes benchmark's cases, a reading that gives a value (or
a bound) carries no warning that says the bars are not resolved, and a fallback says in one
line what was used instead and why."""

from __future__ import annotations

import pytest

from benchlab.benchmarks.bars.extremes import run_extremes


@pytest.mark.slow
def test_no_value_carries_a_not_resolved_warning() -> None:
    outcomes = run_extremes()
    values = [o for o in outcomes if o.result.resolved]
    assert len(values) > 150  # the bucket is mostly values and bounds
    contradicting = [(o.case.bucket, o.estimator, w) for o in values
                     for w in o.result.warnings if "not resolved" in w]
    assert contradicting == []
    fallbacks = [o for o in values if any("could not read them" in w for w in o.result.warnings)]
    assert fallbacks  # the perfect and dark-level-0 patterns defeat some fits
    for o in fallbacks:
        lines = [w for w in o.result.warnings if "could not read them" in w]
        assert len(lines) == 1, lines
        # the estimator's reason is in that line, and so is what was used instead
        assert any(w in lines[0] for w in ("standard errors", "variance", "discarded")), lines[0]
        assert ("contrast 1" in lines[0]) or ("profile's extremes" in lines[0]), lines[0]
