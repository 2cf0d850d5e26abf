from django import forms
from django.contrib import admin, messages
from django.urls import reverse
from django.utils.html import format_html

from training.models import (
    Direction,
    Quota,
    QuotaDefaults,
    RewardFunction,
    RLModel,
    Track,
    TrainingJob,
    Vehicle,
)
from training.services import (
    ROUTE_MAX_BYTES,
    TrackRefused,
    track_add,
    track_check,
    training_stop,
)


class TrackUploadForm(forms.ModelForm):
    """Add a track from a DeepRacer route file; checked and stored by ``track_add``."""

    route_file = forms.FileField(
        label="Route file (.npy)",
        help_text="A DeepRacer route file: one row per waypoint with centre x, centre y, inner "
        "border x, inner border y, outer border x and outer border y, in metres.",
    )
    directions = forms.MultipleChoiceField(
        choices=Direction.choices,
        initial=[d.value for d in Direction],
        widget=forms.CheckboxSelectMultiple,
        help_text="The directions racers may drive it.",
    )

    class Meta:
        model = Track
        fields = ["name", "display_name", "description", "difficulty"]
        help_texts = {
            "name": "As DeepRacer's WORLD_NAME names it (letters, digits, '_' and '-'), e.g. "
            "H_track, so imported models trained on it find it."
        }

    def clean(self) -> dict:
        cleaned = super().clean()
        upload = cleaned.get("route_file")
        if upload is None:
            return cleaned
        if upload.size > ROUTE_MAX_BYTES:
            self.add_error("route_file", f"A route file is at most {ROUTE_MAX_BYTES >> 20} MB.")
            return cleaned
        self.route = upload.read()
        if "name" not in cleaned or "directions" not in cleaned:
            return cleaned
        try:
            track_check(
                name=cleaned["name"],
                route=self.route,
                directions=cleaned["directions"],
                difficulty=cleaned.get("difficulty") or Track.Difficulty.INTERMEDIATE,
                display_name=cleaned.get("display_name", ""),
                description=cleaned.get("description", ""),
            )
        except TrackRefused as error:
            field = {"route": "route_file"}.get(error.field, error.field)
            self.add_error(field if field in self.fields else None, error.message)
        return cleaned


class AddedTrackForm(forms.ModelForm):
    class Meta:
        model = Track
        fields = ["display_name", "description", "difficulty", "counterclockwise", "clockwise"]

    def clean(self) -> dict:
        cleaned = super().clean()
        if not cleaned.get("counterclockwise") and not cleaned.get("clockwise"):
            raise forms.ValidationError("Choose at least one direction racers may drive it.")
        return cleaned


class TrackOriginFilter(admin.SimpleListFilter):
    title = "origin"
    parameter_name = "origin"

    def lookups(self, request, model_admin):
        return [("builtin", "Built in"), ("added", "Added by staff")]

    def queryset(self, request, queryset):
        if self.value() in ("builtin", "added"):
            return queryset.filter(added_at__isnull=self.value() == "builtin")
        return queryset


@admin.register(Track)
class TrackAdmin(admin.ModelAdmin):
    """Built-in tracks are the simulator's (``manage.py loadtracks`` keeps them) and read-only;
    staff add tracks from DeepRacer route files, and may change or delete those."""

    list_display = ["display_name", "name", "difficulty", "length_m", "width_m", "builtin"]
    list_filter = ["difficulty", TrackOriginFilter]
    search_fields = ["name", "display_name"]
    readonly_fields = ["name", "length_m", "width_m", "picture", "added_by", "added_at"]

    @admin.display(boolean=True, description="built in")
    def builtin(self, track: Track) -> bool:
        return track.builtin

    @admin.display(description="preview")
    def picture(self, track: Track) -> str:
        url = reverse("training:track-preview", args=[track.name])
        return format_html('<img src="{}" width="480" alt="Top-down map of {}">', url, track)

    def changeform_view(self, request, object_id=None, form_url="", extra_context=None):
        # Django's admin runs a whole POST, the form's checks included, in one transaction, which
        # on SQLite holds the write lock from its start: the route's check and the preview are
        # slow work, so they run outside it, and track_add writes the row in its own.
        return self._changeform_view(request, object_id, form_url, extra_context)

    def get_form(self, request, obj=None, change=False, **kwargs):
        kwargs["form"] = AddedTrackForm if obj is not None else TrackUploadForm
        return super().get_form(request, obj, change=change, **kwargs)

    def get_fields(self, request, obj=None) -> list[str]:
        if obj is None:
            return ["route_file", *TrackUploadForm.Meta.fields, "directions"]
        return [
            "name",
            *AddedTrackForm.Meta.fields,
            "length_m",
            "width_m",
            "picture",
            "added_by",
            "added_at",
        ]

    def get_readonly_fields(self, request, obj=None) -> list[str]:
        return [] if obj is None else self.readonly_fields

    def has_change_permission(self, request, obj=None) -> bool:
        return super().has_change_permission(request, obj) and not (obj and obj.builtin)

    def has_delete_permission(self, request, obj=None) -> bool:
        return super().has_delete_permission(request, obj) and not (obj and obj.builtin)

    def save_model(self, request, obj: Track, form, change: bool) -> None:
        if change:  # through track_add again, so the preview follows the directions
            directions = [d.value for d in Direction if getattr(obj, d.value)]
            route = bytes(Track.objects.filter(pk=obj.pk).values_list("route", flat=True)[0])
            name, replace = obj.name, True
        else:
            directions, route = form.cleaned_data["directions"], form.route
            name, replace = form.cleaned_data["name"], False
        row = track_add(
            name=name,
            display_name=obj.display_name,
            route=route,
            directions=directions,
            description=obj.description,
            difficulty=obj.difficulty,
            added_by=request.user,
            replace=replace,
        )
        obj.pk, obj.length_m, obj.width_m = row.pk, row.length_m, row.width_m


@admin.register(RLModel)
class RLModelAdmin(admin.ModelAdmin):
    list_display = ["name", "owner", "track", "status", "created_at"]
    list_filter = ["status", "track"]
    search_fields = ["name", "owner__username"]
    date_hierarchy = "created_at"
    list_select_related = ["owner", "track"]
    actions = ["stop_training"]

    @admin.action(description="Stop training of the selected models")
    def stop_training(self, request, queryset) -> None:
        """Stop each selected model's training as its racer's button does, and say per model
        what happened, as the job stands after the stop (which reads it under its lock: it may
        have ended since the list was shown): stopping (saving its last iteration), canceled
        while it waited, or nothing to stop (already ready, say)."""
        for model in queryset:
            job = model.latest_job
            was = job.status if job is not None else None
            if job is not None and job.is_active:
                job = training_stop(job=job)
            model.refresh_from_db(fields=["status"])
            said, level = _stop_said(model, job, was)
            self.message_user(request, f"{model}: {said}.", level)


def _stop_said(model: RLModel, job: TrainingJob | None, was: str | None) -> tuple[str, int]:
    """What the admin's stop did to ``model``, whose ``job`` (after the stop) was ``was``."""
    if job is not None and job.status == TrainingJob.Status.STOPPING:
        said = "already stopping" if was == TrainingJob.Status.STOPPING else "stopping"
        if job.message:
            said += f": {job.message[:1].lower()}{job.message[1:]}"
        return said, messages.INFO if said.startswith("already") else messages.SUCCESS
    if job is not None and job.status == TrainingJob.Status.CANCELED and was != job.status:
        return "canceled: it had not started training", messages.SUCCESS
    return f"already {model.get_status_display().lower()}: nothing to stop", messages.INFO


@admin.register(RewardFunction)
class RewardFunctionAdmin(admin.ModelAdmin):
    list_display = ["name", "owner", "updated_at"]
    search_fields = ["name", "owner__username"]
    list_select_related = ["owner"]
    readonly_fields = ["created_at", "updated_at"]


@admin.register(Vehicle)
class VehicleAdmin(admin.ModelAdmin):
    list_display = ["name", "owner", "camera", "lidar", "shell_colour"]
    list_filter = ["camera", "lidar"]
    search_fields = ["name", "owner__username"]


@admin.register(QuotaDefaults)
class QuotaDefaultsAdmin(admin.ModelAdmin):
    """One row: what new racers get."""

    list_display = ["__str__", "max_models", "max_minutes_per_month"]

    def has_add_permission(self, request) -> bool:
        return not QuotaDefaults.objects.exists()

    def has_delete_permission(self, request, obj=None) -> bool:
        return False


@admin.register(Quota)
class QuotaAdmin(admin.ModelAdmin):
    list_display = ["racer", "max_models", "max_minutes_per_month", "machine_share"]
    search_fields = ["racer__username"]
    list_select_related = ["racer"]
    autocomplete_fields = ["racer"]
