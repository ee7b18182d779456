"""Files written whole or not at all: a crash mid-write never leaves half a file."""
from __future__ import annotations

import math
import os
import tempfile
from pathlib import Path
from typing import Any


def _default_mode() -> int:
    """What ``open()`` would give a new file (0644 under the usual umask 022): mkstemp's
    0600 would make results.json private while curves.png is not."""
    mask = os.umask(0)
    os.umask(mask)
    return 0o666 & ~mask


FILE_MODE = _default_mode()


def fsync_dir(path: Path) -> None:
    """Make a rename or a new entry in ``path`` durable (a no-op where directories cannot
    be opened)."""
    try:
        fd = os.open(path, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def atomic_write_bytes(path: Path, data: bytes, durable: bool = True) -> None:
    """Write via a temporary file beside ``path`` and rename, so a crash never leaves half
    a file; the temporary file is removed if writing fails. ``durable``: fsync the file
    and the rename too (nor, after a power loss, an empty file); a cache that can be
    rebuilt skips that cost."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.")
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            if durable:
                f.flush()
                os.fsync(f.fileno())
        os.chmod(tmp, FILE_MODE)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    if durable:
        fsync_dir(path.parent)


def atomic_write_text(path: Path, text: str) -> None:
    """``atomic_write_bytes`` of ``text`` in UTF-8."""
    atomic_write_bytes(path, text.encode())


def json_safe(x: Any) -> Any:
    """JSON-safe: NaN and infinities -> None, numpy scalars -> Python, tuples -> lists."""
    if isinstance(x, float):
        return None if math.isnan(x) or math.isinf(x) else x
    if hasattr(x, "item") and getattr(x, "ndim", 1) == 0:
        return json_safe(x.item())
    if isinstance(x, (list, tuple)):
        return [json_safe(v) for v in x]
    if isinstance(x, dict):
        return {k: json_safe(v) for k, v in x.items()}
    return x
