from django.core.management.base import BaseCommand, CommandError

from console.supervisor import StartError, Supervisor


class Command(BaseCommand):
    help = (
        "Serve the whole console on one machine: a private Redis (unless REDIS_URL is set), the "
        "database set-up, one Celery worker and Daphne. Ctrl-C stops all of them."
    )

    def handle(self, *args, **options) -> None:
        try:
            code = Supervisor.from_environment().run()
        except StartError as error:
            raise CommandError(str(error)) from None
        if code:
            raise CommandError(
                "Pitlane stopped because one of its processes failed.", returncode=code
            )
