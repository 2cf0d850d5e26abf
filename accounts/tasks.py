"""Celery tasks of racers' accounts: adapters that call the accounts services."""

from __future__ import annotations

from celery import shared_task

from accounts import services


@shared_task(
    name="accounts.password_reset_email", ignore_result=True, soft_time_limit=60, time_limit=90
)
def password_reset_email(email: str) -> None:
    services.password_reset_email_send(email=email)
