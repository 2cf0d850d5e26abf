"""How many places each of a model's settings is written: the lines of our own Python (not tests,
benches, scripts or migrations) that name it as a word, and the modules they are in.

    python scripts/setting_places.py            # every setting of training.configuration
    python scripts/setting_places.py camera_lens seed

Run at two commits (``git worktree add``) to see what declaring the settings once saved. A
setting's name written in a docstring counts too: a place a reader must keep in step.
"""

from __future__ import annotations

import ast
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SKIPPED = ("tests/", "bench/", "scripts/")


def declared() -> list[str]:
    """The settings ``ModelSettings`` declares, read from the source (no Django needed)."""
    tree = ast.parse((ROOT / "training/configuration.py").read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ClassDef) and node.name == "ModelSettings":
            return [
                statement.target.id
                for statement in node.body
                if isinstance(statement, ast.AnnAssign) and isinstance(statement.target, ast.Name)
            ]
    raise SystemExit("training/configuration.py declares no ModelSettings")


def main(names: list[str]) -> None:
    files = subprocess.run(
        ["git", "ls-files", "*.py"], cwd=ROOT, capture_output=True, text=True, check=True
    ).stdout.split()
    ours = [f for f in files if not f.startswith(SKIPPED) and "/migrations/" not in f]
    lines = {f: (ROOT / f).read_text().splitlines() for f in ours}
    total = 0
    for name in names or declared():
        word = re.compile(rf"\b{name}\b")
        places = [
            (f, n) for f, text in lines.items() for n, line in enumerate(text) if word.search(line)
        ]
        total += len(places)
        modules = len({f for f, _ in places})
        print(f"{name:22} {len(places):4} lines in {modules:3} modules")
    print(f"{'all':22} {total:4} lines")


if __name__ == "__main__":
    main(sys.argv[1:])
