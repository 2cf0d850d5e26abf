"""DeepRacer's hyperparameters: names, defaults, allowed ranges, and what they mean to SB3.

Stored with a model under DeepRacer's own names and spellings (``ip/hyperparameters.json`` of a
DeepRacer model), so an imported model keeps its settings and an exported one reads as
DeepRacer's. The keys DeepRacer has and this console does not use (``KEPT``) are kept with the
model and written back, so that a model goes to DeepRacer and back without losing them.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field

PPO = "clipped_ppo"
SAC = "sac"
# How a new model's network is laid out (rl.networks): 2 is DeepRacer's, layer for layer;
# 1 was Pitlane's own. A model keeps the layout it was created with.
NETWORK_LAYOUT = 2

# simapp bundle/markov/constants.py:65-69 (01f5f01): DeepRacer's spellings of the loss type.
HUBER = "huber"
MEAN_SQUARED_ERROR = "mean squared error"
LABELS = {HUBER: "Huber", MEAN_SQUARED_ERROR: "Mean squared error"}  # how the form reads them
IN_A_SENTENCE = {HUBER: "Huber", MEAN_SQUARED_ERROR: "mean squared error"}


@dataclass(frozen=True)
class Setting:
    name: str  # DeepRacer's key
    label: str
    default: float | int | str
    low: float | None = None
    high: float | None = None
    choices: tuple = ()
    integer: bool = False
    aliases: dict = field(default_factory=dict)  # another spelling: DeepRacer's

    def check(self, value) -> float | int | str:
        """``value`` in this setting's type, or ValueError with a racer's message."""
        if self.choices:
            if self.integer:
                # int() of Infinity raises OverflowError (an import answered 500), and of 64.9
                # gives 64: a choice is only a whole number that is one
                try:
                    number = float(value)
                    value = int(number) if number == int(number) else None
                except (TypeError, ValueError, OverflowError):
                    value = None
            elif isinstance(value, str):
                # simapp lower-cases the string settings (sagemaker_graph_manager.py:192-199)
                value = value.strip().lower()
                value = self.aliases.get(value, value)
            if value not in self.choices:
                allowed = [IN_A_SENTENCE.get(choice, str(choice)) for choice in self.choices]
                listed = allowed[0] if len(allowed) == 1 else ", ".join(allowed)
                raise ValueError(f"{self.label} must be {'one of ' * (len(allowed) > 1)}{listed}.")
            return value
        if isinstance(value, bool):
            raise ValueError(f"{self.label} must be a number.")
        try:
            number = float(value)
        except OverflowError:  # a whole number of hundreds of digits: no float holds it
            number = math.inf
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
LOSS_ALIASES = {"mse": MEAN_SQUARED_ERROR}  # Pitlane's spelling before DeepRacer's

# What the racer tunes, in the create form's order. The defaults are the DeepRacer console's;
# the discount factor is DeepRacer's 0.999 (simapp bundle/markov/sagemaker_graph_manager.py:196-197
# (01f5f01) falls back to it).
SETTINGS = {
    PPO: (
        Setting("batch_size", "Gradient descent batch size", 64, choices=BATCH_SIZES, integer=True),
        Setting("num_epochs", "Number of epochs", 10, 3, 10, integer=True),
        Setting("lr", "Learning rate", 3e-4, 1e-8, 1e-3),
        Setting("beta_entropy", "Entropy", 0.01, 0.0, 1.0),
        Setting("discount_factor", "Discount factor", 0.999, 0.0, 1.0),
        Setting(
            "loss_type",
            "Loss type",
            HUBER,
            choices=(HUBER, MEAN_SQUARED_ERROR),
            aliases=LOSS_ALIASES,
        ),
        Setting(
            "num_episodes_between_training",
            "Episodes between policy updates",
            20,
            5,
            100,
            integer=True,
        ),
    ),
    SAC: (
        Setting("batch_size", "Gradient descent batch size", 64, choices=BATCH_SIZES, integer=True),
        Setting("lr", "Learning rate", 3e-4, 1e-8, 1e-3),
        Setting("sac_alpha", "SAC alpha (entropy)", 0.2, 0.0, 1.0),
        Setting("discount_factor", "Discount factor", 0.999, 0.0, 1.0),
        Setting(
            "loss_type",
            "Loss type",
            MEAN_SQUARED_ERROR,
            choices=(MEAN_SQUARED_ERROR,),
            aliases=LOSS_ALIASES,
        ),
        Setting(
            "num_episodes_between_training",
            "Episodes between policy updates",
            1,
            1,
            1,
            integer=True,
        ),
    ),
}

# DeepRacer's other keys (simapp bundle/markov/constants.py:72-89, 01f5f01), which this console
# does not use: kept with the model as given and written back on export. Their defaults are
# simapp's (sagemaker_graph_manager.py:189-205), which it writes into every hyperparameters.json.
KEPT = (
    Setting("stack_size", "Stack size", 1, 1, 1000, integer=True),
    Setting("exploration_type", "Exploration type", "categorical",
            choices=("categorical", "e-greedy")),  # constants.py:58-62
    Setting("e_greedy_value", "E-greedy value", 0.05, 0.0, 1.0),
    Setting("epsilon_steps", "Epsilon steps", 10000, 0, 10**9, integer=True),
    Setting("term_cond_max_episodes", "Maximum episodes", 100000, 1, 10**9, integer=True),
    Setting("term_cond_avg_score", "Average score to stop at", 100000.0, -1e12, 1e12),
)  # fmt: skip
KEPT_BY_NAME = {setting.name: setting for setting in KEPT}
# simapp writes beta_entropy and num_epochs for PPO only and sac_alpha for SAC only
# (sagemaker_graph_manager.py:210-217); given to the other algorithm, they are kept too.
OTHER_ALGORITHM = {
    PPO: {s.name: s for s in SETTINGS[SAC] if s.name not in {t.name for t in SETTINGS[PPO]}},
    SAC: {s.name: s for s in SETTINGS[PPO] if s.name not in {t.name for t in SETTINGS[SAC]}},
}
DEEPRACER_KEYS = frozenset(
    {s.name for settings in SETTINGS.values() for s in settings} | set(KEPT_BY_NAME)
)


def kept_settings(algorithm: str) -> dict[str, Setting]:
    """The DeepRacer keys ``algorithm``'s models keep without using them, by name."""
    return {**KEPT_BY_NAME, **OTHER_ALGORITHM.get(algorithm, {})}


def defaults(algorithm: str) -> dict:
    """What a new model stores: the settings it uses and DeepRacer's others, at their defaults."""
    return {setting.name: setting.default for setting in (*SETTINGS[algorithm], *KEPT)}


def setting(algorithm: str, name: str) -> Setting | None:
    """The setting ``name`` of ``algorithm``'s models, used or kept; None for a key that is not
    DeepRacer's."""
    used = {s.name: s for s in SETTINGS.get(algorithm, ())}
    return used.get(name) or kept_settings(algorithm).get(name)


def spelled(algorithm: str, name: str, value):
    """``value`` of the setting ``name`` as DeepRacer spells it ("mse" is "mean squared
    error"); as it is when it is not one of the setting's values."""
    each = setting(algorithm, name)
    try:
        return each.check(value) if each else value
    except ValueError:
        return value


def unknown_message(name: str) -> str:
    return (
        f"“{name}” is not one of DeepRacer's hyperparameters; they are "
        f"{', '.join(sorted(DEEPRACER_KEYS))}."
    )


def check(algorithm: str, values: dict) -> tuple[dict, dict[str, str]]:
    """(the complete, typed hyperparameters, {name: error message}) for ``algorithm``: the
    settings it uses and DeepRacer's others (``KEPT``), each given or at its default."""
    if algorithm not in SETTINGS:
        return {}, {"algorithm": "The algorithm must be PPO or SAC."}
    errors = {
        str(name): unknown_message(name) for name in values if setting(algorithm, name) is None
    }
    result = {}
    for each in (*SETTINGS[algorithm], *KEPT):
        try:
            result[each.name] = each.check(values.get(each.name, each.default))
        except ValueError as error:
            errors[each.name] = str(error)
    for name, other in OTHER_ALGORITHM[algorithm].items():
        if name in values:
            try:
                result[name] = other.check(values[name])
            except ValueError as error:
                errors[name] = str(error)
    return result, errors


def deepracer_file(algorithm: str, stored: dict) -> dict:
    """``hyperparameters.json`` as DeepRacer writes it for a model that stores ``stored``: every
    key of the algorithm (those missing at DeepRacer's defaults), in DeepRacer's spellings."""
    values, _ = check(algorithm, {})
    values.update({name: spelled(algorithm, name, value) for name, value in stored.items()})
    return dict(sorted(values.items()))  # simapp: json.dumps(..., sort_keys=True)


def deepracer_json(algorithm: str, stored: dict) -> str:
    """``deepracer_file`` as simapp writes it: sorted keys, indented by 2
    (bundle/markov/sagemaker_graph_manager.py:233, 01f5f01)."""
    return json.dumps(deepracer_file(algorithm, stored), indent=2, sort_keys=True)
