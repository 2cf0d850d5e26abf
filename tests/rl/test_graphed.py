"""PPO's minibatch step replayed from a graph (rl.graphed) learns what the eager step learns.

The CUDA capture itself needs a GPU (test_learner's GPU test runs it there); here a capture that
warms the step up as ``cuda_capture`` does and replays it eagerly checks everything around it:
the fixed inputs each minibatch is copied into, the warm-up's steps undone, the eager step of a
short last minibatch on the graph's gradients, a new capture when the learning rate changes."""

import copy

import gymnasium
import numpy as np
import pytest
import torch

import simulator
from rl.graphed import WARM_UP_STEPS, GraphedStep
from tests.helpers.learning import driven, learner_for


@pytest.fixture
def argument_checks(monkeypatch):
    """Distributions' argument checks as they were, after a graphed step turned them off."""
    monkeypatch.setattr(
        torch.distributions.Distribution,
        "_validate_args",
        torch.distributions.Distribution._validate_args,
    )


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
@pytest.mark.usefixtures("argument_checks")
def test_a_graphed_update_learns_what_the_eager_update_learns():
    spaces = gymnasium.make(simulator.ENV_ID, track="pitlane-oval")  # DeepRacer's discrete actions
    captures = []

    def warmed_up(step):
        captures.append(step)
        for _ in range(WARM_UP_STEPS):
            step()
        return step

    learner = learner_for(spaces, num_epochs=2, batch_size=16)
    model, policy = learner.model, learner.model.policy
    start = copy.deepcopy(policy.state_dict())
    episodes = [driven(learner, spaces, steps=40), driven(learner, spaces, steps=40, scale=3.0)]
    runs = {}
    for graphed in (False, True):
        policy.load_state_dict(start)
        # the graph's own optimiser for both, so that only the step's handling can differ
        policy.optimizer = torch.optim.Adam(
            policy.parameters(), lr=3e-4, eps=1e-5, fused=True, capturable=True
        )
        model.learning_rate = 3e-4
        model._setup_lr_schedule()
        model.graphed = GraphedStep(model, warmed_up) if graphed else None
        np.random.seed(3)  # the shuffles: numpy's global generator, as SB3's
        losses = []
        for episode in episodes:  # two updates: 40 steps, minibatches of 16, 16 and 8
            learner.learn([episode])
            losses.append(model.last_losses)
        # and one at a new learning rate, which a graph has baked in: captured anew
        model.learning_rate = 1e-3
        model._setup_lr_schedule()
        learner.learn([episodes[0]])
        assert policy.optimizer.param_groups[0]["lr"] == 1e-3
        losses.append(model.last_losses)
        runs[graphed] = copy.deepcopy(policy.state_dict()), losses

    assert len(captures) == 2  # once for both updates at the first rate, once at the second
    group = policy.optimizer.param_groups[0]
    assert group["fused"] and group["capturable"]  # what a CUDA graph's capture asks of Adam
    assert not torch.equal(start["action_net.weight"], runs[True][0]["action_net.weight"])
    for name, tensor in runs[False][0].items():
        torch.testing.assert_close(runs[True][0][name], tensor, rtol=0, atol=0)
    assert runs[True][1] == runs[False][1]  # the losses, each update's


def test_a_graphed_step_refuses_what_it_cannot_replay():
    spaces = gymnasium.make(simulator.ENV_ID, track="pitlane-oval")
    learner = learner_for(spaces, num_epochs=1, batch_size=16)
    learner.model.target_kl = 0.01
    with pytest.raises(ValueError, match="target KL"):
        GraphedStep(learner.model)
