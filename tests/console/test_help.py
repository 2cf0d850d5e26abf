import re

import pytest
from django.urls import reverse

from rl.hyperparameters import SETTINGS
from training.rewards import PARAMS

pytestmark = pytest.mark.django_db

SECTIONS = (
    "race-types",
    "sensors",
    "networks",
    "action-space",
    "hyperparameters",
    "stop-condition",
    "reward-function",
    "evaluation",
    "league",
    "physical-car",
)


def test_the_help_page_is_public_and_has_every_section(client):
    response = client.get(reverse("help"))
    assert response.status_code == 200
    for section in SECTIONS:
        assert f'id="{section}"' in response.text, section
        assert f'href="#{section}"' in response.text, section  # in the page's contents


def test_the_help_page_is_linked_from_the_navigation_for_visitors_and_racers(client, alice):
    nav = re.compile(r'<ul class="nav-links">.*?<a href="/help/"[^>]*>Help</a>.*?</ul>', re.S)
    assert nav.search(client.get(reverse("home")).text)
    client.force_login(alice)
    assert nav.search(client.get(reverse("training:garage")).text)
    page = client.get(reverse("help"))
    assert '<a href="/help/" aria-current="page">Help</a>' in page.text


def test_every_hyperparameter_has_its_range_default_and_what_raising_it_does(client):
    text = client.get(reverse("help")).text
    for algorithm, settings in SETTINGS.items():
        for setting in settings:
            anchor = f"{algorithm}-{setting.name}".replace("_", "-")
            card = re.search(rf'id="{anchor}">(.*?)</div>', text, re.S)
            assert card, anchor
            assert setting.label in card.group(1)
    batch = re.search(r'id="clipped-ppo-batch-size">(.*?)</div>', text, re.S).group(1)
    assert "32, 64, 128, 256 or 512 · default 64" in batch
    learning_rate = re.search(r'id="clipped-ppo-lr">(.*?)</div>', text, re.S).group(1)
    assert "1e-8 to 0.001 · default 0.0003" in learning_rate
    assert "Raise it:" in learning_rate and "Lower it:" in learning_rate
    loss = re.search(r'id="clipped-ppo-loss-type">(.*?)</div>', text, re.S).group(1)
    assert "<strong>Huber:</strong>" in loss and "<strong>Mean squared error:</strong>" in loss
    alpha = re.search(r'id="sac-sac-alpha">(.*?)</div>', text, re.S).group(1)
    assert "0 to 1 · default 0.2" in alpha and "exploration" in alpha
    fixed = re.search(r'id="sac-num-episodes-between-training">(.*?)</div>', text, re.S).group(1)
    assert "1 only" in fixed and "Raise it" not in fixed  # nothing to tune


def test_the_discount_factor_says_how_far_ahead_the_car_looks(client):
    text = client.get(reverse("help")).text
    assert "<td>0.99</td><td>about 100</td><td>about 6.7 s</td>" in text
    assert "<td>0.999</td><td>about 1000</td><td>about 66.7 s</td>" in text


def test_the_help_page_lists_every_reward_param_and_links_the_editor(client):
    text = client.get(reverse("help")).text
    for name, _kind, _meaning in PARAMS:
        assert f'id="param-{name}"' in text, name
    assert f'href="{reverse("training:reward-editor")}"' in text


def test_the_help_page_says_how_to_get_a_model_onto_the_car(client):
    section = re.search(
        r'id="physical-car">(.*?)</section>', client.get(reverse("help")).text, re.S
    ).group(1)
    for words in (
        "physicalmodel-",
        "<strong>Models</strong>",
        "<strong>Upload</strong>",
        "<strong>Start vehicle</strong>",
        "<code>model_metadata.json</code>",
        "<code>agent/model.pb</code>",
        "<code>model.onnx</code>",
    ):
        assert words in section, words


def test_the_help_page_says_what_the_third_walk_changed(client):
    def section(name: str) -> str:
        page = client.get(reverse("help")).text
        return re.search(rf'id="{name}">(.*?)</section>', page, re.S).group(1)

    said = {
        "action-space": ("a fan from the car",),
        "stop-condition": ("<strong>Ready: not trained yet</strong>", "not race, download"),
        "evaluation": ("<strong>Stop evaluation</strong>",),
        "analysis": ("one of your saved ones",),
        "league": ("<strong>Watch</strong>", "give a reason"),
        "physical-car": ("exact figures", "driving model without training history"),
    }
    for name, words in said.items():
        for word in words:
            assert word in section(name), (name, word)


def test_the_create_form_links_to_the_help_on_its_settings(client, alice, tracks):
    client.force_login(alice)
    response = client.get(reverse("training:model-create"))
    assert f'href="{reverse("help")}#hyperparameters">What each setting means</a>' in response.text
