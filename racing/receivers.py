"""Every account has its place in the league as it is made, however it is made (the sign-up
page, the admin, ``createsuperuser``): staff can set the division of a racer who has not yet
opened a race page, and the monthly promotion sees every racer."""

from django.conf import settings
from django.db.models.signals import post_save
from django.dispatch import receiver

from racing.models import Racer


@receiver(post_save, sender=settings.AUTH_USER_MODEL, dispatch_uid="racing.racer_create")
def _racer_for_new_account(sender, instance, created: bool, raw: bool = False, **kwargs) -> None:
    if created and not raw:
        Racer.objects.get_or_create(user=instance)
