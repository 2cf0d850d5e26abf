"""Every account gets a profile as it is made, however it is made: the sign-up page, the admin,
``createsuperuser`` or a test's ``create_user``; leaderboards can then always show one."""

from django.conf import settings
from django.db.models.signals import post_save
from django.dispatch import receiver

from accounts.services import profile_create


@receiver(post_save, sender=settings.AUTH_USER_MODEL, dispatch_uid="accounts.profile_create")
def _profile_for_new_account(sender, instance, created: bool, raw: bool = False, **kwargs) -> None:
    if created and not raw:
        profile_create(user=instance)
