"""Which files a constraint type touches (issue 34 item 4): for each built-in type, the
files of the repository outside ``tests/`` and ``docs/`` that name its class as a word
(code, comments and prose alike: the compiled step's math in C++, the mink adapter, the
README), counted over what git tracks. Each file is marked by how it names the class:

* ``registers``: a per-type piece of a layer (``register_...(Name, ...)``) or the
  registry's list of built-in types (``constraints/__init__.py``);
* ``defines``: the class's own module (``class Name(``); ``derives``: a subclass's;
* ``builds``: code that makes one (``Name(``, ``Name.on_link(``...: scenarios, examples,
  benchmarks);
* ``mentions``: only prose or comments (and type hints).

What a new type must touch is its module and the ``registers`` files of the layers it
wants a piece in; the others use or describe the built-in types.

Run:  python docs/measure_constraint_files.py [PointLock Barrier ...]
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
#: the folders whose files are not counted: the tests and the documentation
LEFT_OUT = ("tests", "docs")


def files_naming(name: str) -> list[str]:
    """The tracked files outside :data:`LEFT_OUT` naming ``name`` as a word, sorted."""
    found = subprocess.run(
        ["git", "grep", "-l", "-w", "-I", "-e", name, "--", ".",
         *(f":(exclude){folder}" for folder in LEFT_OUT)],
        cwd=ROOT, capture_output=True, text=True, check=False)
    if found.returncode not in (0, 1):  # 1: no file names it
        raise SystemExit(found.stderr.strip())
    return sorted(found.stdout.split())


def role(name: str, path: str) -> str:
    """How the file at ``path`` names the class ``name`` (the module docstring's marks)."""
    with open(os.path.join(ROOT, path), encoding="utf-8") as source:
        text = source.read()
    if re.search(rf"register\w*\(\s*{name}\b", text) or re.search(
            rf"BUILTIN_TYPES\s*=.*\b{name}\b", text):
        return "registers"
    if re.search(rf"^class {name}\(", text, re.MULTILINE):
        return "defines"
    if re.search(rf"^class \w+\([^)]*\b{name}\b", text, re.MULTILINE):
        return "derives"
    code = "\n".join(line.split("#")[0] for line in text.splitlines()
                     if not line.lstrip().startswith(("//", "*", '"', "'")))
    if path.endswith(".py") and re.search(rf"\b{name}(\.\w+)?\(", code):
        return "builds"
    return "mentions"


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=["PointLock", "Barrier"],
                        help="class names (default: PointLock Barrier)")
    for name in parser.parse_args().names:
        files = files_naming(name)
        print(f"{name}: {len(files)} files")
        for path in files:
            print(f"  {role(name, path):9}  {path}")


if __name__ == "__main__":
    main()
