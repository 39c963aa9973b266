"""What every device simulator is built on: a real pseudo-terminal (:mod:`.pty_device`), the
command routing table (:mod:`.dispatch`) and the test clock (:mod:`.clock`)."""
