"""A racer's steps in Chromium that several browser tests take."""

from playwright.sync_api import Page

from tests.helpers.accounts import PASSWORD

# The live frame's bytes, read in the page: ``frame.evaluate(FRAME_BYTES)``.
FRAME_BYTES = (
    "img => fetch(img.src).then(r => r.arrayBuffer()).then(b => Array.from(new Uint8Array(b)))"
)


def log_in(page: Page, username: str, password: str) -> None:
    page.goto("/accounts/login/")
    page.get_by_label("Login name").fill(username)
    page.get_by_label("Password").fill(password)
    page.get_by_role("button", name="Log in").click()


def sign_up(page: Page, username: str) -> None:
    """From the home page, as a visitor finds it."""
    page.get_by_role("link", name="Create your racer account").click()
    sign_up_here(page, username)


def sign_up_here(page: Page, username: str) -> None:
    """The sign-up form, on the page open now, filled in and sent."""
    page.get_by_label("Login name").fill(username)
    page.get_by_label("Password", exact=True).fill(PASSWORD)
    page.get_by_label("Password confirmation").fill(PASSWORD)
    page.get_by_role("button", name="Sign up").click()
