"""``teleop.files.replace_file``: the name replaced, whole, never written through."""

from __future__ import annotations

import os

import pytest
from hypothesis import given
from hypothesis import strategies as st

from teleop.files import replace_file


@given(first=st.text(), second=st.text())
def test_the_file_holds_the_last_text_whole_and_nothing_else_is_left(tmp_path_factory, first,
                                                                     second):
    folder = tmp_path_factory.mktemp("files")
    path = folder / "a.json"
    replace_file(path, first)
    replace_file(path, second)
    assert path.read_bytes() == second.encode("utf-8")
    assert os.listdir(folder) == ["a.json"]


def test_a_symlink_at_the_name_is_replaced_not_followed(tmp_path):
    target = tmp_path / "target.txt"
    target.write_text("kept")
    link = tmp_path / "link.txt"
    link.symlink_to(target)
    replace_file(link, "new")
    assert target.read_text() == "kept" and not link.is_symlink() and link.read_text() == "new"


def test_a_failed_write_leaves_the_old_file_and_no_scratch(tmp_path):
    path = tmp_path / "a.txt"
    path.write_text("old")
    with pytest.raises(UnicodeEncodeError):
        replace_file(path, "\udc80")  # a lone surrogate: not UTF-8
    assert path.read_text() == "old" and os.listdir(tmp_path) == ["a.txt"]
