from django.http import HttpRequest
from django.urls import reverse

NAVIGATION = (
    # (label, URL name, who sees it)
    ("Models", "training:model-list", "racer"),
    ("Garage", "training:garage", "racer"),
    ("Races", "racing:race-list", "everyone"),
    ("Leaderboards", "racing:leaderboard-list", "everyone"),
    ("Help", "help", "everyone"),
    ("System", "system", "staff"),
    ("Admin", "admin:index", "staff"),
)


def navigation(request: HttpRequest) -> dict:
    """The site's navigation for this visitor, with the section of the current page marked."""
    user = getattr(request, "user", None)
    audience = {"everyone"}
    if user is not None and user.is_authenticated:
        audience.add("racer")
        if user.is_staff:
            audience.add("staff")
    items = []
    for label, url_name, who in NAVIGATION:
        if who in audience:
            url = reverse(url_name)
            items.append({"label": label, "url": url, "current": request.path.startswith(url)})
    return {"navigation": items}
