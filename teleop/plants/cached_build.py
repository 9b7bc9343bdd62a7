"""The plant's C sources compiled once into the user's cache (docs/design.md section 17.5).

A library is built with ``sysconfig``'s ``CC`` into ``$XDG_CACHE_HOME/cjm-teleop`` (as the
bench's allocation counter) under a hash of its sources, the compiler and what it is built
against, so the first use on a machine compiles it and every later process loads it; a
build that fails leaves nothing behind and gives None (the caller falls back to Python).
"""

from __future__ import annotations

import hashlib
import os
import shlex
import subprocess
import sysconfig
import tempfile
from collections.abc import Sequence
from pathlib import Path


def cached_build(stem: str, sources: Sequence[Path], flags: Sequence[str],
                 identity: str) -> Path | None:
    """The shared library ``stem-<hash>.so`` of ``sources`` (headers among them are hashed,
    not compiled) compiled with ``flags``, ``identity`` naming what else it depends on
    (library versions); None when it does not build."""
    compiler = shlex.split(sysconfig.get_config_var("CC") or "cc")
    digest = hashlib.sha256(b"\0".join(source.read_bytes() for source in sources)
                            + "\0".join([*compiler, *flags, identity]).encode())
    target = (Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "cjm-teleop"
              / f"{stem}-{digest.hexdigest()[:16]}.so")
    if target.is_file():
        return target
    try:
        target.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=target.parent) as scratch:
            built = Path(scratch) / target.name
            subprocess.run([*compiler, "-shared", "-fPIC", "-O2", "-o", str(built),
                            *(str(source) for source in sources if source.suffix == ".c"),
                            *flags], check=True, capture_output=True, timeout=120)
            built.replace(target)
    except (OSError, subprocess.SubprocessError):
        return None
    return target
