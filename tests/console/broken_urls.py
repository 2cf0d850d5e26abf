"""The site's URLs plus one view that fails, to see what a racer sees when something breaks."""

from django.db import OperationalError
from django.urls import path

from console.urls import urlpatterns as site_urlpatterns


def broken(request):
    return 1 / 0


def database_down(request):
    raise OperationalError('connection to server at "db" (10.0.0.5), port 5432 failed')


urlpatterns = [path("broken/", broken), path("database-down/", database_down), *site_urlpatterns]
handler500 = "console.views.server_error"
