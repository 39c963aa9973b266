"""Device exchanges recorded (:mod:`.io_trace`, ``benchlab --trace-io``), read back
(:mod:`.cassette`) and replayed to the drivers (:mod:`.replay`, ``benchlab --replay``)."""
