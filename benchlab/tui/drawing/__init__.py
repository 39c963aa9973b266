"""What the terminal UI draws: frames as real pixels (Kitty / Sixel) or half-blocks, plots,
the chart overlay and the unwrapped radial view.

May import: :mod:`benchlab.analysis` and Textual; never a device or a session.
"""
