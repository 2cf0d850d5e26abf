"""The README, the CHANGELOG and the docs name only paths and commands that exist
(``scripts/check_docs.py``)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

CHECK = Path(__file__).resolve().parent.parent / "scripts" / "check_docs.py"


def _check_docs():
    spec = importlib.util.spec_from_file_location("check_docs", CHECK)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def test_the_docs_name_only_paths_and_commands_that_exist(capsys):
    status = _check_docs().main([])
    assert status == 0, capsys.readouterr().err


def test_the_check_finds_a_path_that_does_not_exist(tmp_path):
    (tmp_path / "docs").mkdir()
    (tmp_path / "simulator").mkdir()
    (tmp_path / "Makefile").write_text("run:\n\ttrue\n")
    (tmp_path / "README.md").write_text(
        "See `simulator/car.py:12`, DeepRacer's `track_geom/utils.py:156` and `make run`.\n"
    )
    assert _check_docs().find_problems(tmp_path) == ["README.md:1: no such path: simulator/car.py"]


def test_the_check_finds_a_module_name_that_moved_and_a_setting_no_doc_names(tmp_path):
    (tmp_path / "docs").mkdir()
    for package in ("jobs", "training"):
        (tmp_path / package).mkdir()
        (tmp_path / package / "__init__.py").write_text("")
    (tmp_path / "jobs" / "evaluation.py").write_text("class Race:\n    pass\n")
    (tmp_path / "training" / "tasks.py").write_text('@app.task(name="training.evaluate")\n')
    (tmp_path / "training" / "settings.py").write_text('A = env.int("PITLANE_A", 1)\n')
    (tmp_path / "Makefile").write_text("")
    (tmp_path / "docs" / "operating.md").write_text("| `PITLANE_B` | b |\n")
    (tmp_path / "README.md").write_text(
        "`jobs.evaluation.Race` runs `training.evaluate`; `training.evaluation` moved, and "
        "`jobs.evaluation.Evaluator` is gone.\n"
    )
    assert _check_docs().find_problems(tmp_path) == [
        "README.md:1: no such module or name of ours: training.evaluation",
        "README.md:1: no such module or name of ours: jobs.evaluation.Evaluator",
        "training/settings.py: reads PITLANE_A, which docs/operating.md does not name",
    ]
