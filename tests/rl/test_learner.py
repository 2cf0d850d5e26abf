"""DeepRacer's PPO update: each of SB3's options keeps its meaning in it, and a checkpoint says
what made it."""

import getpass

import gymnasium
import numpy as np
import pytest
import stable_baselines3
import torch
from stable_baselines3.common.utils import FloatSchedule

import simulator
from rl import hyperparameters
from rl.learner import Learner, code_version, weights_metadata
from tests.training.test_stop import synthetic_episode

CONTINUOUS = {"steering_angle": {"low": -30, "high": 30}, "speed": {"low": 0.5, "high": 2}}


@pytest.fixture(scope="module")
def env():
    environment = gymnasium.make(simulator.ENV_ID, track="pitlane-oval", action_space=CONTINUOUS)
    yield environment
    environment.close()


def learner_for(env, **values) -> Learner:
    return Learner(
        algorithm="clipped_ppo",
        hyperparameters={**hyperparameters.defaults("clipped_ppo"), **values},
        architecture="DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
        observation_space=env.observation_space, action_space=env.action_space, seed=7,
    )  # fmt: skip


def driven(learner: Learner, env, steps: int = 48, scale: float = 1.0, offset: float = 0.0):
    """An episode as the learner's own policy would have driven it (so the first ratio is 1),
    with rewards ``scale`` times a fixed pattern; the values it was driven with are ``offset``
    from what the value network says now."""
    episode = synthetic_episode(env, steps=steps)
    episode.rewards = (scale * np.linspace(-1.0, 2.0, steps)).astype(np.float32)
    policy = learner.model.policy
    with torch.no_grad():
        observations = {
            name: torch.as_tensor(frames[:-1]) for name, frames in episode.observations.items()
        }
        observations, _ = policy.obs_to_tensor({k: v.numpy() for k, v in observations.items()})
        values, log_prob, _ = policy.evaluate_actions(
            observations, torch.as_tensor(episode.actions, dtype=torch.float32)
        )
    episode.values = (scale * values.flatten().numpy() + offset).astype(np.float32)
    episode.log_probs = log_prob.numpy().astype(np.float32)
    return episode


def steps_taken(learner: Learner) -> list:
    taken = []
    learner.model.policy.optimizer.register_step_post_hook(lambda *_: taken.append(1))
    return taken


def value_weights(learner: Learner) -> dict[str, torch.Tensor]:
    return {
        name: tensor.clone()
        for name, tensor in learner.model.policy.state_dict().items()
        if name.startswith(("vf_features_extractor", "mlp_extractor.value_net", "value_net"))
    }


def test_the_advantages_are_standardised_over_the_whole_batch_unless_told_not_to(env):
    first_losses = {}
    for normalise in (True, False):
        for scale in (1.0, 10.0):
            learner = learner_for(env, num_epochs=1, batch_size=64)  # one minibatch: one step
            learner.model.normalize_advantage = normalise
            learner.learn([driven(learner, env, scale=scale)])
            first_losses[normalise, scale] = learner.model.last_losses["policy"]
    # Standardised, the policy's loss does not depend on the scale of the rewards; as estimated,
    # it grows with it.
    assert first_losses[True, 10.0] == pytest.approx(first_losses[True, 1.0], abs=1e-5)
    assert first_losses[True, 1.0] == pytest.approx(0.0, abs=1e-5)  # mean zero, ratio one
    assert abs(first_losses[False, 10.0]) > 5 * abs(first_losses[False, 1.0]) > 0


def test_a_value_clip_range_holds_the_values_the_loss_sees_near_the_rollouts(env):
    # The rollout's values are 100 above the network's: clipped to 0.2 of them, the loss sees
    # constants and the value network gets no gradient; unclipped, it learns.
    learner = learner_for(env, num_epochs=2, batch_size=32)
    learner.model.clip_range_vf = FloatSchedule(0.2)
    before = value_weights(learner)
    policy_before = learner.model.policy.action_net.weight.clone()
    learner.learn([driven(learner, env, offset=100.0)])
    after = value_weights(learner)
    assert before and all(torch.equal(before[name], after[name]) for name in before)
    assert not torch.equal(policy_before, learner.model.policy.action_net.weight)

    unclipped = learner_for(env, num_epochs=2, batch_size=32)
    before = value_weights(unclipped)
    unclipped.learn([driven(unclipped, env, offset=100.0)])
    assert not all(
        torch.equal(before[name], tensor) for name, tensor in value_weights(unclipped).items()
    )


def test_a_target_kl_stops_the_update_before_the_step_that_passes_it(env):
    learner = learner_for(env, num_epochs=3, batch_size=16)
    taken = steps_taken(learner)
    learner.learn([driven(learner, env)])
    assert len(taken) == 9  # 3 epochs of 3 minibatches of 16 steps

    learner = learner_for(env, num_epochs=3, batch_size=16, lr=0.003)
    learner.model.target_kl = 1e-6
    taken = steps_taken(learner)
    learner.learn([driven(learner, env)])
    assert 1 <= len(taken) < 9  # the first minibatch is the policy that drove: KL 0, a step


def test_a_checkpoint_says_what_made_it(env):
    learner = learner_for(env)
    metadata = weights_metadata(learner.checkpoint())
    assert metadata == {
        "algorithm": "clipped_ppo",
        "seed": "7",
        "code": code_version(),
        "torch": torch.__version__,
        "stable_baselines3": stable_baselines3.__version__,
    }
    assert code_version().startswith("0.1.0")
    learner.restore(learner.checkpoint())  # the metadata is no obstacle to loading


def test_building_and_training_a_learner_writes_nothing_outside_the_job(env, tmp_path, monkeypatch):
    # SB3 writes its log to a new SB3-<time> folder in the temporary directory unless told where;
    # a trainer builds a learner per job (and per resume), so they would pile up on the machine.
    monkeypatch.setenv("TMPDIR", str(tmp_path))
    monkeypatch.delenv("SB3_LOGDIR", raising=False)
    monkeypatch.setattr("tempfile.tempdir", None)  # read TMPDIR again
    learner = learner_for(env)
    learner.learn([driven(learner, env)])
    compile_cache = f"torchinductor_{getpass.getuser()}"  # one per user, reused by every job
    assert [path.name for path in tmp_path.iterdir() if path.name != compile_cache] == []
