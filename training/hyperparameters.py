"""DeepRacer's hyperparameters: names, defaults, allowed ranges, and what they mean to SB3.

Stored with a model under DeepRacer's own names (``hyperparameters.json`` of a DeepRacer export),
so an imported model keeps its settings and an exported one reads as DeepRacer's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

PPO = "clipped_ppo"
SAC = "sac"


@dataclass(frozen=True)
class Setting:
    name: str  # DeepRacer's key
    label: str
    default: float | int | str
    low: float | None = None
    high: float | None = None
    choices: tuple = ()
    integer: bool = False

    def check(self, value) -> float | int | str:
        """``value`` in this setting's type, or ValueError with a racer's message."""
        if self.choices:
            if self.integer:
                try:
                    value = int(value)
                except (TypeError, ValueError):
                    value = None
            if value not in self.choices:
                allowed = ", ".join(str(choice) for choice in self.choices)
                raise ValueError(f"{self.label} must be one of {allowed}.")
            return value
        try:
            number = float(value)
        except (TypeError, ValueError):
            raise ValueError(f"{self.label} must be a number.") from None
        if not math.isfinite(number) or not self.low <= number <= self.high:
            raise ValueError(f"{self.label} must be between {self.low:g} and {self.high:g}.")
        if self.integer:
            if number != int(number):
                raise ValueError(f"{self.label} must be a whole number.")
            return int(number)
        return number


BATCH_SIZES = (32, 64, 128, 256, 512)

SETTINGS = {
    PPO: (
        Setting("batch_size", "Gradient descent batch size", 64, choices=BATCH_SIZES, integer=True),
        Setting("num_epochs", "Number of epochs", 10, 3, 10, integer=True),
        Setting("lr", "Learning rate", 3e-4, 1e-8, 1e-3),
        Setting("beta_entropy", "Entropy", 0.01, 0.0, 1.0),
        Setting("discount_factor", "Discount factor", 0.99, 0.0, 1.0),
        Setting("loss_type", "Loss type", "huber", choices=("huber", "mse")),
        Setting("num_episodes_between_training", "Episodes between policy updates", 20, 5, 100,
                integer=True),
    ),
    SAC: (
        Setting("batch_size", "Gradient descent batch size", 64, choices=BATCH_SIZES, integer=True),
        Setting("lr", "Learning rate", 3e-4, 1e-8, 1e-3),
        Setting("sac_alpha", "SAC alpha (entropy)", 0.2, 0.0, 1.0),
        Setting("discount_factor", "Discount factor", 0.99, 0.0, 1.0),
        Setting("loss_type", "Loss type", "mse", choices=("mse",)),
        Setting("num_episodes_between_training", "Episodes between policy updates", 1, 1, 1,
                integer=True),
    ),
}  # fmt: skip


def defaults(algorithm: str) -> dict:
    return {setting.name: setting.default for setting in SETTINGS[algorithm]}


def check(algorithm: str, values: dict) -> tuple[dict, dict[str, str]]:
    """(the complete, typed hyperparameters, {name: error message}) for ``algorithm``."""
    if algorithm not in SETTINGS:
        return {}, {"algorithm": "The algorithm must be PPO or SAC."}
    known = {setting.name for setting in SETTINGS[algorithm]}
    errors = {name: f"{name} is not a hyperparameter of this algorithm." for name in values
              if name not in known}  # fmt: skip
    result = {}
    for setting in SETTINGS[algorithm]:
        try:
            result[setting.name] = setting.check(values.get(setting.name, setting.default))
        except ValueError as error:
            errors[setting.name] = str(error)
    return result, errors
