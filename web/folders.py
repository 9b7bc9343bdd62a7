"""A folder the browser may read and write files in, and nothing outside it.

The UI names scenes and recordings by **file name** only: the server was started with one
folder for each (``teleop web --scene-dir DIR --record-dir DIR``, docs/design.md section
5.3), and :meth:`Folder.path` turns a name into a path inside it or refuses it. Refused:
anything that is not a plain file name (a path separator, ``.``/``..``, an absolute path,
a drive, a NUL, a name longer than :data:`MAX_NAME`), and a name that resolves outside the
folder (a symlink, or a symlinked folder, leading out). A refusal says only that the name
is not allowed: never whether something exists outside the folder.

Names inside the folder are the operator's own: their errors (no such scene, not JSON)
may say what is there.
"""

from __future__ import annotations

import os
from pathlib import Path

#: longest file name accepted (bytes of UTF-8; most file systems allow 255)
MAX_NAME = 200


class Folder:
    """The folder ``root`` (created on the first write), holding files of one kind.

    ``what`` names the kind in messages ("scene", "recording"); every name must end in
    ``suffix`` (".json"), so nothing else (a script, a dotfile) can be written there.
    """

    def __init__(self, root: str | Path, what: str, suffix: str) -> None:
        self.root = Path(root).expanduser().absolute()
        self.what = what
        self.suffix = suffix

    def __repr__(self) -> str:
        return f"Folder({str(self.root)!r}, {self.what!r})"

    def _refused(self, name: object, why: str) -> ValueError:
        return ValueError(f"{self.what} name {name!r} refused: {why}; give a file name in "
                          f"the {self.what} folder (no folders, no '..')")

    def name_of(self, name: object) -> str:
        """``name`` checked as a plain file name ending in the folder's suffix."""
        if not isinstance(name, str):
            raise self._refused(name, "not a text")
        name = name.strip()
        if not name:
            raise self._refused(name, "empty")
        if "/" in name or "\\" in name or (os.altsep and os.altsep in name) or ":" in name:
            raise self._refused(name, "it contains a path separator or a drive")
        if "\0" in name or any(ord(c) < 32 for c in name):
            raise self._refused(name, "it contains control characters")
        if name in (".", "..") or name.startswith(".."):
            raise self._refused(name, "it leads out of the folder")
        if len(name.encode("utf-8")) > MAX_NAME:
            raise self._refused(name[:40] + "...", f"longer than {MAX_NAME} bytes")
        if not name.endswith(self.suffix) or name == self.suffix or name.startswith("."):
            raise self._refused(name, f"a {self.what} name ends in {self.suffix} and does not "
                                      "start with '.'")
        return name

    def path(self, name: object) -> Path:
        """The path of file ``name`` in the folder; ``ValueError`` when the name is not a
        plain file name or resolves outside the folder (a symlink leading out)."""
        name = self.name_of(name)
        path = self.root / name
        try:
            inside = path.resolve().parent == self.root.resolve()
        except (RuntimeError, OSError):  # a symlink loop: said as any other refusal
            inside = False
        if not inside:
            raise self._refused(name, "it leads out of the folder")
        return path

    def existing(self, name: object) -> Path:
        """:meth:`path` of a file that is there (a regular file in the folder)."""
        path = self.path(name)
        if not path.is_file():
            raise ValueError(f"no {self.what} {path.name!r} in the {self.what} folder")
        return path

    def writable(self, name: object) -> Path:
        """:meth:`path`, with the folder created; a name that is a folder is refused."""
        path = self.path(name)
        try:
            self.root.mkdir(parents=True, exist_ok=True)
        except OSError as error:
            raise ValueError(f"cannot create the {self.what} folder: {error.strerror}") from None
        path = self.path(name)  # the folder may itself have been a dangling link
        if path.exists() and not path.is_file():
            raise ValueError(f"{path.name!r} in the {self.what} folder is not a file")
        return path

    def new(self, name: object) -> Path:
        """:meth:`writable` for a file that is not there yet: a recording never replaces
        another."""
        path = self.writable(name)
        if path.exists():
            raise ValueError(f"{path.name!r} is already in the {self.what} folder: "
                             "choose another name")
        return path

    def unused_name(self, stem: str) -> str:
        """``stem`` + suffix, or ``stem-2`` + suffix, ``stem-3`` ..., the first not in the
        folder."""
        name, count = f"{stem}{self.suffix}", 1
        while (self.root / name).exists() or (self.root / name).is_symlink():
            count += 1
            name = f"{stem}-{count}{self.suffix}"
        return name

    def names(self) -> list[str]:
        """The files in the folder with the suffix, sorted (none when it does not exist)."""
        if not self.root.is_dir():
            return []
        return sorted(entry.name for entry in self.root.iterdir()
                      if entry.suffix == self.suffix and self.root.resolve()
                      == entry.resolve().parent and entry.is_file())
