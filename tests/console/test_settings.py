"""Production settings, checked in a fresh interpreter exactly as an operator would run them."""

import os
import subprocess
import sys

from tests.services import ROOT

PRODUCTION = {
    "DJANGO_SETTINGS_MODULE": "console.settings.prod",
    "DJANGO_SECRET_KEY": "k3Jv0-lq8Zr2WmXn5yTb7Hs1Pd4Cf6Ag9Ue0Ro2Iw5Ly8Nz1Kx3Mv6Bt9Qp4Sa7Dj",
    "DJANGO_ALLOWED_HOSTS": "pitlane.example.org",
    "DATABASE_URL": "postgres://pitlane:secret@db.internal:5432/pitlane",
    "REDIS_URL": "redis://redis.internal:6379/0",
    "PITLANE_S3_BUCKET": "pitlane-artifacts",
    "PITLANE_S3_REGION": "eu-west-1",
}


def manage(*args: str, **env: str) -> subprocess.CompletedProcess:
    environment = {k: v for k, v in os.environ.items() if not k.startswith(("DJANGO_", "PITLANE_"))}
    environment.pop("REDIS_URL", None)
    environment.pop("DATABASE_URL", None)
    return subprocess.run(
        [sys.executable, "manage.py", *args],
        cwd=ROOT,
        env={**environment, **env},
        capture_output=True,
        text=True,
        timeout=120,
    )


def test_check_deploy_reports_no_warnings_with_production_settings():
    result = manage("check", "--deploy", "--fail-level", "WARNING", **PRODUCTION)
    assert result.returncode == 0, result.stderr
    assert "System check identified no issues (0 silenced)." in result.stdout


def test_production_settings_name_a_missing_secret_key():
    settings = {k: v for k, v in PRODUCTION.items() if k != "DJANGO_SECRET_KEY"}
    result = manage("check", **settings)
    assert result.returncode != 0
    assert "The environment variable DJANGO_SECRET_KEY must be set." in result.stderr


def test_production_settings_refuse_any_host():
    result = manage("check", **{**PRODUCTION, "DJANGO_ALLOWED_HOSTS": "pitlane.example.org,*"})
    assert result.returncode != 0
    assert "DJANGO_ALLOWED_HOSTS must name the console's hosts" in result.stderr


def printed_in_production(code: str) -> list[str]:
    """The words ``code`` prints in a shell under the production settings."""
    result = manage("shell", "--no-imports", "-c", code, **PRODUCTION)
    assert result.returncode == 0, result.stderr
    return result.stdout.split()


def test_production_settings_switch_artifacts_to_the_s3_bucket():
    assert printed_in_production(
        "from django.core.files.storage import storages; s = storages['default']; "
        "print(type(s).__name__, s.bucket_name, s.region_name)"
    ) == ["S3Storage", "pitlane-artifacts", "eu-west-1"]


def test_production_settings_use_the_database_url():
    assert printed_in_production(
        "from django.conf import settings as s; d = s.DATABASES['default']; "
        "print(d['ENGINE'], d['HOST'], d['NAME'])"
    ) == ["django.db.backends.postgresql", "db.internal", "pitlane"]


def test_a_bad_value_stops_start_up_with_a_clear_message():
    result = manage("check", DJANGO_SETTINGS_MODULE="console.settings.dev", DJANGO_DEBUG="maybe")
    assert result.returncode != 0
    assert "DJANGO_DEBUG must be true or false" in result.stderr
