"""The one list of procedures: name, labels, and where each one's parameters and steps live.

The command line, the terminal UI, the API and the parameter loader all read it. It imports
nothing heavy (building the CLI parser must not import numpy): the parameter classes and the
procedure classes are named by module and attribute and imported when first asked for.

Adding a procedure is one package under ``protocols/`` and one entry in :data:`REGISTRY`. The
module sits low in the layers (it imports nothing of benchlab) so that the command line can
read it without importing the procedures.
"""

from __future__ import annotations

import importlib
from dataclasses import dataclass
from typing import Any, Literal

#: The procedures' names, as the command line and the API take them.
ProcedureName = Literal["mtf", "radiometry", "characterise", "depth", "fov"]


@dataclass(frozen=True)
class ProcedureEntry:
    """Where one procedure lives and how the interfaces name it."""

    name: ProcedureName
    #: The status line's and the report's name of the procedure.
    label: str
    #: Title of the TUI's checklist panel.
    checklist_title: str
    #: ``module:attribute`` of the parameter class.
    params_class: str
    #: ``module:attribute`` of ``check(checker, limits) -> params``.
    check: str
    #: ``module:attribute`` of ``to_dict(params) -> mapping`` (the file's layout).
    to_dict: str
    #: ``module:attribute`` of the procedure class (``Procedure(params)``).
    procedure_class: str

    def load(self, field: str) -> Any:
        """The object a ``module:attribute`` field names, imported on first use."""
        module, _, attribute = str(getattr(self, field)).partition(":")
        return getattr(importlib.import_module(module), attribute)


_P = "benchlab.protocols"
REGISTRY: dict[str, ProcedureEntry] = {e.name: e for e in (
    ProcedureEntry("mtf", "MTF (Table 4.10)", "checklist (Table 4.10 steps)",
                   f"{_P}.mtf.params:MtfParams", f"{_P}.mtf.params:check_mtf",
                   f"{_P}.mtf.params:mtf_to_dict", f"{_P}.mtf.steps:MtfProcedure"),
    ProcedureEntry("radiometry", "Radiometry (section 4.4)", "positions (section 4.4)",
                   f"{_P}.params:RadiometryParams", f"{_P}.params:check_radiometry",
                   f"{_P}.params:radiometry_to_dict",
                   f"{_P}.radiometry:RadiometryProcedure"),
    ProcedureEntry("characterise", "Camera characterisation (EMVA 1288)",
                   "sweeps (EMVA 1288)",
                   f"{_P}.characterise.params:CharacteriseParams",
                   f"{_P}.characterise.params:check_characterise",
                   f"{_P}.characterise.params:characterise_to_dict",
                   f"{_P}.characterise.steps:CharacteriseProcedure"),
    ProcedureEntry("depth", "Depth of field (section 2.2.4)", "through focus (section 2.2.4)",
                   f"{_P}.depth.params:DepthParams", f"{_P}.depth.params:check_depth",
                   f"{_P}.depth.params:depth_to_dict", f"{_P}.depth.steps:DepthProcedure"),
    ProcedureEntry("fov", "Field of view (Tables 3.1, 4.14)", "distances (field of view)",
                   f"{_P}.fov.params:FovParams", f"{_P}.fov.params:check_fov",
                   f"{_P}.fov.params:fov_to_dict", f"{_P}.fov.steps:FovProcedure"),
)}

#: The procedures in the order the interfaces offer them.
PROCEDURES: tuple[ProcedureName, ...] = tuple(e.name for e in REGISTRY.values())


def procedure_name(name: str) -> ProcedureName:
    """``name`` as a :data:`ProcedureName` (a string from the command line or a file).

    Raises
    ------
    KeyError
        Naming the unknown procedure and the known ones (as :func:`entry`).
    """
    return entry(name).name


def entry(name: str) -> ProcedureEntry:
    """The registry entry of ``name``.

    Raises
    ------
    KeyError
        Naming the unknown procedure and the known ones.
    """
    try:
        return REGISTRY[name]
    except KeyError:
        raise KeyError(f"unknown procedure {name!r}; known: {', '.join(PROCEDURES)}") from None


def entry_of(params: object) -> ProcedureEntry:
    """The entry whose parameter class ``params`` is an instance of.

    Raises
    ------
    TypeError
        For parameters of no registered procedure (never another procedure's by default).
    """
    for e in REGISTRY.values():
        if type(params).__name__ == e.params_class.rpartition(":")[2] and isinstance(
                params, e.load("params_class")):
            return e
    raise TypeError(f"{type(params).__name__} is the parameter class of no procedure; "
                    f"known: {', '.join(PROCEDURES)}")


