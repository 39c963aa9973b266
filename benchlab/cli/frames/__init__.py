"""Commands that analyse saved frames: ``analyze IMAGE`` (bar modulation), ``find-chart``,
``sfr`` (slanted edges) and the view synthesis (``unwrap``, ``perspective``, ``viewpoint``,
``calibrate radial``), with their benchmarks."""
