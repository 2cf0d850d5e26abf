import re

import pytest
from playwright.sync_api import Page, expect

from tests.browser.checks import page_problems
from tests.helpers.accounts import PASSWORD
from tests.helpers.browser import log_in
from tests.helpers.models import ready_model
from training import selectors
from training.models import RLModel
from training.rewards import EXAMPLES
from training.services import model_create

pytestmark = pytest.mark.django_db(transaction=True)


def test_a_racer_creates_a_model_with_a_generated_action_space(page: Page, alice, tracks):
    log_in(page, "alice", PASSWORD)
    page.goto("/models/")
    page.get_by_role("link", name="Create model").click()
    page.get_by_label("Name").fill("seven-steering")
    page.locator(".track-choice", has_text="Pitlane Oval").click()
    expect(page.locator("[data-actions] tr")).to_have_count(10)  # DeepRacer's default

    page.get_by_label("Steering angles").select_option("7")
    page.get_by_label("Speeds").select_option("1")
    page.get_by_label("Maximum speed [m/s]").fill("1.5")
    page.get_by_role("button", name="Generate the table").click()
    expect(page.locator("[data-actions] tr")).to_have_count(7)
    page.get_by_role("button", name="Remove").first.click()
    expect(page.locator("[data-actions] tr")).to_have_count(6)

    # SAC settings show only for SAC; a discrete action space goes with PPO.
    expect(page.get_by_label("SAC alpha (entropy)")).to_be_hidden()
    page.get_by_role("button", name="Create model and start training").click()

    expect(page.get_by_role("heading", name="seven-steering")).to_be_visible()
    expect(page.get_by_text("seven-steering is created; its training is queued.")).to_be_visible()
    model = RLModel.objects.get(name="seven-steering")
    assert model.track.name == "pitlane-oval"
    steering = [a["steering_angle"] for a in model.action_space]
    assert steering == [-20.0, -10.0, 0.0, 10.0, 20.0, 30.0]
    assert {a["speed"] for a in model.action_space} == {1.5}


def test_the_track_picker_narrows_sorts_and_chooses_a_one_way_deepracer_track(
    page: Page, alice, tracks
):
    log_in(page, "alice", PASSWORD)
    page.goto("/models/create/")
    page.get_by_label("Name").fill("yun-car")
    shown = page.locator(".track-choice:visible")
    expect(shown).to_have_count(len(tracks))
    page.get_by_role("searchbox", name="Find a track").fill("speedway 2022")
    found = [t for t in tracks if "speedway" in t.display_name.lower() and t.season == 2022]
    expect(shown).to_have_count(len(found))
    expect(page.locator("[data-track-count]")).to_have_text(f"{len(found)} of {len(tracks)} tracks")
    page.get_by_role("button", name="Length", exact=True).click()
    shortest_first = sorted(found, key=lambda t: (t.length_m, t.position))
    expect(shown.locator("strong")).to_have_text([t.display_name for t in shortest_first])

    page.get_by_role("searchbox", name="Find a track").fill("yun")
    page.locator(".track-choice", has_text="Yun Speedway").click()
    direction = page.get_by_label("Direction")
    expect(direction).to_have_value("clockwise")  # the only way it is driven
    expect(direction.locator("option[value=counterclockwise]")).to_be_disabled()
    page.get_by_role("button", name="Create model and start training").click()
    expect(page.get_by_text("yun-car is created; its training is queued.")).to_be_visible()
    model = RLModel.objects.get(name="yun-car")
    assert (model.track.name, model.direction) == ("Albert", "clockwise")


def test_the_tracks_lists_search_asks_the_server_again_and_widens_a_narrowed_list(
    page: Page, alice, tracks
):
    log_in(page, "alice", PASSWORD)
    page.goto("/models/?q=smile")
    shown = page.locator("[data-track-list] [data-track]:visible")
    expect(shown).to_have_count(1)
    expect(page.get_by_role("button", name="Find", exact=True)).to_be_visible()
    page.get_by_role("searchbox", name="Find a track").fill("speedway")
    page.get_by_role("searchbox", name="Find a track").press("Enter")
    expect(page).to_have_url(re.compile(r"q=speedway"))
    expect(shown).to_have_count(len(selectors.tracks_listed(search="speedway", sort="")))


def open_create_page(page: Page, name: str) -> None:
    log_in(page, "alice", PASSWORD)
    page.goto("/models/create/")
    page.get_by_label("Name").fill(name)


def field(page: Page, label: str):
    """The form field (label, input, its errors and help) that holds the input named ``label``."""
    return page.locator(".field").filter(has=page.get_by_label(label, exact=True))


def test_a_continuous_speed_too_high_is_named_under_the_highest_speed_and_nowhere_else(
    page: Page, alice, tracks
):
    open_create_page(page, "fast-sac")
    page.get_by_label("Continuous", exact=True).check()
    page.get_by_label("SAC", exact=True).check()
    page.get_by_label("Highest speed [m/s]").fill("100")
    page.get_by_role("button", name="Create model and start training").click()

    message = "The highest speed is 0.1 to 4 m/s, not 100."
    expect(field(page, "Highest speed [m/s]").locator(".field-error")).to_have_text(message)
    expect(page.locator(".field-error")).to_have_count(1)  # not under the steering, no SAC error
    expect(page.get_by_text("SAC needs a continuous action space")).to_have_count(0)
    expect(page.get_by_label("Highest speed [m/s]")).to_have_attribute("aria-invalid", "true")
    expect(page.get_by_label("Highest speed [m/s]")).to_have_value("100")  # kept as typed
    assert not RLModel.objects.exists()


def test_only_the_bad_cells_are_marked_each_named_by_the_number_its_row_shows(
    page: Page, alice, tracks
):
    open_create_page(page, "bad-cells")
    rows = page.locator("[data-actions] tr")
    expect(rows).to_have_count(10)
    expect(rows.nth(0).locator("td").first).to_have_text("0")  # numbered from 0, as DeepRacer
    page.get_by_label("Speed of action 4", exact=True).fill("9")
    page.get_by_label("Steering angle of action 2", exact=True).fill("")
    page.get_by_role("button", name="Create model and start training").click()

    bad_speed = page.get_by_label("Speed of action 4", exact=True)
    blank_steering = page.get_by_label("Steering angle of action 2", exact=True)
    expect(rows.nth(4).locator("td").first).to_have_text("4")
    expect(bad_speed).to_have_attribute("aria-invalid", "true")
    expect(bad_speed).to_have_accessible_description("Speed in action 4 is 0.1 to 4 m/s, not 9.")
    expect(blank_steering).to_have_attribute("aria-invalid", "true")
    expect(blank_steering).to_have_accessible_description(
        "Steering angle in action 2 is blank: enter -30 to 30 degrees."
    )
    expect(page.locator("[data-actions] [aria-invalid=true]")).to_have_count(2)
    expect(rows.nth(4).locator(".field-error")).to_have_text(
        "Speed in action 4 is 0.1 to 4 m/s, not 9."
    )
    expect(page.locator(".field-invalid")).to_have_count(0)  # no whole table in red

    bad_speed.fill("2")
    blank_steering.fill("5")
    blank_steering.press("Tab")  # a corrected cell loses its mark at once
    expect(page.locator("[data-actions] [aria-invalid=true]")).to_have_count(0)
    page.get_by_role("button", name="Create model and start training").click()
    expect(page.get_by_text("bad-cells is created; its training is queued.")).to_be_visible()
    model = RLModel.objects.get(name="bad-cells")
    assert model.action_space[2]["steering_angle"] == 5 and model.action_space[4]["speed"] == 2


def test_an_empty_action_table_is_refused(page: Page, alice, tracks):
    open_create_page(page, "no-actions")
    remove = page.get_by_role("button", name="Remove")
    while remove.count():
        remove.first.click()
    expect(page.locator("[data-actions] tr")).to_have_count(0)
    page.get_by_role("button", name="Create model and start training").click()

    expect(
        page.get_by_text("There are no actions: a discrete action space has 2 to 30.")
    ).to_be_visible()
    expect(page.locator("[data-actions] tr")).to_have_count(0)  # the table as it was sent
    assert not RLModel.objects.exists()


def test_a_clone_shows_what_it_keeps_locked_and_is_created_with_it(page: Page, alice, tracks):
    source = ready_model(alice)
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/create/?clone={source.pk}")
    expect(page.get_by_label("5-layer CNN")).to_be_disabled()
    expect(page.get_by_label("SAC", exact=True)).to_be_disabled()
    expect(page.get_by_label("Continuous", exact=True)).to_be_disabled()
    expect(page.get_by_label("Stereo cameras")).to_be_disabled()
    expect(page.get_by_text("Locked: a clone keeps straight-ahead's network")).to_be_visible()
    expect(page.get_by_role("button", name="Add an action")).to_have_count(0)
    expect(page.get_by_role("button", name="Remove")).to_have_count(0)
    page.get_by_label("Speed of action 1", exact=True).fill("1.5")
    page.get_by_role("button", name="Create model and start training").click()

    expect(page.get_by_text("straight-ahead-clone is cloned from straight-ahead")).to_be_visible()
    clone = RLModel.objects.get(name="straight-ahead-clone")
    assert (clone.network, clone.sensors) == (source.network, source.sensors)
    assert [a["speed"] for a in clone.action_space] == [4.0, 1.5, 4.0]


def test_the_evaluate_page_shows_only_the_chosen_race_types_settings(page: Page, alice, tracks):
    model = ready_model(alice)
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{model.pk}/evaluate/")
    boxes, bots = page.get_by_label("Boxes", exact=True), page.get_by_label("Bot cars", exact=True)
    expect(boxes).to_be_hidden()
    expect(bots).to_be_hidden()
    page.get_by_label("Object avoidance").check()
    expect(boxes).to_be_visible()
    expect(bots).to_be_hidden()
    page.get_by_label("Head-to-bot").check()
    expect(boxes).to_be_hidden()
    expect(bots).to_be_visible()
    expect(page.get_by_label("Bot car speed [m/s]")).to_have_attribute("max", "6.0")


def test_a_refused_model_names_the_sections_to_fix_and_links_to_each(page: Page, alice, tracks):
    open_create_page(page, "")
    page.get_by_label("Maximum training time [min]").fill("")
    page.locator(".CodeMirror").evaluate("e => e.CodeMirror.setValue('')")
    page.get_by_role("button", name="Create model and start training").click()

    summary = page.locator("[data-error-summary]")
    expect(summary).to_be_focused()  # a screen reader reads it first
    links = summary.get_by_role("link")
    expect(links).to_have_text(["Name", "Stop condition and workers", "Reward function"])
    assert page_problems(page) == []  # the links read well on the summary's red wash
    links.last.click()
    expect(page).to_have_url(re.compile("#section-reward-function$"))
    expect(page.get_by_role("heading", name="8. Reward function")).to_be_in_viewport()
    for anchor in links.evaluate_all("links => links.map((link) => link.hash)"):
        expect(page.locator(anchor)).to_have_count(1)


def test_the_action_table_fits_a_phone_with_every_value_whole(page: Page, alice, tracks):
    page.set_viewport_size({"width": 390, "height": 844})
    open_create_page(page, "phone-actions")
    page.get_by_label("Speed of action 0", exact=True).fill("1.33")
    page.get_by_label("Steering angle of action 1", exact=True).fill("-22.5")
    cut = page.locator("[data-actions] input").evaluate_all(
        "inputs => inputs.filter((i) => i.scrollWidth > i.clientWidth).map((i) => i.value)"
    )
    assert cut == []
    for box in (b.bounding_box() for b in page.get_by_role("button", name="Remove").all()):
        assert box and box["x"] >= 0 and box["x"] + box["width"] <= 390, box
    assert page_problems(page) == []


def rays(page: Page):
    return page.locator("[data-action-fan] [data-action-ray]")


def left_of_the_car(page: Page, drawn) -> bool:
    """Whether ``drawn`` lies left of the car (up to its rounded line ends), well clear of it."""
    box = drawn.bounding_box()
    car = page.locator("[data-action-fan] .fan-car").bounding_box()
    centre = car["x"] + car["width"] / 2
    return box["x"] + box["width"] <= centre + 4 and box["x"] < centre - 40


def test_the_action_space_is_drawn_as_a_fan_that_follows_the_table(page: Page, alice, tracks):
    open_create_page(page, "fan")
    expect(rays(page)).to_have_count(10)  # DeepRacer's default: 5 angles at 2 speeds
    page.get_by_role("button", name="Add an action").click()
    expect(rays(page)).to_have_count(11)
    page.get_by_label("Steering angle of action 10", exact=True).fill("30")
    page.get_by_label("Steering angle of action 10", exact=True).press("Tab")
    assert left_of_the_car(page, page.locator('[data-action-fan] [data-action-ray="10"]'))
    page.get_by_role("button", name="Remove").first.click()
    expect(rays(page)).to_have_count(10)

    page.get_by_label("Continuous", exact=True).check()
    expect(rays(page)).to_have_count(0)
    sector = page.locator("[data-action-fan] [data-action-sector]")
    expect(sector).to_have_count(1)
    page.get_by_label("Lowest steering angle [°]").fill("0")
    expect(page.locator("[data-action-fan]")).to_have_attribute(
        "aria-label", "Action space fan: steering 0 to 30°, 1 to 2 m/s."
    )
    assert left_of_the_car(page, sector)  # 0 to 30°: all of it left


def test_the_model_page_draws_its_action_space(page: Page, alice, tracks):
    discrete = model_create(
        owner=alice,
        settings={
            "name": "three-rays",
            "track": "rookie-loop",
            "reward_function": EXAMPLES[0].source,
            "action_space": [{"steering_angle": a, "speed": 1} for a in (-20, 0, 20)],
        },
        validate_reward=False,
    )
    log_in(page, "alice", PASSWORD)
    page.goto(f"/models/{discrete.pk}/")
    expect(rays(page)).to_have_count(3)
    expect(page.locator("[data-action-fan]")).to_have_attribute(
        "aria-label", "Action space fan: 3 actions, 1 m/s."
    )
    assert left_of_the_car(page, page.locator('[data-action-fan] [data-action-ray="2"]'))

    continuous = model_create(
        owner=alice,
        settings={
            "name": "a-sector",
            "track": "rookie-loop",
            "reward_function": EXAMPLES[0].source,
            "action_space": {
                "steering_angle": {"low": 5, "high": 30},
                "speed": {"low": 1, "high": 3},
            },
        },
        validate_reward=False,
    )
    page.goto(f"/models/{continuous.pk}/")
    expect(rays(page)).to_have_count(0)
    expect(page.locator("[data-action-fan] [data-action-sector]")).to_have_count(1)
    assert left_of_the_car(page, page.locator("[data-action-fan] [data-action-sector]"))
