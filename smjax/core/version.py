"""smjax's version, from the installed distribution's metadata."""
from __future__ import annotations

from importlib.metadata import PackageNotFoundError, version


def smjax_version() -> str:
    """Read from metadata, never from ``smjax.__version__``: a folder named smjax beside a
    user's script can shadow the package, and results must still be written."""
    try:
        return version("smjax")
    except PackageNotFoundError:  # a source tree that was never installed
        return "0+unknown"
