"""The racer's library of named reward functions: saved from the reward-function page, opened,
changed, deleted, and picked in the create-model form."""

import html
import json

import pytest
from django.urls import reverse

from training.models import RewardFunction
from training.rewards import EXAMPLES
from training.services import RewardFunctionInvalid, reward_function_delete, reward_function_save

pytestmark = pytest.mark.django_db

SPEEDY = "def reward_function(params):\n    return float(params['speed'])\n"
TYPO = "def reward_function(params):\n    return float(params['sped'])\n"


def save(owner, name="speedy", source=SPEEDY, **extra) -> RewardFunction:
    return reward_function_save(owner=owner, name=name, source=source, track="rookie-loop", **extra)


class TestTheServices:
    def test_a_racer_saves_a_validated_function_under_a_name(self, alice, tracks):
        function = save(alice, name="  Speedy   straights ")
        assert (function.owner, function.name, function.source) == (
            alice,
            "Speedy straights",
            SPEEDY,
        )

    def test_code_from_a_form_is_kept_with_the_editors_line_endings(self, alice, tracks):
        assert save(alice, source=SPEEDY.replace("\n", "\r\n")).source == SPEEDY

    @pytest.mark.slow
    def test_a_name_is_unique_per_racer_whatever_its_case(self, alice, bob, tracks):
        save(alice, name="Speedy")
        with pytest.raises(RewardFunctionInvalid) as refused:
            save(alice, name="speedy")
        assert refused.value.errors == {
            "name": "You already have a reward function named “speedy”; choose another name, "
            "or open that one from your list to change it."
        }
        assert save(bob, name="speedy").owner == bob  # another racer's name is no clash

    def test_code_with_errors_is_not_saved_and_says_what_to_fix(self, alice, tracks):
        with pytest.raises(RewardFunctionInvalid) as refused:
            save(alice, source=TYPO)
        assert refused.value.errors == {"source": "It was not saved: the code has 1 error to fix."}
        (error,) = refused.value.validation.errors
        assert (error.line, error.message) == (2, "params has no key 'sped'; did you mean 'speed'?")
        assert not RewardFunction.objects.exists()

    def test_a_function_needs_a_name_and_code(self, alice, tracks):
        with pytest.raises(RewardFunctionInvalid) as refused:
            save(alice, name=" ", source="  ")
        assert refused.value.errors == {
            "name": "Name your reward function to save it.",
            "source": "Write a reward function first.",
        }

    def test_saving_an_opened_function_changes_it_and_may_rename_it(self, alice, tracks):
        function = save(alice, name="speedy")
        changed = save(alice, name="Speedy", source=EXAMPLES[1].source, reward_function=function)
        assert changed.pk == function.pk
        function.refresh_from_db()
        assert (function.name, function.source) == ("Speedy", EXAMPLES[1].source)

    def test_it_will_not_change_another_racers_function(self, alice, bob, tracks):
        function = save(alice)
        with pytest.raises(RewardFunctionInvalid):
            save(bob, name="mine now", reward_function=function)
        function.refresh_from_db()
        assert function.name == "speedy"

    def test_deleting_takes_it_out_of_the_library(self, alice, tracks):
        reward_function_delete(reward_function=save(alice))
        assert not RewardFunction.objects.exists()


def post_save(client, pk=None, **data):
    url = (
        reverse("training:reward-function", args=[pk]) if pk else reverse("training:reward-editor")
    )
    return client.post(url, {"name": "speedy", "source": SPEEDY, "track": "rookie-loop", **data})


class TestThePages:
    def test_saving_opens_the_saved_function_and_lists_it(self, client, alice, tracks):
        client.force_login(alice)
        response = post_save(client)
        function = RewardFunction.objects.get(owner=alice)
        assert response.url == reverse("training:reward-function", args=[function.pk])
        page = client.get(response.url)
        assert "Saved “speedy”." in page.text
        assert "Reward function: speedy" in page.text
        assert html.escape(SPEEDY) in page.text
        assert f'href="/models/create/?reward={function.pk}"' in page.text

    def test_save_and_create_a_model_opens_the_form_with_its_code(self, client, alice, tracks):
        client.force_login(alice)
        response = post_save(client, then="create")
        function = RewardFunction.objects.get(owner=alice)
        assert response.url == f"{reverse('training:model-create')}?reward={function.pk}"
        form = client.get(response.url)
        assert form.status_code == 200
        assert html.escape(SPEEDY) in form.text
        assert html.escape(EXAMPLES[0].source) not in form.text.split("reward-examples")[0]
        assert f'value="saved:{function.pk}" selected' in form.text

    def test_a_refused_save_keeps_the_code_and_the_name_and_shows_the_problems(
        self, client, alice, tracks
    ):
        client.force_login(alice)
        response = post_save(client, source=TYPO, name="typo", track="speedway")
        assert response.status_code == 400
        assert "the code has 1 error to fix" in response.text
        assert html.escape(TYPO) in response.text
        assert 'value="typo"' in response.text
        assert 'value="speedway" selected' in response.text
        result = json.loads(
            response.text.split('id="reward-validation-result" type="application/json">')[1].split(
                "</script>"
            )[0]
        )
        assert result["errors"][0]["line"] == 2

    def test_a_taken_name_is_said_on_the_name(self, client, alice, tracks):
        client.force_login(alice)
        post_save(client)
        response = post_save(client, name="Speedy")
        assert response.status_code == 400
        assert "You already have a reward function named “Speedy”" in html.unescape(response.text)

    def test_changes_to_an_opened_function_are_saved_on_it(self, client, alice, tracks):
        client.force_login(alice)
        function = save(alice)
        post_save(client, pk=function.pk, name="speedy", source=EXAMPLES[2].source)
        function.refresh_from_db()
        assert function.source == EXAMPLES[2].source
        assert RewardFunction.objects.count() == 1

    def test_delete_asks_first_then_deletes(self, client, alice, tracks):
        client.force_login(alice)
        function = save(alice)
        url = reverse("training:reward-function-delete", args=[function.pk])
        assert "Delete the reward function “speedy”?" in html.unescape(client.get(url).text)
        assert RewardFunction.objects.exists()
        response = client.post(url)
        assert response.url == reverse("training:reward-editor")
        assert not RewardFunction.objects.exists()

    def test_another_racers_function_is_not_found_anywhere(self, client, alice, bob, tracks):
        function = save(alice)
        client.force_login(bob)
        for response in (
            client.get(reverse("training:reward-function", args=[function.pk])),
            post_save(client, pk=function.pk, name="mine"),
            client.get(reverse("training:reward-function-delete", args=[function.pk])),
            client.post(reverse("training:reward-function-delete", args=[function.pk])),
            client.get(f"{reverse('training:model-create')}?reward={function.pk}"),
        ):
            assert response.status_code == 404
        function.refresh_from_db()
        assert function.name == "speedy"
        listing = client.get(reverse("training:reward-editor")).text
        assert "speedy" not in listing
        assert "speedy" not in client.get(reverse("training:model-create")).text

    def test_the_create_form_offers_the_racers_functions_and_the_examples(
        self, client, alice, tracks
    ):
        client.force_login(alice)
        function = save(alice)
        response = client.get(reverse("training:model-create"))
        assert f'<option value="saved:{function.pk}">speedy</option>' in response.text
        for example in EXAMPLES:
            assert f'<option value="example:{example.slug}">{example.title}</option>' in (
                response.text
            )
        sources = json.loads(
            response.text.split('id="reward-library" type="application/json">')[1].split(
                "</script>"
            )[0]
        )
        assert sources == {str(function.pk): SPEEDY}

    def test_the_library_is_for_racers_only(self, client, alice, tracks):
        function = save(alice)
        for url in (
            reverse("training:reward-function", args=[function.pk]),
            reverse("training:reward-function-delete", args=[function.pk]),
        ):
            assert client.get(url).status_code == 302
