"""The documents name the repository's files as they are: every path of the packages, the
tests, the docs or the examples a document writes in backticks exists (a file renamed or
removed leaves none behind, as ``teleop/cli/ros2_options.py`` in docs/ros2.md did)."""

from __future__ import annotations

import re
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent

#: the documents read: the README, the contributors' guide and docs/
DOCUMENTS = [REPO / "README.md", REPO / "CONTRIBUTING.md", *sorted((REPO / "docs").glob("*.md"))]

#: a repository path in backticks (a folder's ``/`` and a glob's ``*`` included)
PATH = re.compile(r"`((?:constraints|controllers|teleop|web|tests|docs|examples)/[\w./*-]*)`")

#: paths the documents write as patterns for the reader to fill in, not as files
PLACEHOLDERS = frozenset({"docs/results/compare/NAME.json", "tests/test_x.py"})


def named_paths(document: Path) -> list[str]:
    return [path for path in PATH.findall(document.read_text()) if path not in PLACEHOLDERS]


def test_the_documents_name_paths():
    """The pattern finds what it looks for (a test of nothing otherwise)."""
    assert {"tests/test_layers.py", "controllers/cjm/_step/"} <= set(
        named_paths(REPO / "README.md"))


@pytest.mark.parametrize("document", DOCUMENTS, ids=lambda document: document.name)
def test_every_path_a_document_names_exists(document):
    missing = [path for path in named_paths(document) if not list(REPO.glob(path))]
    assert missing == [], f"{document.name} names files that are not in the repository"
