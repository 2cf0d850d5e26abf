"""What every page must pass, measured in the browser: readable contrast, and no page wider than
the window (wide tables scroll inside their own box)."""

from __future__ import annotations

from pathlib import Path

from playwright.sync_api import Page

SCRIPT = (Path(__file__).parent / "checks.js").read_text()


def page_problems(page: Page) -> list[str]:
    """What is wrong with the page as it is now: text too faint to read, a page wider than the
    window. An empty list when all is well."""
    page.add_script_tag(content=SCRIPT)
    failures = page.evaluate("window.pitlaneContrastFailures()")
    problems = [f"{page.url}: low contrast: {failure}" for failure in failures]
    wider, culprits = page.evaluate("window.pitlaneOverflow()")
    if wider > 0:
        problems.append(f"{page.url}: the page is {wider} px wider than the window: {culprits}")
    return problems
