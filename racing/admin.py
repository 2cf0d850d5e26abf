"""The league staff's tool: seasons, events, submissions, rankings and divisions in the admin.

Members of the "Race staff" group (with staff status) hold every permission on these models and
none on users; superusers manage everything.
"""

from django import forms
from django.contrib import admin, messages
from django.contrib.admin import helpers
from django.core.exceptions import NON_FIELD_ERRORS, ValidationError
from django.db import models
from django.db.models import QuerySet
from django.http import HttpRequest
from django.template.defaultfilters import pluralize
from django.template.response import TemplateResponse

from accounts.selectors import racer_name
from common.formatting import laptime
from common.time_zones import local_text
from racing import services
from racing.forms import LOCAL, RACE_FIELDS, RaceObstaclesForm
from racing.models import (
    Event,
    Lap,
    LiveEntry,
    LiveSession,
    Racer,
    Ranking,
    Season,
    Submission,
)


class EventInlineForm(forms.ModelForm):
    """An event as the admin edits it. The model also checks fields a form may not show (the
    season of an inline row, the direction): their errors are said above the form or row,
    named, rather than left on a field nobody sees."""

    def add_error(self, field: str | None, error) -> None:
        if field is None and isinstance(error, ValidationError) and hasattr(error, "error_dict"):
            error = ValidationError(self._errors_where_seen(error.error_dict))
        super().add_error(field, error)

    def _errors_where_seen(self, errors: dict[str, list[ValidationError]]) -> dict:
        shown: dict[str, list] = {}
        for name, messages_ in errors.items():
            field = self.fields.get(name)
            if name == NON_FIELD_ERRORS or (field is not None and not field.widget.is_hidden):
                shown.setdefault(name, []).extend(messages_)
                continue
            label = (field.label if field else Event._meta.get_field(name).verbose_name) or name
            label = label[0].upper() + label[1:]
            shown.setdefault(NON_FIELD_ERRORS, []).extend(
                f"{label}: {message}" for error in messages_ for message in error.messages
            )
        return shown


class EventAdminForm(RaceObstaclesForm, EventInlineForm):
    """An event, with its boxes and bot cars as fields of their own rather than raw JSON."""

    class Meta:
        model = Event
        fields = [
            "season",
            "name",
            "slug",
            "division",
            *RACE_FIELDS,
            "public",
            "organiser",
            "participants",
            "removed",
        ]


class EventInline(admin.TabularInline):
    """A season's events as a table that fits a laptop screen: one date-and-time box per
    moment, short name boxes (an event's own page has every field)."""

    model = Event
    form = EventInlineForm
    fields = ["name", "slug", "track", "race_type", "division", "opens_at", "closes_at"]
    prepopulated_fields = {"slug": ["name"]}
    formfield_overrides = {
        models.DateTimeField: {
            "form_class": forms.DateTimeField,
            "widget": forms.DateTimeInput(attrs={"type": "datetime-local"}, format=LOCAL),
        },
        models.CharField: {"widget": forms.TextInput(attrs={"size": 14})},
    }
    extra = 0
    show_change_link = True

    class Media:
        css = {"all": ["racing/admin.css"]}


@admin.register(Season)
class SeasonAdmin(admin.ModelAdmin):
    list_display = ["name", "year", "starts_on", "ends_on"]
    list_filter = ["year"]
    search_fields = ["name"]
    date_hierarchy = "starts_on"
    inlines = [EventInline]

    def changeform_view(self, request, object_id=None, form_url="", extra_context=None):
        # The events table needs the page's width: no side menu on a season's page.
        extra_context = {**(extra_context or {}), "is_nav_sidebar_enabled": False}
        return super().changeform_view(request, object_id, form_url, extra_context)


@admin.register(Event)
class EventAdmin(admin.ModelAdmin):
    list_display = ["name", "season", "track", "race", "divisions", "runs", "state", "public"]
    list_filter = [
        "season",
        "division",
        "race_type",
        "cars",
        "physical",
        "track",
        "public",
        "ranking_method",
    ]
    search_fields = ["name", "slug", "organiser__username"]
    form = EventAdminForm
    prepopulated_fields = {"slug": ["name"]}
    date_hierarchy = "opens_at"
    list_select_related = ["season", "track"]
    raw_id_fields = ["organiser", "participants", "removed"]
    readonly_fields = ["invite_token"]
    actions = ["close_events", "recompute_rankings"]
    fieldsets = [
        (None, {"fields": ["season", "name", "slug", "division", "any_division"]}),
        ("Race", {"fields": [
            "track", "direction", "race_type", "cars", "physical", "min_lap_s", "race_time_min",
        ]}),
        ("Object avoidance", {"fields": ["box_count", "box_randomize"]}),
        ("Head-to-bot", {"fields": ["bot_count", "bot_speed", "bot_lane_changes"]}),
        ("When", {"fields": ["opens_at", "closes_at"]}),
        ("Rules", {"fields": [
            "ranking_method", "laps_required", "laps_to_drive", "off_track_penalty_s",
            "crash_penalty_s", "max_off_tracks_per_lap", "submissions_per_racer",
        ]}),
        ("Community race", {"classes": ["collapse"], "fields": [
            "public", "organiser", "invite_token", "participants", "removed",
        ]}),
    ]  # fmt: skip

    @admin.display(description="state")
    def state(self, event: Event) -> str:
        return event.state.label

    @admin.display(description="race", ordering="race_type")
    def race(self, event: Event) -> str:
        return event.format_display  # the race type, with its cars a race or real cars

    @admin.display(description="division", ordering="division")
    def divisions(self, event: Event) -> str:
        return event.division_display

    @admin.display(description="open", ordering="opens_at")
    def runs(self, event: Event) -> str:
        return f"{local_text(event.opens_at)} to {local_text(event.closes_at)}"

    def changelist_view(self, request, extra_context=None):
        # The events list needs the page's width: no side menu, as on a season's page.
        extra_context = {**(extra_context or {}), "is_nav_sidebar_enabled": False}
        return super().changelist_view(request, extra_context)

    @admin.action(description="Close the selected events now")
    def close_events(self, request: HttpRequest, queryset: QuerySet[Event]) -> None:
        for event in queryset:
            services.event_close(event=event)
        count = len(queryset)
        self.message_user(request, f"Closed {count} event{pluralize(count)}.", messages.SUCCESS)

    @admin.action(description="Recompute the selected events' rankings")
    def recompute_rankings(self, request: HttpRequest, queryset: QuerySet[Event]) -> None:
        for event in queryset:
            ranked = services.event_rankings_recompute(event=event)
            self.message_user(request, f"{event.name}: {ranked} racers ranked.", messages.SUCCESS)

    def save_model(self, request, event: Event, form, change: bool) -> None:
        if not event.public:
            event.ensure_invite()
        super().save_model(request, event, form, change)


class DisqualifyForm(forms.Form):
    reason = forms.CharField(
        max_length=255,
        widget=forms.Textarea(attrs={"rows": 3, "cols": 60}),
        help_text="The racer reads it on their run's page and in their notification.",
        error_messages={"required": "Say why: the racer reads it."},
    )


class SubmissionAdminForm(forms.ModelForm):
    """A submission as staff change it: a disqualification says why."""

    class Meta:
        model = Submission
        fields = ["disqualified", "disqualification_reason"]

    def clean(self) -> dict:
        data = super().clean()
        if data.get("disqualified") and not (data.get("disqualification_reason") or "").strip():
            self.add_error("disqualification_reason", "Say why: the racer reads it.")
        return data


class LapInline(admin.TabularInline):
    model = Lap
    fields = readonly_fields = [
        "number",
        "time_ms",
        "status",
        "counted",
        "off_tracks",
        "crashes",
        "resets",
        "penalty_ms",
    ]
    extra = 0
    can_delete = False

    def has_add_permission(self, request, obj=None) -> bool:
        return False


@admin.register(Submission)
class SubmissionAdmin(admin.ModelAdmin):
    list_display = [
        "pk",
        "event",
        "racer",
        "model_name",
        "status",
        "score",
        "qualified",
        "disqualified",
        "created_at",
    ]
    list_filter = ["event__season", "event", "status", "qualified", "disqualified", "physical"]
    search_fields = ["racer__username", "model_name", "event__name"]
    date_hierarchy = "created_at"
    list_select_related = ["event", "racer"]
    readonly_fields = [
        "event",
        "racer",
        "model",
        "model_name",
        "evaluation",
        "status",
        "failure_reason",
        "created_at",
        "finished_at",
        "score_ms",
        "qualified",
        "laps_completed",
        "off_tracks",
        "video",
        "physical",
    ]
    fields = [*readonly_fields, "disqualified", "disqualification_reason"]
    form = SubmissionAdminForm
    inlines = [LapInline]
    actions = ["disqualify"]

    @admin.display(description="score", ordering="score_ms")
    def score(self, submission: Submission) -> str:
        return laptime(submission.score_ms)

    @admin.action(description="Disqualify the selected submissions (asks for the reason)")
    def disqualify(
        self, request: HttpRequest, queryset: QuerySet[Submission]
    ) -> TemplateResponse | None:
        """First a page that lists the submissions and asks why (as Django's delete action
        asks); then each is disqualified with that reason and its racer told."""
        form = DisqualifyForm(request.POST if "apply" in request.POST else None)
        submissions = list(queryset.select_related("event", "racer"))
        if form.is_valid():
            for submission in submissions:
                services.submission_disqualify(
                    submission=submission, reason=form.cleaned_data["reason"]
                )
            count = len(submissions)
            self.message_user(
                request, f"Disqualified {count} submission{pluralize(count)}.", messages.SUCCESS
            )
            return None
        return TemplateResponse(
            request,
            "racing/submission_disqualify.html",
            {
                **self.admin_site.each_context(request),
                "title": f"Disqualify {len(submissions)} submission{pluralize(len(submissions))}",
                "opts": self.model._meta,
                "submissions": submissions,
                "form": form,
                "action_checkbox_name": helpers.ACTION_CHECKBOX_NAME,
            },
        )

    def save_model(self, request, submission: Submission, form, change: bool) -> None:
        """A disqualification (or its new reason) and a reinstatement go through the league's
        services, from the row as it was: the ranking, the leaderboard and the racer follow."""
        if {"disqualified", "disqualification_reason"} & set(form.changed_data):
            before = Submission.objects.get(pk=submission.pk)
            if submission.disqualified:
                services.submission_disqualify(
                    submission=before, reason=submission.disqualification_reason
                )
            elif before.disqualified:
                services.submission_reinstate(submission=before)
            submission.disqualification_reason = before.disqualification_reason
        super().save_model(request, submission, form, change)

    def has_add_permission(self, request) -> bool:
        return False  # submissions come from racers


@admin.register(Ranking)
class RankingAdmin(admin.ModelAdmin):
    list_display = ["event", "racer", "model_name", "time", "submitted_at"]
    list_filter = ["event__season", "event"]
    search_fields = ["racer__username", "model_name"]
    list_select_related = ["event", "racer"]
    readonly_fields = [
        "event",
        "racer",
        "submission",
        "model_name",
        "score_ms",
        "submitted_at",
        "laps_completed",
        "off_tracks",
    ]

    @admin.display(description="time", ordering="score_ms")
    def time(self, ranking: Ranking) -> str:
        return laptime(ranking.score_ms)

    def has_add_permission(self, request) -> bool:
        return False  # rankings come from scored submissions


@admin.register(Racer)
class RacerAdmin(admin.ModelAdmin):
    list_display = ["name", "user", "division", "division_set_by_staff", "promoted_at"]
    list_filter = ["division", "division_set_by_staff"]
    search_fields = ["user__profile__racer_name", "user__username"]
    list_select_related = ["user__profile"]
    readonly_fields = ["name", "user", "promoted_at"]
    fields = ["name", "user", "division", "division_set_by_staff", "promoted_at"]

    @admin.display(description="racer name", ordering="user__profile__racer_name")
    def name(self, racer: Racer) -> str:
        return racer_name(racer=racer.user)

    def save_model(self, request, racer: Racer, form, change: bool) -> None:
        if "division" in form.changed_data:
            racer.division_set_by_staff = True  # the monthly promotion leaves it alone now
        super().save_model(request, racer, form, change)

    def has_add_permission(self, request) -> bool:
        return False  # every account gets one as it is made (racing.receivers)


class LiveEntryInline(admin.TabularInline):
    model = LiveEntry
    fields = readonly_fields = ["position", "racer", "model_name", "speed", "status", "submission"]
    extra = 0

    def has_add_permission(self, request, obj=None) -> bool:
        return False  # racers join from the race page


@admin.register(LiveSession)
class LiveSessionAdmin(admin.ModelAdmin):
    """Live races: opened and run from each event's race page; here staff see their queues and
    may change their settings."""

    list_display = ["event", "facilitator", "autolaunch", "min_speed", "max_speed", "created_at"]
    fields = ["event", "facilitator", "autolaunch", "min_speed", "max_speed"]
    readonly_fields = ["event", "facilitator"]
    inlines = [LiveEntryInline]

    def has_add_permission(self, request) -> bool:
        return False  # opened on the event's race page
