"""benchlab: optical test bench control, measurement procedures and analysis."""

from importlib.metadata import PackageNotFoundError, version

try:
    __version__ = version("benchlab")
except PackageNotFoundError:  # running from a source tree without an install
    __version__ = "0.0.0+unknown"

__all__ = ["__version__"]
