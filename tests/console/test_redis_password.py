"""`make run`'s private Redis takes a password that the machine generates for itself and keeps
under var/, as it keeps its secret key; every client has it in REDIS_URL, nobody else sees it."""

from __future__ import annotations

import io
import os
import subprocess
import sys
from pathlib import Path

import pytest
import redis

from console.supervisor import Supervisor
from tests.services import ROOT, free_port


def settings_in(var_dir: Path, **env: str) -> str:
    """``REDIS_URL`` as `make run`'s settings make it, in a fresh interpreter."""
    environment = {k: v for k, v in os.environ.items() if not k.startswith(("DJANGO_", "PITLANE_"))}
    environment.pop("REDIS_URL", None)
    environment.update(
        DJANGO_SETTINGS_MODULE="console.settings.dev", PITLANE_VAR_DIR=str(var_dir), **env
    )
    result = subprocess.run(
        [
            sys.executable,
            "-c",
            "import django; django.setup(); "
            "from django.conf import settings; print(settings.REDIS_URL)",
        ],
        cwd=ROOT,
        env=environment,
        capture_output=True,
        text=True,
        timeout=60,
        check=True,
    )
    return result.stdout.strip()


@pytest.mark.slow
def test_the_private_redis_url_holds_a_password_generated_once_and_kept(tmp_path):
    url = settings_in(tmp_path)
    kept = tmp_path / "redis_password"
    password = kept.read_text().strip()
    assert len(password) >= 40
    assert url == f"redis://:{password}@127.0.0.1:6391/0"
    assert kept.stat().st_mode & 0o777 == 0o600
    assert settings_in(tmp_path) == url  # the same on every start
    # A Redis that someone else runs keeps its own URL, and nothing is generated for it.
    other = tmp_path / "elsewhere"
    assert settings_in(other, REDIS_URL="redis://redis.internal:6379/0") == (
        "redis://redis.internal:6379/0"
    )
    assert not (other / "redis_password").exists()


@pytest.fixture
def supervisor(tmp_path, settings):
    port = free_port()
    settings.VAR_DIR = tmp_path
    settings.REDIS_PASSWORD = "generated-" + "x" * 40
    settings.REDIS_URL = f"redis://:{settings.REDIS_PASSWORD}@127.0.0.1:{port}/0"
    started = Supervisor.from_environment()
    started.out = io.StringIO()
    started.var_dir = tmp_path
    try:
        started._start_redis(port)
        started._wait_for_redis()
        yield started, port
    finally:
        started._stop_children()


@pytest.mark.slow
def test_make_runs_redis_answers_only_with_the_password_which_no_command_line_shows(
    supervisor, settings
):
    started, port = supervisor
    with pytest.raises(redis.AuthenticationError):
        redis.Redis(port=port, socket_timeout=5).ping()
    assert redis.Redis.from_url(settings.REDIS_URL, socket_timeout=5).ping()
    command_line = Path(f"/proc/{started.children[0].process.pid}/cmdline").read_text()
    assert settings.REDIS_PASSWORD not in command_line
    assert settings.REDIS_PASSWORD not in started.out.getvalue()
    assert (started.var_dir / "redis" / "redis.conf").stat().st_mode & 0o777 == 0o600
