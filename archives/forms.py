"""The import's forms: the archive and the name, then the preview's changes to confirm."""

from django import forms
from django.contrib.auth import get_user_model
from pitlane_client import drfc

from archives import imports
from archives.models import KeptUpload
from common.forms import RacerWords
from training import configuration
from training.forms import limit
from training.models import Track


class ModelImportForm(RacerWords, forms.Form):
    """The name first (checked before the archive is read, and in the browser as it is typed),
    then the archive, or the one the racer uploaded to an attempt that had to be corrected
    (``kept_upload``, named by the hidden ``kept`` token)."""

    name = forms.CharField(
        max_length=64,
        required=False,
        help_text="Leave empty to keep the archive's name. Letters, digits and hyphens.",
    )
    archive = forms.FileField(
        label="Archive (.tar.gz)",
        required=False,
        help_text="A Pitlane virtual model, or a model downloaded from DeepRacer.",
        widget=forms.FileInput(attrs={"accept": ".tar.gz,.tgz,.tar,application/gzip"}),
    )
    kept = forms.CharField(required=False, widget=forms.HiddenInput)

    def __init__(self, *args, owner, kept: KeptUpload | None = None, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.owner = owner
        self.kept_upload = kept

    def clean_name(self) -> str:
        name = self.cleaned_data["name"].strip()
        if name and (problem := configuration.name_problem(name, owner=self.owner)):
            raise forms.ValidationError(problem)
        return name

    def clean_archive(self):
        archive = self.cleaned_data["archive"]
        if archive is None:
            if self.kept_upload is None:
                raise forms.ValidationError(
                    "Choose the model's archive: a virtualmodel-<name>.tar.gz or a model "
                    "downloaded from DeepRacer."
                )
            return None
        if archive.size > imports.MAX_ARCHIVE:
            raise forms.ValidationError(f"The archive is over {imports.size(imports.MAX_ARCHIVE)}.")
        return archive

    def keep(self, kept: KeptUpload | None) -> None:
        """Show ``kept`` (or nothing) as the archive the next attempt uses."""
        self.kept_upload = kept
        self.data = self.data.copy()
        self.data["kept"] = kept.token if kept else ""


class ModelImportConfirmForm(RacerWords, forms.Form):
    """An import's preview (``imports.ImportPreview``): what the racer may change before the
    model is created and its training starts (``imports.PREVIEW_CHANGES``), checked again by the
    import as the create-model page checks them; the archive is the one kept (``kept``)."""

    name = forms.CharField(max_length=64, help_text="Letters, digits and hyphens.")
    track = forms.ModelChoiceField(
        queryset=Track.objects.all(),
        to_field_name="name",
        empty_label=None,
        error_messages={"required": "Choose a track.", "invalid_choice": "Choose a listed track."},
    )
    direction = forms.ChoiceField(
        choices=[("counterclockwise", "Counter-clockwise"), ("clockwise", "Clockwise")]
    )
    max_minutes = forms.IntegerField(
        label="Maximum training time [min]",
        help_text=f"{configuration.MINUTES[0]} to {configuration.MINUTES[1]} minutes of your "
        "monthly training time.",
    )
    kept = forms.CharField(widget=forms.HiddenInput)

    def __init__(self, *args, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        limit(self.fields["max_minutes"], *configuration.MINUTES, step=1)

    @classmethod
    def of(cls, preview: imports.ImportPreview, kept: KeptUpload) -> "ModelImportConfirmForm":
        """The preview's settings as the form's values, its problems on their fields."""
        settings = preview.settings
        form = cls({"kept": kept.token, **{key: settings[key] for key in imports.PREVIEW_CHANGES}})
        form.add_problems(preview.problems)
        return form

    def changes(self) -> dict:
        """The racer's changes that are valid (all of them once ``is_valid``)."""
        data = getattr(self, "cleaned_data", {})
        changes = {key: data[key] for key in imports.PREVIEW_CHANGES if key in data}
        if "track" in changes:
            changes["track"] = changes["track"].name
        return changes

    def add_problems(self, problems: dict[str, str]) -> None:
        """``imports.ImportPreview.problems`` on the fields they concern."""
        self.is_valid()
        for setting, message in problems.items():
            self.add_error(setting if setting in self.fields else None, message)


class BucketImportForm(RacerWords, forms.Form):
    """Staff's import from DeepRacer for Cloud's bucket (``archives.drfc_bucket``): the model's
    place, its name here, and the racer it is for."""

    url = forms.CharField(
        label="Model's place in S3",
        max_length=1024,
        widget=forms.TextInput(attrs={"placeholder": "s3://bucket/rl-deepracer-sagemaker"}),
        help_text="s3://&lt;DR_LOCAL_S3_BUCKET&gt;/&lt;DR_LOCAL_S3_MODEL_PREFIX&gt;, read with the "
        "console's keys for DeepRacer for Cloud's bucket (PITLANE_DRFC_S3_*).",
    )
    name = forms.CharField(
        max_length=64,
        required=False,
        help_text="Leave empty to keep DeepRacer's name. Letters, digits and hyphens.",
    )
    racer = forms.CharField(
        label="For the racer",
        max_length=150,
        required=False,
        help_text="Their login name; leave empty to import it as yours.",
    )

    def __init__(self, *args, staff, **kwargs) -> None:
        super().__init__(*args, **kwargs)
        self.staff = staff

    def clean_url(self) -> str:
        url = self.cleaned_data["url"].strip()
        try:
            drfc.parse_url(url)
        except drfc.DrfcUnreadable as unreadable:
            raise forms.ValidationError(str(unreadable)) from None
        return url

    def clean_racer(self):
        given = self.cleaned_data["racer"].strip()
        if not given:
            return self.staff
        racer = get_user_model().objects.filter(username=given, is_active=True).first()
        if racer is None:
            raise forms.ValidationError(f"No racer logs in as {given!r}.")
        return racer

    def clean(self) -> dict:
        data = super().clean()
        name, racer = (data.get("name") or "").strip(), data.get("racer")
        if name and racer and (problem := configuration.name_problem(name, owner=racer)):
            self.add_error("name", problem)
        data["name"] = name
        return data
