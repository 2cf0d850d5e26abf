"""A racer's steps in Chromium that several browser tests take."""

from playwright.sync_api import Locator, Page, expect

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


# What is drawn at the element's centre, when that is not the element or inside it ("" if it
# is); _DETACHED when the page replaced the element between its lookup and this check (its box is
# then all zeros, and the point it names is the window's corner: the site header).
_DETACHED = "detached"
_COVER = """element => {
  if (!element.isConnected) return "detached";
  const box = element.getBoundingClientRect();
  const top = document.elementFromPoint(box.left + box.width / 2, box.top + box.height / 2);
  if (top && (top === element || element.contains(top))) return "";
  return top ? top.outerHTML.slice(0, 160) : "nothing: it is outside the window";
}"""


def expect_seen(locator: Locator) -> None:
    """A person sees it: visible, in the window, and not covered by another layer at its
    centre (Playwright's visibility alone passes an element under an opaque overlay). An
    element the page replaced meanwhile is looked up again, as Playwright's own checks do."""
    expect(locator).to_be_visible()
    expect(locator).to_be_in_viewport()
    for _ in range(50):
        covered = locator.evaluate(_COVER)
        if covered != _DETACHED:
            break
    assert not covered, f"{locator} is covered by {covered}"
