"""The help page's guidance: what each hyperparameter does, and what raising or lowering it
changes, in the spirit of DeepRacer's own advice. Ranges and defaults are read from
``rl.hyperparameters``, so the page cannot disagree with the form."""

from __future__ import annotations

from dataclasses import dataclass

from rl import hyperparameters
from rl.hyperparameters import Setting
from simulator.config import CONTROL_HZ

# name: (what it is, raising it, lowering it)
GUIDANCE = {
    "batch_size": (
        "How many recent experiences (steps) are drawn at random from the buffer for each "
        "gradient step of the network.",
        "Steadier, smoother updates; each update takes longer.",
        "Quicker, noisier updates; with a small batch, fewer epochs are usually enough.",
    ),
    "num_epochs": (
        "How many passes the update makes over the experience gathered since the last update.",
        "More stable learning from the same experience, but slower training.",
        "Faster training; use fewer epochs with a small batch size. Without a GPU the update "
        "is most of the training time: with 3, a fast continuous model drove 3 clean laps "
        "after about 5 minutes of training instead of 30 (docs/benchmarks.md's training figures).",
    ),
    "lr": (
        "How big a step each update takes toward better behaviour.",
        "Faster learning, but past a point the reward stops converging and can collapse.",
        "Slower, steadier learning; useful late in training or when cloning a good model.",
    ),
    "beta_entropy": (
        "How much randomness PPO keeps in the car's choices so that it goes on trying actions.",
        "More exploration: useful when the car settles on a poor line too early.",
        "The car commits sooner to what it knows: faster, but it may miss a better line.",
    ),
    "discount_factor": (
        "How much rewards further ahead count when the car weighs an action. The car looks "
        "ahead about 1 / (1 - discount) steps (see the table below).",
        "The car plans further ahead (braking before a bend, lining up a turn); training is "
        "slower.",
        "The car cares about the next few steps only: quicker to train, more short-sighted. "
        "Without a GPU a fast continuous model (1-4 m/s) with 0.97 drove 3 clean laps within "
        "2.5 minutes in each of 4 runs, and after 20 minutes lapped in 6.5-7.3 s (a braking "
        "driver laps in 6.7 s; docs/benchmarks.md's training figures).",
    ),
    "loss_type": (
        "How the size of a prediction error is turned into an update. Huber and mean squared "
        "error behave alike for small errors; for large ones Huber takes smaller steps.",
        "choose it when training is unstable or does not converge.",
        "choose it when training converges well and you want it faster.",
    ),
    "num_episodes_between_training": (
        "How many episodes of experience the car gathers before each policy update.",
        "More varied, less correlated experience per update: slower but more stable, useful "
        "for hard tracks and complex reward functions (try 20 or 40).",
        "More frequent updates: enough for a simple track and reward (try 10).",
    ),
    "sac_alpha": (
        "SAC's entropy weight: how much the car is rewarded for keeping its actions varied.",
        "More exploration of steering and speed.",
        "More exploitation of what the car already does well.",
    ),
}


@dataclass(frozen=True)
class HyperparameterHelp:
    algorithm: str
    name: str
    label: str
    allowed: str
    default: str
    meaning: str
    raising: str
    lowering: str

    fixed: bool  # one allowed value: nothing to tune

    @property
    def anchor(self) -> str:
        return f"{self.algorithm}-{self.name}".replace("_", "-")

    @property
    def hints(self) -> list[tuple[str, str]]:
        """(what to do, what it changes), for a setting the racer can tune."""
        if self.fixed:
            return []
        if self.name == "loss_type":
            return [("Huber", self.raising), ("Mean squared error", self.lowering)]
        return [("Raise it", self.raising), ("Lower it", self.lowering)]


def _allowed(setting: Setting) -> str:
    if setting.choices:
        if len(setting.choices) == 1:
            return f"{_spelled(setting.choices[0])} only"
        shown = [_spelled(choice) for choice in setting.choices]
        return ", ".join(shown[:-1]) + " or " + shown[-1]
    if setting.low == setting.high:
        return f"{_spelled(setting.low)} only"
    return f"{_spelled(setting.low)} to {_spelled(setting.high)}"


def _spelled(value) -> str:
    """A setting's value as a racer reads it: "Huber", 1e-8 (not 1e-08), 10."""
    names = {"huber": "Huber", "mse": "mean squared error"}
    if isinstance(value, str):
        return names.get(value, value)
    return f"{value:g}".replace("e-0", "e-")  # 1e-8, not 1e-08


def hyperparameter_help() -> dict[str, list[HyperparameterHelp]]:
    """Each algorithm's hyperparameters, in the create form's order, with their guidance."""
    return {
        algorithm: [
            HyperparameterHelp(
                algorithm,
                setting.name,
                setting.label,
                _allowed(setting),
                _spelled(setting.default),
                *GUIDANCE[setting.name],
                fixed=len(setting.choices) == 1
                or (setting.low is not None and setting.low == setting.high),
            )
            for setting in settings
        ]
        for algorithm, settings in hyperparameters.SETTINGS.items()
    }


def lookahead(discount: float) -> tuple[int, float]:
    """(steps, simulated seconds) the car looks ahead with this discount factor."""
    steps = round(1 / (1 - discount))
    return steps, steps / CONTROL_HZ
