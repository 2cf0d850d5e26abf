import pytest
from django.core.exceptions import ImproperlyConfigured

from console.env import Env


def test_it_uses_the_default_when_a_variable_is_unset_or_blank():
    env = Env({"BLANK": "  "})
    assert env.str("UNSET", "fallback") == "fallback"
    assert env.int("BLANK", 7) == 7


def test_it_names_a_required_variable_that_is_missing():
    with pytest.raises(ImproperlyConfigured, match="DJANGO_ALLOWED_HOSTS must be set"):
        Env({}).list("DJANGO_ALLOWED_HOSTS")


@pytest.mark.parametrize(("raw", "expected"), [("1", True), ("Yes", True), ("off", False)])
def test_it_reads_booleans_in_the_usual_spellings(raw, expected):
    assert Env({"FLAG": raw}).bool("FLAG") is expected


def test_it_rejects_a_boolean_it_cannot_read():
    with pytest.raises(ImproperlyConfigured, match=r"DJANGO_DEBUG must be true or false.*'maybe'"):
        Env({"DJANGO_DEBUG": "maybe"}).bool("DJANGO_DEBUG")


def test_it_rejects_a_port_that_is_not_a_number_or_out_of_range():
    with pytest.raises(ImproperlyConfigured, match="PITLANE_PORT must be a whole number"):
        Env({"PITLANE_PORT": "eighty"}).int("PITLANE_PORT", minimum=1, maximum=65535)
    with pytest.raises(ImproperlyConfigured, match="between 1 and 65535, not 70000"):
        Env({"PITLANE_PORT": "70000"}).int("PITLANE_PORT", minimum=1, maximum=65535)


def test_it_splits_lists_on_commas():
    env = Env({"HOSTS": "pitlane.example, www.pitlane.example,,"})
    assert env.list("HOSTS") == ["pitlane.example", "www.pitlane.example"]


def test_it_rejects_a_url_with_the_wrong_scheme_without_showing_its_password():
    env = Env({"REDIS_URL": "http://user:hunter2@cache:6379"})
    with pytest.raises(ImproperlyConfigured, match="redis://") as raised:
        env.url("REDIS_URL", schemes=("redis", "rediss"))
    assert "hunter2" not in str(raised.value)


def test_it_accepts_a_postgres_url():
    url = "postgres://pitlane:secret@db:5432/pitlane"
    assert Env({"DATABASE_URL": url}).url("DATABASE_URL", schemes=("postgres",)) == url


@pytest.mark.parametrize("weak", ["short", "django-insecure-" + "x" * 50, "ab" * 30])
def test_it_rejects_a_weak_secret_key(weak):
    with pytest.raises(ImproperlyConfigured, match="at least 50 characters"):
        Env({"DJANGO_SECRET_KEY": weak}).secret_key("DJANGO_SECRET_KEY")


def test_it_takes_one_of_its_choices_in_any_case_and_names_them_when_refusing_another():
    assert (
        Env({"PITLANE_ROLLOUT_DEVICE": "CUDA"}).choice(
            "PITLANE_ROLLOUT_DEVICE", "auto", choices=("auto", "cpu", "cuda")
        )
        == "cuda"
    )
    assert Env({}).choice("PITLANE_ROLLOUT_DEVICE", "auto", choices=("auto", "cpu")) == "auto"
    with pytest.raises(ImproperlyConfigured, match=r"must be one of auto, cpu, cuda, not 'gpu'"):
        Env({"PITLANE_ROLLOUT_DEVICE": "gpu"}).choice(
            "PITLANE_ROLLOUT_DEVICE", "auto", choices=("auto", "cpu", "cuda")
        )
