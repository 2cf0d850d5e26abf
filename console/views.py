import sys

from django.conf import settings
from django.contrib import messages
from django.contrib.admin.views.decorators import staff_member_required
from django.contrib.auth import login
from django.contrib.auth.views import LoginView, PasswordResetView
from django.db import InterfaceError, OperationalError, transaction
from django.http import HttpRequest, HttpResponse, HttpResponseServerError, JsonResponse
from django.shortcuts import redirect, render
from django.template import loader
from django.templatetags.static import static
from django.utils.http import url_has_allowed_host_and_scheme
from django.views.decorators.cache import never_cache
from django.views.decorators.http import require_safe

from accounts import tasks as accounts_tasks
from common import ratelimits
from common.health import system_health
from console import guidance
from console.forms import PasswordResetRequestForm, SignInForm, SignUpForm
from racing.models import RankingMethod
from racing.selectors import events_not_closed
from training.rewards import PARAMS
from training.selectors import models_for_racer, vehicles_for_racer

NEW_RACER = "new_racer"  # session key: the home page greets a racer who just signed up once


def home(request: HttpRequest) -> HttpResponse:
    context = {"events": events_not_closed()[:3]}
    if request.user.is_authenticated:
        context["new_racer"] = request.session.pop(NEW_RACER, False)
        context["has_vehicle"] = vehicles_for_racer(racer=request.user).exists()
        context["models"] = models_for_racer(racer=request.user)[:5]
    return render(request, "console/home.html", context)


def signup(request: HttpRequest) -> HttpResponse:
    """A new racer's account; they land logged in where they were going (``next``, when it is
    a page of this site), or on the home page, greeted once either way."""
    next_url = _safe_next(request)
    if request.user.is_authenticated:
        return redirect(next_url or "home")
    form = SignUpForm(request.POST or None)
    if limited := ratelimits.over(request, "sign-up", ratelimits.address(request)):
        ratelimits.refuse(form, limited)
    elif request.method == "POST" and form.is_valid():
        user = form.save()
        login(request, user, backend="django.contrib.auth.backends.ModelBackend")
        if not next_url:
            request.session[NEW_RACER] = True  # the home page's heading greets them
            return redirect("home")
        messages.success(request, f"Welcome to Pitlane, {user.username}!")
        return redirect(next_url)
    return render(
        request,
        "registration/signup.html",
        {"form": form, "next": next_url},
        status=limited.status if limited else 400 if form.errors else 200,
    )


SIGN_IN_LIMITS = ("sign-in-address", "sign-in-account")  # failed sign-ins, per address and name


class SignInView(LoginView):
    """Django's sign-in, limited per login name and per address: past either limit the form
    says how long to wait, and the password is not checked at all. Only failures count: each
    attempt is counted before its password is checked (so guesses sent together count each
    other) and given back when it succeeds, so that a race day's racers behind one address
    sign in as often as they need."""

    form_class = SignInForm
    held: ratelimits.Held | None = None

    def post(self, request: HttpRequest, *args, **kwargs) -> HttpResponse:
        name = str(request.POST.get("username", "")).strip().lower()[:150]
        self.held = ratelimits.hold(
            request,
            *SIGN_IN_LIMITS,
            keys={
                "sign-in-address": ratelimits.address(request),
                "sign-in-account": f"name:{name}",
            },
        )
        if limited := self.held.limited:
            form = self.get_form_class()(request, initial={"username": name})
            context = self.get_context_data(form=form, limited=limited)
            return self.render_to_response(context, status=limited.status)
        return super().post(request, *args, **kwargs)

    def form_valid(self, form) -> HttpResponse:
        if self.held is not None:
            self.held.give_back(*SIGN_IN_LIMITS)
        return super().form_valid(form)


class ForgottenPasswordView(PasswordResetView):
    """ "Forgot your password?": where the site sends email, Django's reset link goes to the
    account with that address; the page says the same whether there is one or not, and a
    worker looks the address up and sends the email, so neither its words nor its time tell
    anybody who has an account. Requests are limited per address and per email address asked
    for. Where the site sends no email, the page says to ask league staff (the admin)."""

    form_class = PasswordResetRequestForm

    def get_context_data(self, **kwargs) -> dict:
        return super().get_context_data(
            by_email=settings.PITLANE_PASSWORD_RESET_BY_EMAIL,
            link_hours=settings.PASSWORD_RESET_TIMEOUT // 3600,
            **kwargs,
        )

    def post(self, request: HttpRequest, *args, **kwargs) -> HttpResponse:
        if not settings.PITLANE_PASSWORD_RESET_BY_EMAIL:
            return self.get(request, *args, **kwargs)
        form = self.get_form()
        email = str(request.POST.get("email", "")).strip().lower()[:254]
        limited = ratelimits.over(
            request, "password-reset", ratelimits.address(request)
        ) or ratelimits.over(request, "password-reset-email", f"email:{email}")
        if limited:
            ratelimits.refuse(form, limited)
            return self.render_to_response(self.get_context_data(form=form), status=429)
        if not form.is_valid():
            return self.render_to_response(self.get_context_data(form=form), status=400)
        asked = form.cleaned_data["email"]
        transaction.on_commit(lambda: accounts_tasks.password_reset_email.delay(asked))
        return redirect(self.get_success_url())


def _safe_next(request: HttpRequest) -> str:
    """The page to go to after signing up, if it is one of this site's; "" otherwise."""
    url = request.POST.get("next") or request.GET.get("next") or ""
    allowed = url_has_allowed_host_and_scheme(
        url, allowed_hosts={request.get_host()}, require_https=request.is_secure()
    )
    return url if allowed else ""


@require_safe
def favicon(request: HttpRequest) -> HttpResponse:
    """Browsers ask for /favicon.ico whatever a page links: the site's icon (not a 404)."""
    return redirect(static("console/pitlane.svg"))


@never_cache
@require_safe
def healthz(request: HttpRequest) -> JsonResponse:
    """Reachability of the database, Redis and the workers: 200 when all are up, else 503. A
    load balancer or an uptime check (anyone) reads up or down; staff also read what was checked
    and why it failed, which names hosts and workers."""
    health = system_health()
    body = health if request.user.is_staff else {"status": health["status"]}
    return JsonResponse(body, status=200 if health["status"] == "ok" else 503)


@require_safe
def help_page(request: HttpRequest) -> HttpResponse:
    """What every setting means, tuning hints, and how to get a model onto the car: public."""
    return render(
        request,
        "console/help.html",
        {
            "hyperparameters": guidance.hyperparameter_help(),
            "lookaheads": [(d, *guidance.lookahead(d)) for d in (0.9, 0.99, 0.999, 0.9999)],
            "params": PARAMS,
            "ranking_methods": RankingMethod.choices,
        },
    )


@staff_member_required
def system(request: HttpRequest) -> HttpResponse:
    return render(request, "console/system.html", {"health": system_health()})


def csrf_failure(request: HttpRequest, reason: str = "") -> HttpResponse:
    return render(request, "403_csrf.html", status=403)


def server_error(request: HttpRequest) -> HttpResponse:
    """What a racer sees when a page fails: 503 while the database does not answer (a restart,
    a failover: try again shortly), else 500. Rendered without context or database."""
    failure = sys.exc_info()[1]  # Django calls this while handling the page's exception
    if isinstance(failure, OperationalError | InterfaceError):
        response = HttpResponse(loader.render_to_string("503.html"), status=503)
        response["Retry-After"] = "30"
        return response
    return HttpResponseServerError(loader.render_to_string("500.html"))
