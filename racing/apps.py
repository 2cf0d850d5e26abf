from django.apps import AppConfig


class RacingConfig(AppConfig):
    name = "racing"
    verbose_name = "League racing"

    def ready(self) -> None:
        from racing import receivers, services  # noqa: F401  (receivers: every account's division)
        from training.signals import evaluation_lapsed, evaluations_waiting

        evaluation_lapsed.connect(services.submission_resend, dispatch_uid="racing.resend")
        evaluations_waiting.connect(services.submissions_waiting, dispatch_uid="racing.waiting")
