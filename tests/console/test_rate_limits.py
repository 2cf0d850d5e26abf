"""Rate limits: past each, the page answers 429 and says how long to wait, and nothing is done.
Counted in the suite's real Redis, as in production."""

import pytest
from django.contrib.auth.models import User
from django.urls import reverse

from tests.helpers.accounts import PASSWORD
from tests.helpers.models import trained_model
from training import services
from training.models import EvaluationJob, RewardFunction, RLModel

pytestmark = pytest.mark.django_db


@pytest.fixture
def rates(settings):
    """Every rate at 2 per 15 minutes, for the test to change."""
    settings.PITLANE_RATES = dict.fromkeys(settings.PITLANE_RATES, "2/15m")
    return settings.PITLANE_RATES


def assert_waits(response, at_most: int = 15 * 60) -> None:
    """The refusal says in ``Retry-After`` how many seconds to wait: no more than the window."""
    assert 1 <= int(response.headers["Retry-After"]) <= at_most


def sign_in(client, username: str, password: str):
    return client.post(reverse("login"), {"username": username, "password": password})


def test_wrong_passwords_for_one_racer_end_in_a_wait_even_for_the_right_one(alice, client, rates):
    rates["sign-in-address"] = "100/15m"
    for _ in range(2):
        assert sign_in(client, "alice", "wrong password").status_code == 200
    response = sign_in(client, "alice", PASSWORD)
    assert response.status_code == 429
    assert_waits(response)
    assert "Too many sign-in attempts for this racer for now: try again in" in response.text
    assert "minute" in response.text
    assert "_auth_user_id" not in client.session
    # Another racer from elsewhere is not held up by alice's limit.
    other = client_from("10.0.0.9")
    assert sign_in(other, "bob", PASSWORD).status_code in (200, 302)


def client_from(address: str):
    from django.test import Client

    return Client(REMOTE_ADDR=address)


def test_one_address_trying_many_racers_ends_in_a_wait(alice, bob, stella, client, rates):
    rates["sign-in-account"] = "100/15m"
    assert sign_in(client, "alice", "wrong").status_code == 200
    assert sign_in(client, "bob", "wrong").status_code == 200
    response = sign_in(client, "stella", PASSWORD)
    assert response.status_code == 429
    assert_waits(response)
    assert "Too many sign-in attempts from your address" in response.text
    assert sign_in(client_from("10.0.0.7"), "stella", PASSWORD).status_code == 302


@pytest.mark.slow  # 40 sign-ins: 3 s
def test_it_lets_a_race_day_behind_one_address_sign_in_as_often_as_it_succeeds(
    alice, bob, client, rates
):
    # Only failed sign-ins count: 40 right passwords from one address (a paddock behind one NAT)
    # against limits of 2 all get in; then failures from it still end in a wait.
    for attempt in range(40):
        other = client_from("127.0.0.1")
        assert sign_in(other, ("alice", "bob")[attempt % 2], PASSWORD).status_code == 302
        assert "_auth_user_id" in other.session
    assert sign_in(client, "alice", "wrong").status_code == 200
    assert sign_in(client, "bob", "wrong").status_code == 200
    response = sign_in(client, "bob", PASSWORD)
    assert response.status_code == 429
    assert "Too many sign-in attempts from your address" in response.text


def test_sign_ups_from_one_address_are_limited(client, rates):
    for n in range(2):
        client.post(
            reverse("signup"), {"username": f"racer{n}", "password1": "x", "password2": "y"}
        )
    response = client.post(
        reverse("signup"),
        {
            "username": "racer9",
            "password1": PASSWORD,
            "password2": PASSWORD,
        },
    )
    assert response.status_code == 429
    assert_waits(response)
    assert "Too many new accounts from your address" in response.text
    assert not User.objects.filter(username="racer9").exists()


def test_reward_checks_are_limited_per_racer(alice, bob, client, rates):
    client.force_login(alice)
    for _ in range(2):
        assert client.post(reverse("training:reward-validation"), {}).status_code == 400
    response = client.post(reverse("training:reward-validation"), {})
    assert response.status_code == 429
    assert_waits(response)
    assert response.json()["message"].startswith("Too many reward function checks for now")
    client.force_login(bob)  # each racer counts alone
    assert client.post(reverse("training:reward-validation"), {}).status_code == 400
    # Saving runs the same check, and counts with Validate: bob has one left.
    save = {"name": "mine", "source": "def reward_function(params):\n    return 1.0\n"}
    assert client.post(reverse("training:reward-editor"), save).status_code == 400  # no track
    response = client.post(reverse("training:reward-editor"), {**save, "track": "rookie-loop"})
    assert response.status_code == 429
    assert_waits(response)
    assert "Too many reward function checks for now: try again in" in response.text
    assert "mine" in response.text  # what the racer typed stays
    assert not RewardFunction.objects.exists()


def test_new_models_and_imports_are_limited_per_racer(alice, client, rates):
    client.force_login(alice)
    for page, what in (
        ("training:model-create", "new models"),
        ("archives:model-import", "refused or unconfirmed imports"),  # see test_import_archives
    ):
        for _ in range(2):
            assert client.post(reverse(page), {"name": ""}).status_code == 400
        response = client.post(reverse(page), {"name": ""})
        assert response.status_code == 429, page
        assert_waits(response)
        assert f"Too many {what} for now: try again in" in response.text
    assert not RLModel.objects.exists()


def test_evaluations_and_race_entries_share_a_limit(alice, client, rates, tracks):
    model = trained_model(alice, "limited")
    client.force_login(alice)
    page = reverse("training:evaluation-create", args=[model.pk])
    assert client.post(page, {"track": ""}).status_code == 400
    assert client.post(reverse("racing:submission-create"), {}).status_code == 200
    response = client.post(page, {"track": ""})
    assert response.status_code == 429
    assert_waits(response)
    assert "Too many evaluations and race entries for now" in response.text
    response = client.post(reverse("racing:submission-create"), {})
    assert response.status_code == 429
    assert_waits(response)
    assert not EvaluationJob.objects.exists()


def test_a_racer_has_at_most_so_many_evaluations_waiting(alice, bob, settings, tracks):
    settings.PITLANE_MAX_QUEUED_EVALUATIONS = 2
    models = [trained_model(alice, f"model-{n}") for n in range(3)]
    for model in models[:2]:
        services.evaluation_start(model=model, settings={}, enqueue=False)
    with pytest.raises(services.EvaluationRefused, match="You have 2 evaluations and race"):
        services.evaluation_start(model=models[2], settings={}, enqueue=False)
    # Another racer's queue is their own.
    services.evaluation_start(model=trained_model(bob, "bobs"), settings={}, enqueue=False)


@pytest.fixture
def cache_unreachable(settings):
    """The rate limits' cache (Redis) on a port where nothing listens."""
    settings.CACHES = {
        "default": {**settings.CACHES["default"], "LOCATION": "redis://127.0.0.1:1/0"}
    }


def test_sign_in_and_sign_up_are_refused_while_attempts_cannot_be_counted(
    alice, client, cache_unreachable
):
    response = sign_in(client, "alice", PASSWORD)
    assert response.status_code == 503
    assert "Signing in is paused for a moment" in response.text
    assert "try again in a moment" in response.text
    assert_waits(response, at_most=60)
    assert "_auth_user_id" not in client.session
    response = client.post(
        reverse("signup"),
        {
            "username": "racer9",
            "password1": PASSWORD,
            "password2": PASSWORD,
        },
    )
    assert response.status_code == 503
    assert "Signing up is paused for a moment" in response.text
    assert_waits(response, at_most=60)
    assert not User.objects.filter(username="racer9").exists()


def test_a_signed_in_racers_work_goes_on_while_attempts_cannot_be_counted(
    alice, client, cache_unreachable
):
    client.force_login(alice)
    response = client.post(reverse("training:model-create"), {"name": ""})
    assert response.status_code == 400  # the form's own errors: not refused
