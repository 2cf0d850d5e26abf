from django.apps import AppConfig


class ArchivesConfig(AppConfig):
    name = "archives"
    verbose_name = "Archives"

    def ready(self) -> None:
        from django.contrib.auth.signals import user_logged_out

        from archives import kept_uploads

        user_logged_out.connect(kept_uploads.discard_at_logout, dispatch_uid="kept-upload-logout")
