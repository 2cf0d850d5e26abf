"""`make lint`'s size check: a module of Pitlane's packages over MODULE_LINES lines says at its top
why (a paragraph of its docstring beginning "Long because"), and a function over FUNCTION_LINES
lines says why on the line above its ``def`` (a comment beginning "# Long because"). Tests,
benchmarks and migrations are not checked.

    python scripts/check_sizes.py          # exit 1, listing each, when one does not say why
"""

from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGES = (
    "accounts",
    "analysis",
    "archives",
    "common",
    "console",
    "jobs",
    "notifications",
    "racing",
    "rl",
    "sandbox",
    "simulator",
    "training",
)
MODULE_LINES = 400
FUNCTION_LINES = 60
MODULE_REASON = "Long because"
FUNCTION_REASON = "# Long because"


def problems(path: Path) -> list[str]:
    text = path.read_text()
    lines = text.splitlines()
    tree = ast.parse(text, filename=str(path))
    where = path.relative_to(ROOT)
    found = []
    docstring = ast.get_docstring(tree) or ""
    if len(lines) > MODULE_LINES and MODULE_REASON not in docstring:
        found.append(f"{where}: {len(lines)} lines, and its docstring does not say why")
    for node in ast.walk(tree):
        if not isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            continue
        first = min([node.lineno, *(d.lineno for d in node.decorator_list)])
        length = node.end_lineno - node.lineno + 1
        comment = first - 1  # the comment block right above the def, read from its first line
        while comment >= 1 and lines[comment - 1].strip().startswith("#"):
            comment -= 1
        above = lines[comment].strip() if comment < first - 1 else ""
        if length > FUNCTION_LINES and not above.startswith(FUNCTION_REASON):
            found.append(f"{where}:{node.lineno}: {node.name} has {length} lines")
    return found


def main() -> int:
    found = [
        problem
        for package in PACKAGES
        for path in sorted((ROOT / package).rglob("*.py"))
        if "migrations" not in path.parts
        for problem in problems(path)
    ]
    for problem in found:
        print(problem)
    if found:
        print(
            f"Split these, or say why they are long: a module over {MODULE_LINES} lines in a "
            f"docstring paragraph beginning {MODULE_REASON!r}, a function over {FUNCTION_LINES} "
            f"lines in a comment above it beginning {FUNCTION_REASON!r}."
        )
    return 1 if found else 0


if __name__ == "__main__":
    sys.exit(main())
