"""benchlab: optical test bench control, measurement procedures and analysis."""

__all__ = ["__version__"]


def __getattr__(name: str) -> str:
    # The version is looked up on first use: importlib.metadata costs start-up time that
    # `benchlab --help` and most commands never need.
    if name != "__version__":
        raise AttributeError(f"module 'benchlab' has no attribute {name!r}")
    from importlib.metadata import PackageNotFoundError, version

    try:
        value = version("benchlab")
    except PackageNotFoundError:  # running from a source tree without an install
        value = "0.0.0+unknown"
    globals()["__version__"] = value
    return value
