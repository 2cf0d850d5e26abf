from __future__ import annotations

from django import forms

from common.forms import RacerWords
from training.rewards import MAX_SOURCE_SIZE


class RescoreForm(RacerWords, forms.Form):
    """Another reward function, and the iterations to score it over."""

    reward_function = forms.CharField(
        strip=False,
        max_length=MAX_SOURCE_SIZE,
        widget=forms.Textarea(attrs={"rows": 14, "spellcheck": "false", "class": "code"}),
        error_messages={
            "required": "Paste a reward function to score the recorded driving with.",
            "max_length": f"A reward function is at most {MAX_SOURCE_SIZE:,} characters long.",
        },
    )
    first = forms.IntegerField(min_value=0, required=False, label="Score from iteration")
    last = forms.IntegerField(min_value=0, required=False, label="to iteration")
