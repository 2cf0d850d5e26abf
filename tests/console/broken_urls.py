"""The site's URLs plus one view that fails, to see what a racer sees when something breaks."""

from django.urls import path

from console.urls import urlpatterns as site_urlpatterns


def broken(request):
    return 1 / 0


urlpatterns = [path("broken/", broken), *site_urlpatterns]
