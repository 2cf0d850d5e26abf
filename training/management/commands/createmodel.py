from pathlib import Path

import yaml
from django.contrib.auth import get_user_model
from django.core.management.base import BaseCommand, CommandError

from common.refusals import Refused
from rl import hyperparameters
from training.management.lookup import redis_check
from training.services import model_create


class Command(BaseCommand):
    help = (
        "Create a model and queue its training, from a YAML file of settings (the create-model "
        "page's fields: name, track, direction, race_type, boxes, bots, sensors, network, "
        "action_space, algorithm, hyperparameters, max_minutes, workers, extra_tracks) and a "
        "reward function file."
    )

    def add_arguments(self, parser) -> None:
        parser.add_argument("--config", type=Path, required=True, help="the settings, YAML")
        parser.add_argument("--reward", type=Path, required=True, help="the reward function")
        parser.add_argument("--owner", required=True, help="the racer who owns the model")

    def handle(self, *args, config: Path, reward: Path, owner: str, **options) -> None:
        owner_row = get_user_model().objects.filter(username=owner).first()
        if owner_row is None:
            raise CommandError(f"No racer named {owner!r}.")
        try:
            settings = yaml.safe_load(config.read_text()) or {}
            source = reward.read_text()
        except (OSError, UnicodeDecodeError, yaml.YAMLError) as error:
            raise CommandError(f"Cannot read the settings: {error}") from None
        if not isinstance(settings, dict):
            raise CommandError(f"{config} must hold a mapping of settings.")
        redis_check("No model was created.")
        algorithm = settings.get("algorithm", hyperparameters.PPO)
        settings.setdefault("hyperparameters", hyperparameters.defaults(algorithm))
        try:
            model = model_create(owner=owner_row, settings={**settings, "reward_function": source})
        except Refused as refused:
            raise CommandError(refused.told("The model was not created")) from None
        self.stdout.write(f"Created model {model.name} (#{model.pk}); its training is queued.")
