"""The technician's terminal UI (Textual): devices, live view, procedure runner, sessions.

The UI has no measurement logic of its own: every action calls the same bench, procedure,
analysis and session code as the command line. Start it with ``benchlab`` (or ``benchlab tui``),
``--simulate`` for the simulated bench.
"""
