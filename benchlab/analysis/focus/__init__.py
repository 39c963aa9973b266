"""Focus: the live sharpness figure (:mod:`.sharpness`) and the through-focus analysis of a
depth-of-field sweep (:mod:`.through_focus`, :mod:`.criteria`, :mod:`.field`).

``sharpness`` is re-exported here: ``from benchlab.analysis.focus import sharpness`` is the
import the focus step and the live views have always used.
"""

from benchlab.analysis.focus.sharpness import sharpness

__all__ = ["sharpness"]
