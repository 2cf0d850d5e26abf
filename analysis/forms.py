from __future__ import annotations

from django import forms
from django.contrib.auth.models import AbstractBaseUser

from common.forms import RacerWords
from training.models import RLModel
from training.rewards import MAX_SOURCE_SIZE
from training.selectors import reward_functions_for_racer

PASTED = ""
THE_MODELS_OWN = "model"


class RescoreForm(RacerWords, forms.Form):
    """Another reward function, and the iterations to score it over. The function is pasted, or
    chosen from what the racer has already written: the model's own, or one of their saved
    functions (looked up among theirs alone, so another racer's id is refused as unknown)."""

    saved = forms.ChoiceField(
        required=False,
        label="Start from",
        error_messages={
            "invalid_choice": "Choose the model's own reward function or one of "
            "your saved ones; that one is not in your library."
        },
    )
    reward_function = forms.CharField(
        strip=False,
        required=False,
        max_length=MAX_SOURCE_SIZE,
        widget=forms.Textarea(attrs={"rows": 14, "spellcheck": "false", "class": "code"}),
        error_messages={
            "max_length": f"A reward function is at most {MAX_SOURCE_SIZE:,} characters long.",
        },
    )
    first = forms.IntegerField(min_value=0, required=False, label="Score from iteration")
    last = forms.IntegerField(min_value=0, required=False, label="to iteration")

    def __init__(self, *args, owner: AbstractBaseUser, model: RLModel, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.sources = {THE_MODELS_OWN: model.reward_function} if model.trainable else {}
        library = list(reward_functions_for_racer(racer=owner))
        self.sources.update((str(function.pk), function.source) for function in library)
        choices = [(PASTED, "What I paste below")]
        if model.trainable:
            choices.append((THE_MODELS_OWN, f"{model.name}'s own (what it trained with)"))
        if library:
            saved = [(str(function.pk), function.name) for function in library]
            choices.append(("Your saved reward functions", saved))
        self.fields["saved"].choices = choices
        self.fields["saved"].initial = THE_MODELS_OWN if model.trainable else PASTED

    def clean(self) -> dict:
        cleaned = super().clean()
        chosen = cleaned.pop("saved", PASTED)
        if chosen:
            cleaned["reward_function"] = self.sources[chosen]
        elif not cleaned.get("reward_function") and "reward_function" not in self.errors:
            self.add_error(
                "reward_function", "Paste a reward function to score the recorded driving with."
            )
        return cleaned
