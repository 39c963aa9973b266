"""benchlab: optical test bench control, measurement procedures and analysis.

The scripting API - open a bench, run a procedure, read a session, measure bars, an edge or a
chart - is listed once, in ``__init__.pyi``; lazy_loader imports each name on first use
(:mod:`benchlab.api`), so ``import benchlab`` (and ``benchlab --help``) costs next to nothing.
"""

import lazy_loader as lazy

_lazy_getattr, _, _names = lazy.attach_stub(__name__, __file__)
__all__ = [*_names, "__version__"]


def __dir__() -> list[str]:
    return list(__all__)


def __getattr__(name: str) -> object:
    if name != "__version__":
        return _lazy_getattr(name)
    # The version is looked up on first use: importlib.metadata costs start-up time that
    # `benchlab --help` and most commands never need.
    from importlib.metadata import PackageNotFoundError, version

    try:
        value = version("benchlab")
    except PackageNotFoundError:  # running from a source tree without an install
        value = "0.0.0+unknown"
    globals()["__version__"] = value
    return value
