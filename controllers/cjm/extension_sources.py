"""Which C++ sources the compiled step was built from (docs/design.md section 16).

``setup.py`` builds ``controllers.cjm._step`` with :func:`sources_digest` of the sources
in ``_step/`` compiled in, as ``_step.SOURCES_DIGEST``. Where the sources sit beside the
package (a clone, an editable install), an extension whose digest differs from theirs is
stale: built before a ``git pull`` or an edit, it would run other code than the one read,
or fail with pybind11's "incompatible function arguments". The CJM then does not use it
(:func:`stale_extension_reason`). This module imports nothing but the standard library:
``setup.py`` loads it by path, before the package's dependencies are installed.
"""

from __future__ import annotations

import hashlib
from pathlib import Path

#: the C++ sources and headers of the compiled step
SOURCE_DIRECTORY = Path(__file__).resolve().parent / "_step"
#: the suffixes of the files the digest covers
SOURCE_SUFFIXES = (".cpp", ".hpp")


def source_files(directory: Path = SOURCE_DIRECTORY) -> list[Path]:
    """The C++ sources and headers in ``directory``, sorted by name."""
    return sorted(path for path in directory.glob("*") if path.suffix in SOURCE_SUFFIXES)


def sources_digest(directory: Path = SOURCE_DIRECTORY) -> str:
    """SHA-256 (16 hex digits) of each source's name and bytes, in name order."""
    digest = hashlib.sha256()
    for path in source_files(directory):
        digest.update(path.name.encode() + b"\0" + path.read_bytes() + b"\0")
    return digest.hexdigest()[:16]


def stale_extension_reason(built_digest: str,
                           directory: Path = SOURCE_DIRECTORY) -> str | None:
    """Why an extension built from sources of digest ``built_digest`` must not run here,
    or None: no sources beside the package (a wheel: nothing to compare), or the same."""
    if not source_files(directory):
        return None
    current = sources_digest(directory)
    if built_digest == current:
        return None
    return (f"controllers.cjm._step was built from other C++ sources (digest "
            f"{built_digest or 'none'}) than those in {directory} ({current}): rebuild it "
            f"with pip install -e .")
