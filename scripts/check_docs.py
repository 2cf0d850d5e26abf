"""The docs name only what exists: every repository path and command named in README.md,
CHANGELOG.md and docs/**/*.md is checked against this checkout.

- a path in backticks or a link (``tests/console/test_cluster.py``, ``simulator/car.py:156-167``,
  ``[a picture](docs/tracks.png)``) whose first component is one of the repository's own top-level
  entries must exist; a line suffix (``:12``, ``:12-34``) is allowed, globs and ``<placeholders>``
  are skipped, and so are paths in DeepRacer's repositories (``track_geom/utils.py``,
  ``bundle/...``), whose first folder is not ours; a link's ``#section`` must be a heading there;
- ``python -m X`` names a module of ours (``X.py``, ``X/__init__.py`` or ``X/__main__.py``);
  third-party modules (pytest, pip, celery...) are skipped;
- ``manage.py NAME`` names a management command of ours or a Django or third-party built-in;
- ``make TARGET`` names a target of the Makefile;
- a dotted name in backticks whose first part is one of our packages (``jobs.shares``,
  ``rl.episode.Fleet``) names a module of ours, or a name a module of ours defines at its top;
  a Celery task's name (``training.train``) is one too;
- every environment variable the code reads through ``console.env`` or ``os.environ`` is in
  docs/operating.md's settings (docs/testing.md's, for the test settings').

    python scripts/check_docs.py     # exit 1, listing each problem, when one is found
"""

from __future__ import annotations

import re
import sys
from collections.abc import Iterator
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

# What running the console makes (data, screenshots, the virtualenv): named in the docs, never
# shipped, so a fresh clone has none of them.
RUNTIME_ENTRIES = {
    ".venv",
    "var",
    "test-artifacts",
    ".pytest_cache",
    ".ruff_cache",
    ".hypothesis",
    ".git",
}

# Paths in DeepRacer's repositories whose first folder happens to be one of ours.
FOREIGN_PATHS = {"scripts/evaluation/prepare-config.py"}  # DeepRacer for Cloud's

DJANGO_COMMANDS = {
    # django.core
    "check",
    "compilemessages",
    "createcachetable",
    "dbshell",
    "diffsettings",
    "dumpdata",
    "flush",
    "inspectdb",
    "loaddata",
    "makemessages",
    "makemigrations",
    "migrate",
    "optimizemigration",
    "runserver",
    "sendtestemail",
    "shell",
    "showmigrations",
    "sqlflush",
    "sqlmigrate",
    "sqlsequencereset",
    "squashmigrations",
    "startapp",
    "startproject",
    "test",
    "testserver",
    # django.contrib: auth, staticfiles, sessions, contenttypes; channels
    "changepassword",
    "createsuperuser",
    "collectstatic",
    "findstatic",
    "clearsessions",
    "remove_stale_contenttypes",
    "runworker",
}

FENCE = re.compile(r"^```[^\n]*\n(.*?)^```", re.S | re.M)
INLINE_CODE = re.compile(r"`([^`\n]+(?:\n[^`\n]+)*)`")
LINK = re.compile(r"\]\(([^)\s]+)\)|<img [^>]*src=\"([^\"]+)\"")
HEADING = re.compile(r"^#{1,6} +(.+?) *#*$", re.M)
LINE_SUFFIX = re.compile(r":\d+(-\d+)?$")
PYTHON_MODULE = re.compile(r"python3? -m ([A-Za-z_][\w.]*)(<?)")
MANAGE_COMMAND = re.compile(r"manage\.py ([a-z_]+)")
MAKE_TARGET = re.compile(r"(?:^|[\s;&|(])make ([a-z][\w-]*)")
DOTTED = re.compile(r"^([a-z_][a-z0-9_]*)((?:\.[A-Za-z_]\w*)+)$")
TASK_NAME = re.compile(r"\bname=\"([a-z_]+(?:\.[a-z_]+)+)\"")
SETTING_READ = re.compile(r"(?:env\.[a-z]+\(\s*|environ(?:\.get)?[\[(]\s*)\"([A-Z][A-Z0-9_]+)\"")
# Where the code's settings are read: the apps and the libraries below them, not tests or benches
SETTINGS_READERS = ("accounts", "analysis", "archives", "common", "console", "jobs")
SETTINGS_READERS += ("notifications", "racing", "rl", "sandbox", "simulator", "training")
FILE_SUFFIXES = {"py", "md", "json", "yaml", "txt", "html", "js", "css", "csv", "sh", "toml"}
TEST_SETTINGS = "console/settings/test.py"  # its variables are the suite's: docs/testing.md


def documents(root: Path) -> list[Path]:
    """README.md, CHANGELOG.md and every Markdown file under docs/."""
    named = [root / "README.md", root / "CHANGELOG.md"]
    return [path for path in named if path.exists()] + sorted((root / "docs").rglob("*.md"))


def top_level_entries(root: Path) -> set[str]:
    return {path.name for path in root.iterdir()} - RUNTIME_ENTRIES


def make_targets(root: Path) -> set[str]:
    makefile = (root / "Makefile").read_text(encoding="utf-8")
    targets = set()
    for match in re.finditer(r"^([A-Za-z0-9_. -]+?)\s*::?(?!=)", makefile, re.M):
        targets.update(name for name in match.group(1).split() if not name.startswith("."))
    return targets


def management_commands(root: Path) -> set[str]:
    ours = {path.stem for path in root.glob("*/management/commands/*.py")}
    return (ours - {"__init__"}) | DJANGO_COMMANDS


def blanked(match: re.Match) -> str:
    """The match as spaces, its line breaks kept, so that offsets and line numbers hold."""
    return re.sub(r"[^\n]", " ", match.group(0))


def code_spans(text: str) -> Iterator[tuple[int, str, bool]]:
    """(offset, code, inline) for each fenced block and each inline code span of ``text``."""
    for match in FENCE.finditer(text):
        yield match.start(1), match.group(1), False
    for match in INLINE_CODE.finditer(FENCE.sub(blanked, text)):
        yield match.start(1), " ".join(match.group(1).split()), True


def path_problem(token: str, root: Path, entries: set[str]) -> str | None:
    """Why ``token``, a word of inline code, is a path of ours that does not exist (or None)."""
    token = token.strip("\"'()[],;.").split("::")[0]
    token = LINE_SUFFIX.sub("", token)
    if not token or any(mark in token for mark in "*?{<>…") or "..." in token:
        return None
    if token.split("/")[0] not in entries or token in FOREIGN_PATHS or "//" in token:
        return None
    if not (root / token).exists():
        return f"no such path: {token}"
    return None


def module_problem(module: str, root: Path, entries: set[str]) -> str | None:
    if module.split(".")[0] not in entries:
        return None  # a third party's: pytest, pip, celery, daphne...
    base = root.joinpath(*module.split("."))
    candidates = (base.with_suffix(".py"), base / "__init__.py", base / "__main__.py")
    if not any(candidate.exists() for candidate in candidates):
        return f"no such module: python -m {module}"
    return None


def packages(root: Path) -> set[str]:
    return {path.parent.name for path in root.glob("*/__init__.py")} - {"tests"}


def task_names(root: Path) -> set[str]:
    return {
        name
        for package in packages(root)
        for path in (root / package).rglob("tasks.py")
        for name in TASK_NAME.findall(path.read_text(encoding="utf-8"))
    }


def defines(source: str, name: str) -> bool:
    """Whether a module's ``source`` defines ``name`` at its top (a class, a function, an
    assignment or an import)."""
    word = re.escape(name)
    return bool(
        re.search(rf"^(?:class|def|async def) {word}\b|^{word}\s*[:=]", source, re.M)
        or re.search(rf"^(?:from \S+ )?import .*\b{word}\b", source, re.M)
    )


def dotted_problem(token: str, context: dict) -> str | None:
    """Why ``token`` (``jobs.shares.share_cores``) names nothing of ours, or None."""
    token = token.strip("\"'()[],;:").removesuffix("()")
    match = DOTTED.match(token)
    if not match or match.group(1) not in context["packages"] or token in context["tasks"]:
        return None
    if token.rsplit(".", 1)[1] in FILE_SUFFIXES:  # a file's name: `jobs.py`
        return None
    parts, root = token.split("."), context["root"]
    for length in range(len(parts), 0, -1):
        base = root.joinpath(*parts[:length])
        module = next(
            (p for p in (base.with_suffix(".py"), base / "__init__.py") if p.exists()), None
        )
        if module is None:
            continue
        if length == len(parts) or defines(module.read_text(encoding="utf-8"), parts[length]):
            return None
        break
    return f"no such module or name of ours: {token}"


def setting_problems(root: Path) -> list[str]:
    """Every environment variable the code reads that its doc does not name."""
    operating, testing = (
        path.read_text(encoding="utf-8") if path.exists() else ""
        for path in (root / "docs" / "operating.md", root / "docs" / "testing.md")
    )
    problems = []
    for package in SETTINGS_READERS:
        for path in sorted((root / package).rglob("*.py")):
            name = path.relative_to(root).as_posix()
            doc, where = (
                (testing, "docs/testing.md")
                if name == TEST_SETTINGS
                else (operating, "docs/operating.md")
            )
            for variable in SETTING_READ.findall(path.read_text(encoding="utf-8")):
                if variable not in doc:
                    problems.append(f"{name}: reads {variable}, which {where} does not name")
    return sorted(set(problems))


def heading_slugs(path: Path) -> set[str]:
    """The anchors GitHub gives the headings of a Markdown file."""
    slugs = set()
    for heading in HEADING.findall(path.read_text(encoding="utf-8")):
        text = re.sub(r"[`*_]|\[([^\]]*)\]\([^)]*\)", r"\1", heading).lower()
        slugs.add(re.sub(r"[^\w\- ]", "", text).replace(" ", "-"))
    return slugs


def link_problem(target: str, document: Path, root: Path) -> str | None:
    if re.match(r"[a-z]+:", target) or target.startswith("/"):
        return None  # a web address, mailto:, or a page of the running console
    name, _, anchor = target.partition("#")
    path = (document.parent / name).resolve() if name else document
    if not path.is_relative_to(root):
        return f"link leaves the repository: {target}"
    if not path.exists():
        return f"broken link: {target}"
    if anchor and path.suffix == ".md" and anchor not in heading_slugs(path):
        return f"no heading for the link's #{anchor}: {target}"
    return None


def code_problems(code: str, inline: bool, context: dict) -> Iterator[str]:
    """The problems of one code span: its paths (inline code only) and its commands."""
    root, entries = context["root"], context["entries"]
    if inline:
        for token in code.split():
            problem = path_problem(token, root, entries) or dotted_problem(token, context)
            if problem:
                yield problem
    for module, placeholder in PYTHON_MODULE.findall(code):
        problem = None if placeholder else module_problem(module, root, entries)
        if problem:
            yield problem
    for command in MANAGE_COMMAND.findall(code):
        if command not in context["commands"]:
            yield f"no such management command: manage.py {command}"
    for target in MAKE_TARGET.findall(code):
        if target not in context["targets"]:
            yield f"no such make target: make {target}"


def document_problems(document: Path, context: dict) -> Iterator[str]:
    root = context["root"]
    text = document.read_text(encoding="utf-8")
    name = document.relative_to(root)

    found = []
    for offset, code, inline in code_spans(text):
        found += [(offset, problem) for problem in code_problems(code, inline, context)]
    prose = INLINE_CODE.sub(blanked, FENCE.sub(blanked, text))
    for match in LINK.finditer(prose):
        problem = link_problem(match.group(1) or match.group(2), document, root)
        found += [(match.start(), problem)] if problem else []
    for offset, problem in sorted(found):
        yield f"{name}:{text.count(chr(10), 0, offset) + 1}: {problem}"


def find_problems(root: Path = ROOT) -> list[str]:
    """Every problem of every document, as ``file:line: what``."""
    context = {
        "root": root,
        "entries": top_level_entries(root),
        "targets": make_targets(root),
        "commands": management_commands(root),
        "packages": packages(root),
        "tasks": task_names(root),
    }
    found = [problem for doc in documents(root) for problem in document_problems(doc, context)]
    return found + setting_problems(root)


def main(argv: list[str] | None = None) -> int:
    problems = find_problems()
    for problem in problems:
        print(problem, file=sys.stderr)
    if problems:
        print(f"{len(problems)} problem(s) in the docs.", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
