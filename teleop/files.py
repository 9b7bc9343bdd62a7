"""Files written whole: to a fresh name in the target's folder, then renamed over it."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path


def replace_file(path: str | Path, text: str) -> Path:
    """Write ``text`` (UTF-8) as file ``path``: into a new file of the same folder, then
    renamed to ``path`` (``os.replace``). The name is replaced, never written through: a
    hard link or a symlink at ``path`` leaves the file it shares or points to untouched,
    and a reader sees the old content or the new, never a part. ``OSError`` as ``open``."""
    path = Path(path)
    handle, scratch = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".part")
    try:
        with os.fdopen(handle, "w", encoding="utf-8") as stream:
            stream.write(text)
        os.replace(scratch, path)
    except BaseException:
        Path(scratch).unlink(missing_ok=True)
        raise
    return path
