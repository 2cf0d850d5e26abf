"""The one place where Pitlane reads its configuration from environment variables.

Every setting that can change between machines is read through an ``Env``; a value that cannot be
understood raises ``ImproperlyConfigured`` naming the variable, what it holds and what was expected,
so a typo in a deployment stops the process at start-up instead of surfacing later.
"""

from __future__ import annotations

import os
import re
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote, urlsplit

from django.core.exceptions import ImproperlyConfigured

_TRUE = {"1", "true", "yes", "on"}
_FALSE = {"0", "false", "no", "off"}
_MISSING = object()


@dataclass(frozen=True)
class EmailServer:
    """Django's EMAIL_* settings, as ``Env.email`` reads them from one URL."""

    backend: str
    host: str = ""
    port: int = 25
    user: str = ""
    password: str = ""
    use_tls: bool = False
    use_ssl: bool = False


class Env:
    """Typed access to environment variables, with defaults for a single machine."""

    def __init__(self, environ: Mapping[str, str] | None = None) -> None:
        self._environ = os.environ if environ is None else environ

    def _raw(self, name: str, default: object) -> str | object:
        value = self._environ.get(name)
        if value is None or value.strip() == "":
            if default is _MISSING:
                raise ImproperlyConfigured(f"The environment variable {name} must be set.")
            return default
        return value.strip()

    def str(self, name: str, default: object = _MISSING) -> str:
        return self._raw(name, default)  # type: ignore[return-value]

    def bool(self, name: str, default: bool | object = _MISSING) -> bool:
        value = self._raw(name, default)
        if not isinstance(value, str):
            return value  # type: ignore[return-value]
        if value.lower() in _TRUE:
            return True
        if value.lower() in _FALSE:
            return False
        raise ImproperlyConfigured(
            f"The environment variable {name} must be true or false (or 1/0, yes/no, on/off), "
            f"not {value!r}."
        )

    def int(
        self,
        name: str,
        default: int | object = _MISSING,
        *,
        minimum: int | None = None,
        maximum: int | None = None,
    ) -> int:
        value = self._raw(name, default)
        if isinstance(value, str):
            try:
                value = int(value)
            except ValueError:
                raise ImproperlyConfigured(
                    f"The environment variable {name} must be a whole number, not {value!r}."
                ) from None
        if (minimum is not None and value < minimum) or (maximum is not None and value > maximum):
            raise ImproperlyConfigured(
                f"The environment variable {name} must be between {minimum} and {maximum}, "
                f"not {value}."
            )
        return value  # type: ignore[return-value]

    def choice(
        self, name: str, default: str | object = _MISSING, *, choices: tuple[str, ...]
    ) -> str:
        """One of ``choices``, in any case."""
        value = self._raw(name, default)
        if value.lower() not in choices:
            raise ImproperlyConfigured(
                f"The environment variable {name} must be one of {', '.join(choices)}, "
                f"not {value!r}."
            )
        return value.lower()

    def rate(self, name: str, default: str | object = _MISSING) -> str:
        """A rate limit: a count per period, as ``5/15m`` (5 in 15 minutes) or ``30/h``; the
        period in s, m, h or d."""
        value = self._raw(name, default)
        if not re.fullmatch(r"[1-9]\d*/[1-9]?\d*[smhd]", value):
            raise ImproperlyConfigured(
                f"The environment variable {name} must be a count per period, such as 5/15m or "
                f"30/h (s, m, h or d), not {value!r}."
            )
        return value

    def list(self, name: str, default: list[str] | object = _MISSING) -> list[str]:
        """A comma-separated list; empty items are dropped."""
        value = self._raw(name, default)
        if not isinstance(value, str):
            return list(value)  # type: ignore[call-overload]
        return [item.strip() for item in value.split(",") if item.strip()]

    def url(self, name: str, default: str | object = _MISSING, *, schemes: tuple[str, ...]) -> str:
        """A URL whose scheme is one of ``schemes`` and that names a host (or a file path)."""
        value = self._raw(name, default)
        if value is default:
            return value  # type: ignore[return-value]
        parts = urlsplit(value)
        if parts.scheme not in schemes:
            raise ImproperlyConfigured(
                f"The environment variable {name} must be a URL starting with "
                f"{' or '.join(s + '://' for s in schemes)}, not {_redact(value)!r}."
            )
        if not (parts.netloc or parts.path):
            raise ImproperlyConfigured(
                f"The environment variable {name} must name a host, not {_redact(value)!r}."
            )
        return value

    def email(self, name: str) -> EmailServer | None:
        """An email server as a URL: ``smtp://user:password@host:587`` (STARTTLS with
        ``smtp+tls://``, TLS from the start with ``smtps://``), or ``console://`` to print the
        emails instead of sending them; None when the variable is unset (no email)."""
        if urlsplit(self.str(name, "")).scheme == "console":
            return EmailServer("django.core.mail.backends.console.EmailBackend")
        value = self.url(name, "", schemes=("smtp", "smtp+tls", "smtps", "console"))
        if not value:
            return None
        parts = urlsplit(value)
        if not parts.hostname:
            raise ImproperlyConfigured(
                f"The environment variable {name} must name the email server's host, "
                f"not {_redact(value)!r}."
            )
        try:
            port = parts.port or (465 if parts.scheme == "smtps" else 25)
        except ValueError:
            raise ImproperlyConfigured(
                f"The environment variable {name} has a port that is not a number: "
                f"{_redact(value)!r}."
            ) from None
        return EmailServer(
            "django.core.mail.backends.smtp.EmailBackend",
            host=parts.hostname,
            port=port,
            user=unquote(parts.username or ""),
            password=unquote(parts.password or ""),
            use_tls=parts.scheme == "smtp+tls",
            use_ssl=parts.scheme == "smtps",
        )

    def path(self, name: str, default: Path | object = _MISSING) -> Path:
        value = self._raw(name, default)
        return Path(value).expanduser().resolve()  # type: ignore[arg-type]

    def secret_key(self, name: str, default: str | object = _MISSING) -> str:
        """A Django secret key strong enough for ``check --deploy``."""
        value = self._raw(name, default)
        if value is default:
            return value  # type: ignore[return-value]
        if len(value) < 50 or len(set(value)) < 5 or value.startswith("django-insecure-"):
            raise ImproperlyConfigured(
                f"The environment variable {name} must be a random string of at least 50 "
                'characters; generate one with: python -c "import secrets; '
                'print(secrets.token_urlsafe(50))"'
            )
        return value


def _redact(url: str) -> str:
    """The URL without its password, for error messages."""
    parts = urlsplit(url)
    if parts.password:
        return url.replace(f":{parts.password}@", ":***@", 1)
    return url


env = Env()
