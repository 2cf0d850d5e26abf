"""Personal access tokens and the API's first doors: a token is made on the profile page and
shown once, acts as its racer within its scopes, stops at its expiry, its revocation or its
account's end, never reaches another racer's models, and is counted against its rate; every
refusal is JSON with a code and words."""

from __future__ import annotations

import re
from datetime import timedelta

import pytest
from django.urls import reverse
from django.utils import timezone

from accounts.models import AccessToken, TokenScope
from accounts.tokens import token_create
from tests.helpers.accounts import racer
from tests.helpers.training import settings as training_settings
from training import configuration, services
from training.models import RLModel

ME, MODELS = "/api/v1/me", "/api/v1/models"


def a_model(owner, name: str) -> RLModel:
    checked = configuration.check(training_settings(name=name), owner=owner, validate_reward=False)
    return services.model_insert(owner=owner, settings=checked, status=RLModel.Status.READY)


def bearer(secret: str) -> dict[str, str]:
    return {"HTTP_AUTHORIZATION": f"Bearer {secret}"}


def secret_of(owner, *scopes: str, days: int = 30, name: str = "script") -> str:
    return token_create(owner=owner, name=name, scopes=list(scopes or ["read"]), days=days)[1]


def test_a_racer_makes_a_token_on_the_profile_page_sees_it_once_and_its_use_is_listed(
    alice, client
):
    client.force_login(alice)
    response = client.post(
        reverse("accounts:token-new"), {"name": "notebook", "scopes": ["read"], "days": "30"}
    )
    assert response.status_code == 201
    token = AccessToken.objects.get(owner=alice)
    page = response.text
    secret = re.search(r'value="(plt_[^"]+)"[^>]*data-secret', page).group(1)
    assert secret.startswith(token.prefix) and "not shown again" in page
    assert token.digest != secret and secret not in token.digest  # kept as its digest alone

    profile = client.get(reverse("accounts:profile")).text
    assert secret not in profile and token.prefix in profile and "never" in profile

    client.logout()
    answer = client.get(ME, **bearer(secret))
    assert answer.status_code == 200
    assert answer.json()["username"] == "alice" and answer.json()["scopes"] == ["read"]
    assert answer.json()["token"]["name"] == "notebook"
    client.force_login(alice)
    assert "never" not in client.get(reverse("accounts:profile")).text.split("data-token-list")[1]

    revoked = client.post(reverse("accounts:token-revoke", args=[token.pk]), follow=True)
    assert "Revoked notebook: it no longer works." in revoked.text
    # a token that no longer works is refused, even beside the racer's own session
    assert client.get(ME, **bearer(secret)).json()["code"] == "unauthenticated"
    assert client.get(ME).json()["token"] is None  # the session alone still works


@pytest.mark.parametrize(
    ("fields", "words"),
    [
        ({"name": "", "scopes": ["read"], "days": "30"}, "Give the token a name"),
        ({"name": "x", "days": "30"}, "Choose what the token may do"),
        ({"name": "x", "scopes": ["read"], "days": "10000"}, "how long the token lasts"),
        ({"name": "x", "scopes": ["admin"], "days": "30"}, "Choose what the token may do"),
    ],
)
def test_a_token_the_page_cannot_make_is_refused_in_words(alice, client, fields, words):
    client.force_login(alice)
    response = client.post(reverse("accounts:token-new"), fields)
    assert response.status_code == 400 and words in response.text.replace("&#x27;", "'")
    assert not AccessToken.objects.exists()


def test_a_token_stops_at_its_expiry_its_accounts_end_and_outside_its_scopes(alice, tracks, client):
    a_model(alice, "mine")
    train_only = secret_of(alice, "train", name="trainer")
    refused = client.get(MODELS, **bearer(train_only))
    assert refused.status_code == 403 and refused.json()["code"] == "scope"
    assert "read scope" in refused.json()["message"]

    expiring = secret_of(alice, "read", name="old")
    assert client.get(MODELS, **bearer(expiring)).status_code == 200
    AccessToken.objects.filter(name="old").update(expires_at=timezone.now() - timedelta(seconds=1))
    assert client.get(MODELS, **bearer(expiring)).status_code == 401

    reader = secret_of(alice, "read", name="reader")
    alice.is_active = False
    alice.save()
    assert client.get(MODELS, **bearer(reader)).status_code == 401
    for wrong in ("", "plt_short", "x" * 44, "plt_" + "A" * 40):
        answer = client.get(MODELS, **bearer(wrong))
        assert answer.status_code == 401 and answer.json()["code"] == "unauthenticated"


def test_staff_lose_a_tokens_admin_scope_when_they_stop_being_staff(stella, client):
    secret = secret_of(stella, "read", "admin")
    assert client.get(ME, **bearer(secret)).json()["scopes"] == ["admin", "read"]
    stella.is_staff = False
    stella.save()
    assert client.get(ME, **bearer(secret)).json()["scopes"] == ["read"]


def test_a_racers_token_never_reaches_another_racers_models(alice, bob, tracks, client):
    hers = a_model(alice, "hers")
    his = a_model(bob, "his")
    secret = secret_of(bob, "read")
    listed = client.get(MODELS, **bearer(secret)).json()
    assert listed["count"] == 1 and [item["id"] for item in listed["items"]] == [his.pk]
    for model_id in (hers.pk, 10**9):
        answer = client.get(f"{MODELS}/{model_id}", **bearer(secret))
        assert answer.status_code == 404 and answer.json()["code"] == "not_found"
    detail = client.get(f"{MODELS}/{his.pk}", **bearer(secret)).json()
    assert detail["name"] == "his" and detail["track"] == "pitlane-oval"
    assert detail["checkpoints"] == {"best": None, "last": None, "iterations": 0}


def test_the_models_filters_and_pages_and_bad_input_is_json_words(alice, tracks, client):
    for name in ("alpha", "beta", "gamma"):
        a_model(alice, name)
    secret = secret_of(alice, "read")
    page = client.get(MODELS, {"limit": 2, "offset": 1}, **bearer(secret)).json()
    assert page["count"] == 3 and [m["name"] for m in page["items"]] == ["beta", "alpha"]
    assert client.get(MODELS, {"q": "amm"}, **bearer(secret)).json()["items"][0]["name"] == "gamma"
    assert client.get(MODELS, {"status": "TRAINING"}, **bearer(secret)).json()["count"] == 0
    for query in ({"limit": 0}, {"limit": "many"}, {"status": "FLYING"}):
        answer = client.get(MODELS, query, **bearer(secret))
        assert answer.status_code == 400, query
        assert answer.json()["code"] in {"invalid", "refused"} and answer.json()["message"]
    assert client.get(f"{MODELS}/not-a-number", **bearer(secret)).status_code == 400


def test_a_tokens_requests_past_its_rate_are_refused_with_retry_after(alice, client, settings):
    settings.PITLANE_RATES = {**settings.PITLANE_RATES, "api": "3/m"}
    secret = secret_of(alice, "read")
    assert [client.get(ME, **bearer(secret)).status_code for _ in range(3)] == [200] * 3
    refused = client.get(ME, **bearer(secret))
    assert refused.status_code == 429 and refused.json()["code"] == "rate_limited"
    assert int(refused["Retry-After"]) >= 1 and "API requests" in refused.json()["message"]
    other = secret_of(alice, "read", name="another")  # each token has its own count
    assert client.get(ME, **bearer(other)).status_code == 200


def test_the_openapi_document_and_its_reference_are_served_from_our_own_files(client, alice):
    document = client.get("/api/v1/schema")
    assert document.status_code == 200
    schema = document.json()
    assert schema["openapi"].startswith("3.") and schema["info"]["title"] == "Pitlane API"
    assert {"/api/v1/me", "/api/v1/models", "/api/v1/models/{model_id}"} <= set(schema["paths"])
    client.force_login(alice)
    reference = client.get("/api/v1/docs")
    assert reference.status_code == 200 and "/static/ninja/swagger-ui-bundle.js" in reference.text
    assert "cdn" not in reference.text.lower()


def test_the_scopes_on_the_page_are_the_tokens_scopes():
    assert set(TokenScope.values) == {"read", "train", "race", "admin"}


def test_an_administrator_sees_racers_tokens_without_their_secrets_and_revokes_one(
    alice, stella, client
):
    secret = secret_of(alice, "read", name="leaked")
    client.force_login(stella)  # league staff, without the right to racers' accounts
    assert client.get("/admin/accounts/accesstoken/").status_code == 403
    client.force_login(racer("root", is_staff=True, is_superuser=True))
    listing = client.get("/admin/accounts/accesstoken/")
    assert listing.status_code == 200 and "leaked" in listing.text and secret not in listing.text
    token = AccessToken.objects.get(name="leaked")
    client.post(
        "/admin/accounts/accesstoken/",
        {"action": "revoke", "_selected_action": [token.pk]},
    )
    token.refresh_from_db()
    assert token.revoked_at is not None
    client.logout()
    assert client.get(ME, **bearer(secret)).status_code == 401
    assert client.get("/admin/accounts/accesstoken/add/").status_code == 302  # to the login
