from django.contrib import messages
from django.contrib.auth import get_user_model
from django.contrib.auth.decorators import login_required
from django.contrib.auth.views import redirect_to_login
from django.core.exceptions import ValidationError
from django.http import Http404, HttpRequest, HttpResponse
from django.shortcuts import get_object_or_404, redirect, render
from django.urls import reverse
from django.views.decorators.http import require_POST

from accounts.selectors import racer_name
from common import ratelimits
from racing import live_races, selectors, services, timing
from racing.forms import CommunityRaceForm, SubmissionForm
from racing.models import Division, Event, LiveSession, Season, Submission
from training import artifacts
from training import selectors as training_selectors


def race_list(request: HttpRequest) -> HttpResponse:
    user = request.user
    return render(
        request,
        "racing/race_list.html",
        {
            "seasons": selectors.seasons_with_events(),
            "community": selectors.community_races_for(racer=user) if user.is_authenticated else [],
            "open_events": selectors.events_open_to(racer=user) if user.is_authenticated else [],
        },
    )


def leaderboard_list(request: HttpRequest) -> HttpResponse:
    return render(
        request, "racing/leaderboard_list.html", {"events": selectors.events_with_leaders()}
    )


def _get_event_for_user(request: HttpRequest, slug: str) -> Event:
    """The event, if this user may see it (public events: anyone); 404 otherwise."""
    event = get_object_or_404(
        Event.objects.select_related("season", "track", "organiser__profile"), slug=slug
    )
    if not selectors.event_visible_to(event=event, user=request.user):
        raise Http404("No such event.")
    return event


def _get_event_run_by(request: HttpRequest, slug: str, may) -> Event:
    """The event, if this user may see it and ``may(event=, user=)`` run it (its timekeeper, its
    live race's facilitator); 404 otherwise."""
    event = _get_event_for_user(request, slug)
    if not may(event=event, user=request.user):
        raise Http404("No such event to run.")
    return event


def leaderboard(request: HttpRequest, slug: str) -> HttpResponse:
    event = _get_event_for_user(request, slug)
    page = selectors.leaderboard_page(event=event, page=request.GET.get("page", 1))
    mine = selectors.ranking_of(event=event, racer=request.user)
    context = {
        "event": event,
        "page": page,
        "rankings": page.object_list,
        "mine": mine,
        "mine_elsewhere": mine is not None and mine.page != page.number,
        "my_submissions": selectors.submissions_in_event(event=event, racer=request.user),
    }
    if request.GET.get("fragment") == "table":
        return render(request, "racing/includes/leaderboard_table.html", context)
    if request.user.is_authenticated:
        context["can_submit"] = not selectors.submission_refusal(
            racer=request.user, event=event, model=None
        )
        context["may_keep_time"] = timing.may_keep_time(event=event, user=request.user)
        context["may_facilitate"] = live_races.may_facilitate(event=event, user=request.user)
    context["live_race"] = LiveSession.objects.filter(event=event).exists()
    return render(request, "racing/leaderboard.html", context)


def season_standings(request: HttpRequest, pk: int) -> HttpResponse:
    season = get_object_or_404(Season, pk=pk)
    division = request.GET.get("division", Division.OPEN)
    if division not in Division.values:
        division = Division.OPEN
    standings, events = selectors.season_standings(season=season, division=division)
    return render(
        request,
        "racing/season_standings.html",
        {
            "season": season,
            "division": Division(division),
            "divisions": Division,
            "standings": standings,
            "events": events,
            "points": selectors.POINTS,
        },
    )


# Submissions


@login_required
def submission_create(request: HttpRequest) -> HttpResponse:
    initial = {}  # what the link chose; the form chooses a list's only entry itself
    if model := request.GET.get("model"):
        initial["model"] = model
    if slug := request.GET.get("event"):
        initial["event"] = Event.objects.filter(slug=slug).values_list("pk", flat=True).first()
    form = SubmissionForm(request.POST or None, racer=request.user, initial=initial)
    if limited := ratelimits.over(request, "evaluate"):
        ratelimits.refuse(form, limited)
    elif request.method == "POST" and form.is_valid():
        try:
            submission = services.submission_create(
                racer=request.user,
                event=form.cleaned_data["event"],
                model=form.cleaned_data["model"],
                checkpoint=form.cleaned_data["checkpoint"] or "best",
            )
        except services.SubmissionRefused as refused:
            form.add_error(None, str(refused))
        else:
            messages.success(
                request, f"{submission.model_name} is on the grid for {submission.event.name}."
            )
            return redirect(submission)
    return render(
        request,
        "racing/submission_create.html",
        {
            "form": form,
            "has_events": form.fields["event"].queryset.exists(),
            "has_models": form.fields["model"].queryset.exists(),
        },
        status=429 if limited else 200,
    )


@login_required
def submission_list(request: HttpRequest) -> HttpResponse:
    return render(
        request,
        "racing/submission_list.html",
        {"submissions": selectors.submissions_for_racer(racer=request.user)[:200]},
    )


def _get_submission_for_user(request: HttpRequest, pk: int) -> Submission:
    """The submission, if this user may see it (``selectors.submission_visible_to``); 404
    otherwise."""
    submission = get_object_or_404(
        Submission.objects.select_related(
            "event", "event__track", "event__season", "racer__profile"
        ),
        pk=pk,
    )
    if not selectors.submission_visible_to(submission=submission, user=request.user):
        raise Http404("No such submission.")
    return submission


def submission_detail(request: HttpRequest, pk: int) -> HttpResponse:
    """A run's page: its racer's own while it races, and everyone's once it stands on the
    leaderboard (the leaderboard's "Watch" opens it)."""
    try:
        submission = _get_submission_for_user(request, pk)
    except Http404:
        if request.user.is_authenticated:
            raise
        return redirect_to_login(request.get_full_path())  # a racer's link, logged out
    ranking = selectors.ranking_of(event=submission.event, racer=submission.racer)
    return render(
        request,
        "racing/submission_detail.html",
        {
            "submission": submission,
            "event": submission.event,
            "laps": list(submission.laps.all()),
            "cars": training_selectors.race_cars(evaluation=submission.evaluation),
            "ranking": ranking,
            "own": request.user.pk == submission.racer_id,
        },
    )


def submission_video(request: HttpRequest, pk: int) -> HttpResponse:
    """A race's video, for whoever may see its submission."""
    submission = _get_submission_for_user(request, pk)
    if not submission.video:
        raise Http404("No such video.")
    filename = f"{submission.event.slug}-{submission.model_name}-{submission.pk}.webm"
    return artifacts.download(
        request, submission.video, filename, attachment=False, content_type="video/webm"
    )


# Community races


@login_required
def community_race_create(request: HttpRequest) -> HttpResponse:
    form = CommunityRaceForm(request.POST or None, organiser=request.user)
    if request.method == "POST" and form.is_valid():
        try:
            event, made = services.community_race_create(
                organiser=request.user,
                fields=form.fields_for_service(),
                form_token=form.cleaned_data["form_token"],
            )
        except ValidationError as invalid:
            form.add_error(None, invalid)
        else:
            messages.add_message(request, *_race_made_message(event, made))
            return redirect("racing:community-race-manage", slug=event.slug)
    return render(
        request,
        "racing/community_race_create.html",
        {"form": form, "tracks": training_selectors.tracks_available()},
    )


def _race_made_message(event: Event, made: services.RaceMade) -> tuple[int, str]:
    if made == services.RaceMade.BY_THIS_FORM:
        return (
            messages.INFO,
            f"This form created {event.name} already, so here it is: no second race.",
        )
    if made == services.RaceMade.ALIKE:
        return messages.INFO, (
            f"You created {event.name} with these settings a moment ago, so here it is: no "
            "second race. To organise another race like it, give it another name."
        )
    return messages.SUCCESS, "Your race is set up: send its invitation link to racers."


def _get_organised_event(request: HttpRequest, slug: str) -> Event:
    """A community race the user organises; 404 otherwise."""
    return get_object_or_404(
        Event.objects.select_related("track"), slug=slug, public=False, organiser=request.user
    )


@login_required
def community_race_manage(request: HttpRequest, slug: str) -> HttpResponse:
    event = _get_organised_event(request, slug)
    invite = request.build_absolute_uri(reverse("racing:event-join", args=[event.invite_token]))
    return render(
        request,
        "racing/community_race_manage.html",
        {
            "event": event,
            "invite": invite,
            "participants": event.participants.select_related("profile").order_by(
                "profile__racer_name"
            ),
            "removed": event.removed.select_related("profile").order_by("profile__racer_name"),
        },
    )


@login_required
def community_race_delete(request: HttpRequest, slug: str) -> HttpResponse:
    """Asks first (GET), then deletes a race nobody has submitted to (POST)."""
    event = _get_organised_event(request, slug)
    if request.method == "POST":
        try:
            services.community_race_delete(event=event)
        except services.RaceNotDeleted as refused:
            messages.error(request, str(refused))
            return redirect("racing:community-race-manage", slug=event.slug)
        messages.success(request, f"{event.name} is deleted.")
        return redirect("racing:race-list")
    return render(
        request,
        "racing/community_race_delete.html",
        {"event": event, "refusal": selectors.race_deletion_refusal(event=event)},
    )


@login_required
@require_POST
def community_race_close(request: HttpRequest, slug: str) -> HttpResponse:
    event = _get_organised_event(request, slug)
    services.event_close(event=event)
    messages.success(request, f"{event.name} is closed; its invitation no longer works.")
    return redirect("racing:community-race-manage", slug=event.slug)


@login_required
@require_POST
def community_race_remove(request: HttpRequest, slug: str, user_pk: int) -> HttpResponse:
    event = _get_organised_event(request, slug)
    racer = get_object_or_404(get_user_model(), pk=user_pk, joined_events=event)
    try:
        services.participant_remove(event=event, racer=racer)
    except services.SubmissionRefused as refused:
        messages.error(request, str(refused))
    else:
        messages.success(request, f"{racer_name(racer=racer)} is out of {event.name}.")
    return redirect("racing:community-race-manage", slug=event.slug)


@login_required
@require_POST
def community_race_readmit(request: HttpRequest, slug: str, user_pk: int) -> HttpResponse:
    event = _get_organised_event(request, slug)
    racer = get_object_or_404(get_user_model(), pk=user_pk, removed_from_events=event)
    services.participant_readmit(event=event, racer=racer)
    messages.success(request, f"{racer_name(racer=racer)} is back in {event.name}.")
    return redirect("racing:community-race-manage", slug=event.slug)


@login_required
@require_POST
def community_race_invitation_renew(request: HttpRequest, slug: str) -> HttpResponse:
    event = _get_organised_event(request, slug)
    services.invitation_renew(event=event)
    messages.success(
        request, "Here is a new invitation link; the old one no longer works. Racers in stay in."
    )
    return redirect("racing:community-race-manage", slug=event.slug)


def event_join(request: HttpRequest, token: str) -> HttpResponse:
    event = get_object_or_404(
        Event.objects.select_related("track", "organiser__profile"),
        public=False,
        invite_token=token,
    )
    expired = event.state == Event.State.CLOSED
    refusal = selectors.invitation_refusal(event=event, racer=request.user)
    if request.method == "POST" and not refusal:
        if not request.user.is_authenticated:
            return redirect_to_login(request.get_full_path())
        services.event_join(event=event, racer=request.user)
        messages.success(request, f"You are in {event.name}. Submit a model while it is open.")
        return redirect(event)
    joined = (
        request.user.is_authenticated and event.participants.filter(pk=request.user.pk).exists()
    )
    return render(
        request,
        "racing/event_join.html",
        {"event": event, "expired": expired, "refusal": refusal, "joined": joined},
        status=410 if expired else 403 if refusal else 200,
    )
