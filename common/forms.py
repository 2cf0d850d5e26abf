"""The site's own words for a form's everyday mistakes, in place of Django's defaults ("This
field is required.", "Ensure this value has at most 64 characters (it has 70)."): each names
the field and says what it takes. Every form of the site gets them in one way: it mixes
``RacerWords`` in before the Django form it extends (``class VehicleForm(RacerWords,
forms.ModelForm)``, ``class SignUpForm(RacerWords, UserCreationForm)``); a test walks the site's
forms and holds them to it. A message a form or a field sets for itself is kept; only Django's
defaults are replaced."""

from __future__ import annotations

from decimal import Decimal

from django import forms
from django.forms.utils import pretty_name


class RacerWords:
    """A form mixin: before the form is cleaned, each field's default messages become the
    site's (fields a form adds in its ``__init__`` included)."""

    fields: dict[str, forms.Field]

    def full_clean(self) -> None:
        for name, field in self.fields.items():
            reword(field, name)
        super().full_clean()  # type: ignore[misc]


def reword(field: forms.Field, name: str) -> None:
    """Put the site's words in ``field``'s error messages wherever Django's own stand."""
    defaults: dict = {}
    for klass in reversed(type(field).__mro__):
        defaults.update(getattr(klass, "default_error_messages", {}))
    for code, text in words(field, _subject(field.label or pretty_name(name))).items():
        current = field.error_messages.get(code)
        if current is None or str(current) == str(defaults.get(code)):
            field.error_messages[code] = text


def words(field: forms.Field, label: str) -> dict[str, str]:
    """The site's message for each of Django's error codes that ``field`` can raise. The limits
    come from the error itself (``%(limit_value)s``, ``%(show_value)d``), so a limit the model
    sets (a validator on the model's field, checked when a model form is cleaned) is said too."""
    said = {"required": f"{label} is needed."}
    if isinstance(field, forms.ChoiceField | forms.ModelChoiceField):
        said["invalid_choice"] = f"{label}: choose one of those listed."
    if isinstance(field, forms.FileField):
        said["required"] = f"{label}: choose a file."
        said["empty"] = f"{label}: the file chosen is empty."
        # Django raises this one with {"max", "length"}, not a validator's limit_value.
        said["max_length"] = (
            f"{label}: its name is at most %(max)d characters; this one has %(length)d."
        )
    elif invalid := _invalid(field, label):
        said["invalid"] = invalid
    if isinstance(field, forms.CharField):
        for code, what in (("max_length", "at most"), ("min_length", "at least")):
            said[code] = (
                f"{label} is {what} %(limit_value)d characters long; this one has %(show_value)d."
            )
    if isinstance(field, forms.IntegerField | forms.FloatField | forms.DecimalField):
        for code, what in (
            ("max_value", "at most"),
            ("min_value", "at least"),
            ("step_size", "in steps of"),
        ):
            said[code] = f"{label} is {what} {_limit(getattr(field, code))}."
    if isinstance(field, forms.DecimalField):
        said["max_digits"] = f"{label} has at most %(max)s digits."
        said["max_decimal_places"] = f"{label} has at most %(max)s decimal places."
        said["max_whole_digits"] = f"{label} is too large."
    return {code: _escaped(text) if code in FORMATTED else text for code, text in said.items()}


# The codes whose message Django formats with the error's params (a "%" of a label doubled).
FORMATTED = {
    "invalid_choice",
    "max_length",
    "min_length",
    "max_value",
    "min_value",
    "step_size",
    "max_digits",
    "max_decimal_places",
    "max_whole_digits",
}
PLACEHOLDERS = (
    "%(limit_value)d",
    "%(limit_value)s",
    "%(show_value)d",
    "%(max)s",
    "%(max)d",
    "%(length)d",
)


def _escaped(text: str) -> str:
    """``text`` with a label's "%" doubled and Django's placeholders kept."""
    doubled = text.replace("%", "%%")
    for placeholder in PLACEHOLDERS:
        doubled = doubled.replace("%" + placeholder, placeholder)
    return doubled


def _invalid(field: forms.Field, label: str) -> str | None:
    if isinstance(field, forms.FloatField | forms.DecimalField):
        return f"{label} is a number, such as 2.5."
    if isinstance(field, forms.IntegerField):
        return f"{label} is a whole number."
    if isinstance(field, forms.DateTimeField):
        return f"{label} is a date and a time of day."
    if isinstance(field, forms.DateField):
        return f"{label} is a date."
    if isinstance(field, forms.EmailField):
        return f"{label} is an email address, such as racer@example.com."
    if isinstance(field, forms.JSONField):
        return f"{label} is not readable JSON."
    return None


def _subject(label: str) -> str:
    label = str(label).strip().rstrip(":")
    return label[:1].upper() + label[1:]


def _limit(value: object) -> str:
    """A number field's own limit as written (6, not 6.0); the error's, for a limit only the
    model's validators know."""
    if isinstance(value, int | float | Decimal) and not isinstance(value, bool):
        return f"{value:,}" if isinstance(value, int) else f"{value:g}"
    return "%(limit_value)s"
