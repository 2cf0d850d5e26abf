"""The suite's process groups (``tests/conftest.py``) reach pytest-xdist's scheduler: with pytest
9.2 they silently did not (pytest-dev/pytest-xdist#1386), every test spread alone, and both
processes started the Celery workers and the consoles their modules share."""

import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import pytest

from tests.conftest import TESTS, _process_group

GROUPED = """
import pytest


@pytest.mark.xdist_group("shared")
@pytest.mark.parametrize("n", range(4))
def test_one_of_a_group(n):
    pass
"""
# The suite's own plugins and settings left out: only the pinned pytest and pytest-xdist.
TWO_PROCESSES = ("-c", "pytest.ini", "-p", "no:cacheprovider", "-p", "no:django", "-n", "2")


@pytest.mark.slow  # 4 s: a pytest of two processes
def test_a_group_runs_in_one_process_under_the_pinned_pytest_and_xdist(tmp_path: Path):
    (tmp_path / "test_grouped.py").write_text(GROUPED)
    (tmp_path / "pytest.ini").write_text("[pytest]\n")
    done = subprocess.run(
        [sys.executable, "-m", "pytest", *TWO_PROCESSES, "--dist", "loadgroup", "-v"],
        cwd=tmp_path,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    passed = [line.split()[0] for line in done.stdout.splitlines() if " PASSED " in line]
    assert len(passed) == 4 and len(set(passed)) == 1, done.stdout  # one worker ran them all


def _item(path: Path, *, cluster: bool = False) -> SimpleNamespace:
    return SimpleNamespace(
        path=path, get_closest_marker=lambda name: cluster if name == "cluster" else None
    )


def test_each_test_is_given_its_process_group():
    browser, module = TESTS / "browser" / "test_x_in_chromium.py", TESTS / "racing" / "test_y.py"
    assert _process_group(_item(module, cluster=True), ()) == "cluster"
    assert _process_group(_item(browser), ("page", "celery_worker_process")) == "celery"
    assert _process_group(_item(module), ("celery_worker_process",)) == "celery"
    assert _process_group(_item(browser), ("page",)) == "browser"
    assert _process_group(_item(module), ("tensorflow",)) == "tensorflow"
    assert _process_group(_item(module), ("db",)) == "racing/test_y"  # its module's
