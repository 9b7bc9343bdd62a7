"""Which files a constraint type touches (issue 34 item 4): for each built-in type, the
files of the repository outside ``tests/`` and ``docs/`` that name its class as a word
(code, comments and prose alike: the compiled step's declaration in C++, the mink adapter,
the README), counted over what git tracks.

Run:  python docs/measure_constraint_files.py [PointLock Barrier ...]
"""

from __future__ import annotations

import argparse
import os
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("names", nargs="*", default=["PointLock", "Barrier"],
                        help="class names (default: PointLock Barrier)")
    for name in parser.parse_args().names:
        files = files_naming(name)
        print(f"{name}: {len(files)} files")
        for path in files:
            print(f"  {path}")


if __name__ == "__main__":
    main()
