"""Fixtures of the training tests: staff in the admin."""

import pytest
from django.contrib.auth.models import User


@pytest.fixture
def admin_client(client, db):
    """The client logged in as a superuser, marshal (in place of pytest-django's fixture of the
    name)."""
    staff = User.objects.create_superuser("marshal", password="x")
    client.force_login(staff)
    return client
