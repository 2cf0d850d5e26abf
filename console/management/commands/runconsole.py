from django.core.management.base import BaseCommand, CommandError

from console.supervisor import StartError, Supervisor


class Command(BaseCommand):
    help = (
        "Serve the whole console on one machine: a private Redis (unless REDIS_URL is set), the "
        "database set-up, a Celery worker per queue and Daphne, each started again should it "
        "die. Ctrl-C stops all of them."
    )

    def handle(self, *args, **options) -> None:
        try:
            Supervisor.from_environment().run()
        except StartError as error:
            raise CommandError(str(error)) from None
