"""A middleware base that is sync and async alike, as every middleware of the site must be: an
async view (``training.checkers``) is then awaited on the server's event loop rather than run in
one of its threads, and Django never has to adapt a middleware (a test fails if it does)."""

from __future__ import annotations

from collections.abc import Callable

from asgiref.sync import iscoroutinefunction, markcoroutinefunction
from django.http import HttpRequest, HttpResponse


class SyncAndAsyncMiddleware:
    """Calls ``before`` with the request, then the view, then ``after`` with its response, in the
    server's sync or async stack, whichever it has."""

    sync_capable = async_capable = True

    def __init__(self, get_response: Callable[[HttpRequest], HttpResponse]) -> None:
        self.get_response = get_response
        if iscoroutinefunction(get_response):
            markcoroutinefunction(self)

    def __call__(self, request: HttpRequest):
        if iscoroutinefunction(self):
            return self._acall(request)
        self.before(request)
        return self.after(request, self.get_response(request))

    async def _acall(self, request: HttpRequest) -> HttpResponse:
        self.before(request)
        return self.after(request, await self.get_response(request))

    def before(self, request: HttpRequest) -> None:
        """What is done with the request before the view."""

    def after(self, request: HttpRequest, response: HttpResponse) -> HttpResponse:
        """What is done with the response after the view."""
        return response
