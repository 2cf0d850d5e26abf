"""The policy the rollout workers and evaluations drive with."""

import gymnasium
import numpy as np
import pytest
import torch

import simulator
from rl.networks import SHALLOW
from rl.policies import Policy
from tests.helpers.models import sensor_frames

DISCRETE = [{"steering_angle": a, "speed": 1.0} for a in (-30, 0, 30)]
CONTINUOUS = {"steering_angle": {"low": -30.0, "high": 30.0}, "speed": {"low": 0.5, "high": 2.0}}


@pytest.mark.slow
@pytest.mark.parametrize(
    ("algorithm", "space"),
    [("clipped_ppo", DISCRETE), ("clipped_ppo", CONTINUOUS), ("sac", CONTINUOUS)],
    ids=["PPO discrete", "PPO continuous", "SAC"],
)
def test_driving_chooses_the_deterministic_action_without_the_critic(algorithm, space):
    environment = {"track": "rookie-loop", "action_space": space}
    env = gymnasium.make(simulator.ENV_ID, **environment)
    torch.manual_seed(3)
    policy = Policy.build(algorithm, SHALLOW, env.observation_space, env.action_space)
    env.close()
    critic_ran = []
    if policy.ppo:
        policy.network.value_net.register_forward_hook(lambda *_: critic_ran.append(True))
    for observation in sensor_frames(environment, count=4):
        tensor, _ = policy.network.obs_to_tensor(observation)
        with torch.no_grad():  # the whole network's deterministic action (the critic's too)
            whole = policy.network if policy.ppo else policy.network.actor
            chosen = whole(tensor, deterministic=True)
            chosen = (chosen[0] if policy.ppo else chosen)[0].numpy()
        critic_ran.clear()
        np.testing.assert_array_equal(policy.drive(observation), chosen)
        assert critic_ran == []


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_the_value_of_an_episodes_last_observation_is_the_critics_as_in_a_step():
    environment = {"track": "rookie-loop", "action_space": DISCRETE}
    env = gymnasium.make(simulator.ENV_ID, **environment)
    torch.manual_seed(3)
    policy = Policy.build("clipped_ppo", SHALLOW, env.observation_space, env.action_space)
    env.close()
    observations = sensor_frames(environment, count=2)
    _, values, _ = policy.explore(observations, [None, None])  # as a car's step records them
    assert [policy.value(observation) for observation in observations] == pytest.approx(
        list(values), rel=1e-5, abs=1e-6
    )
