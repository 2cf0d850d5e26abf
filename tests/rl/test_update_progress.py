"""An update tells how far it has gone, step by step, so that the racer's page can say it."""

import pytest

from rl import hyperparameters
from rl import learner as learner_module
from rl.learner import Interrupted, Learner
from tests.helpers.learning import driven, learner_for, steps_taken, synthetic_episode


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_a_ppo_update_tells_its_minibatches_done_of_all_its_epochs(env):
    learner = learner_for(env, num_epochs=3, batch_size=16)
    told, taken = [], steps_taken(learner)
    learner.learn([driven(learner, env, steps=40)], progress=lambda *seen: told.append(seen))
    # 3 epochs of 3 minibatches (16, 16 and 8 of the 40 steps): one word after each.
    assert told == [(done, 9) for done in range(1, 10)]
    assert len(taken) == 9


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_a_ppo_update_that_a_target_kl_ends_early_still_ends_at_its_total(env):
    learner = learner_for(env, num_epochs=3, batch_size=16, lr=0.003)
    learner.model.target_kl = 1e-6
    told = []
    learner.learn([driven(learner, env)], progress=lambda *seen: told.append(seen))
    dones = [done for done, _ in told]
    assert dones == sorted(dones) and len(set(dones)) == len(dones)
    assert 2 <= len(told) < 10 and told[-1] == (9, 9)


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_a_sac_update_tells_its_gradient_steps_done_chunk_by_chunk(env, monkeypatch):
    monkeypatch.setattr(learner_module, "SAC_CHUNK", 2)  # few steps, cheap ones, several chunks
    learner = Learner(
        algorithm="sac",
        hyperparameters={**hyperparameters.defaults("sac"), "batch_size": 4},
        architecture="DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
        observation_space=env.observation_space,
        action_space=env.action_space,
    )
    told = []
    learner.learn([synthetic_episode(env, steps=5)], progress=lambda *seen: told.append(seen))
    assert told == [(2, 5), (4, 5), (5, 5)]


def test_an_update_abandoned_never_says_it_finished(env):
    learner = learner_for(env, num_epochs=3, batch_size=16)
    told, asked = [], []

    def interrupted() -> bool:
        asked.append(True)
        return len(asked) > 1

    with pytest.raises(Interrupted):
        learner.learn(
            [driven(learner, env, steps=40)],
            interrupted=interrupted,
            progress=lambda *seen: told.append(seen),
        )
    assert told == [(1, 9)]
