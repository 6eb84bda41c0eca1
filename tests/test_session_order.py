"""The order the test session hands its files to the workers in (tests/conftest.py)."""

from __future__ import annotations

from pathlib import Path

import conftest

TESTS = Path(__file__).resolve().parent


def test_every_timed_file_exists_and_the_tiers_are_told_apart():
    """A renamed or removed test file would lose its place silently: every entry names a file of
    tests/; each ``-m`` expression takes its tier's seconds, and no expression both."""
    for tier, table in conftest.FILE_SECONDS.items():
        for name in table:
            assert (TESTS.parent / name).is_file(), f"FILE_SECONDS[{tier!r}]: {name} is gone"
    assert conftest.file_seconds("not slow") is conftest.FILE_SECONDS["default"]
    assert conftest.file_seconds("slow and not docs_pages") is conftest.FILE_SECONDS["slow"]
    both = conftest.file_seconds("")
    name = "tests/test_evaluate.py"
    assert (
        both[name] == conftest.FILE_SECONDS["default"][name] + conftest.FILE_SECONDS["slow"][name]
    )


def test_longest_files_first_and_a_files_tests_keep_their_order():
    """The sort is stable: the tests of one file stay in order, unlisted files keep theirs and
    come after every listed one."""
    listed = sorted(conftest.FILE_SECONDS["default"].items(), key=lambda kv: kv[1])
    short, least = listed[0]
    longer = next(name for name, seconds in listed if seconds > least)  # two files may tie
    ids = [f"{short}::a", "tests/test_x.py::b", f"{longer}::c", f"{short}::d", "tests/test_y.py::e"]
    items = [type("Item", (), {"nodeid": i})() for i in ids]
    config = type("Config", (), {"getoption": lambda self, name, default=None: "not slow"})()
    conftest.pytest_collection_modifyitems(config, items)
    assert [i.nodeid for i in items] == [
        f"{longer}::c",
        f"{short}::a",
        f"{short}::d",
        "tests/test_x.py::b",
        "tests/test_y.py::e",
    ]
