"""smjax's version, from the installed distribution's metadata, and a warning when a folder
named smjax shadows the package."""
from __future__ import annotations

import sys
import warnings
from importlib.metadata import PackageNotFoundError, version


def smjax_version() -> str:
    """Read from metadata, never from ``smjax.__version__``: a folder named smjax beside a
    user's script can shadow the package, and results must still be written."""
    try:
        return version("smjax")
    except PackageNotFoundError:  # a source tree that was never installed
        return "0+unknown"


def shadowing_folder() -> str | None:
    """The folder that stands in for the package ``smjax`` when ``import smjax`` found a
    folder without ``__init__.py`` (a clone beside a script, say): Python makes it a
    namespace package, and the installed modules still import under it. None otherwise."""
    package = sys.modules.get("smjax")
    if package is None or getattr(package, "__file__", None) is not None:
        return None
    return next(iter(getattr(package, "__path__", [])), "?")


def warn_if_shadowed() -> None:
    """Warn once, on import: the package's ``__init__`` never ran, so nothing it sets up
    (``smjax.make``, ``smjax.__version__``, the XLA flags) is there."""
    folder = shadowing_folder()
    if folder is not None:
        warnings.warn(f"the folder {folder} (no __init__.py) shadows the installed smjax "
                      f"package: rename it, or run from another directory")
