"""DeepRacer's PPO update: each of SB3's options keeps its meaning in it, and a checkpoint says
what made it."""

import contextlib
import copy
import getpass
import warnings

import gymnasium
import numpy as np
import pytest
import stable_baselines3
import torch
from stable_baselines3 import SAC
from stable_baselines3.common.utils import FloatSchedule
from stable_baselines3.common.vec_env import DummyVecEnv

import simulator
from rl import hyperparameters
from rl.learner import Learner, SpacesOnly, code_version, update_precision, weights_metadata
from rl.networks import lower_precision
from rl.ppo import sb3_minibatches
from rl.sac import DeepRacerSAC, Replay
from tests.helpers.learning import driven, learner_for, steps_taken, synthetic_episode

SMALL_OBSERVATIONS = gymnasium.spaces.Dict({"lidar": gymnasium.spaces.Box(0, 1, (4,))})
SMALL_ACTIONS = gymnasium.spaces.Box(-1, 1, (2,))


def value_weights(learner: Learner) -> dict[str, torch.Tensor]:
    return {
        name: tensor.clone()
        for name, tensor in learner.model.policy.state_dict().items()
        if name.startswith(("vf_features_extractor", "mlp_extractor.value_net", "value_net"))
    }


@pytest.mark.slow
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


@pytest.mark.slow
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


@pytest.mark.slow
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


def test_an_update_stopped_before_its_first_minibatch_ends_cleanly_with_no_losses(env):
    learner = learner_for(env, num_epochs=3, batch_size=16)
    episode = driven(learner, env)
    with torch.no_grad():
        learner.model.policy.action_net.bias.add_(0.5)  # the episodes were another policy's
    learner.model.target_kl = 1e-6  # so the first minibatch is already past 1.5 times it
    taken = steps_taken(learner)
    learner.learn([episode])
    assert taken == []
    assert learner.model.last_losses == {}


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


@pytest.mark.slow
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


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_minibatches_cut_on_the_device_make_the_same_update_as_sb3s_buffer(monkeypatch):
    spaces = gymnasium.make(simulator.ENV_ID, track="pitlane-oval")  # DeepRacer's discrete actions
    learner = learner_for(spaces, num_epochs=2, batch_size=16)
    policy = learner.model.policy
    start = copy.deepcopy((policy.state_dict(), policy.optimizer.state_dict()))
    episode = driven(learner, spaces, steps=40)
    weights = []
    for reference in (False, True):
        policy.load_state_dict(start[0])
        policy.optimizer.load_state_dict(start[1])
        if reference:
            monkeypatch.setattr(
                learner.model, "_minibatches", lambda: sb3_minibatches(learner.model)
            )
        np.random.seed(3)  # the shuffles: numpy's global generator, as SB3's
        learner.learn([episode])
        weights.append(copy.deepcopy(policy.state_dict()))
    assert not torch.equal(start[0]["action_net.weight"], weights[0]["action_net.weight"])
    for name, tensor in weights[0].items():
        torch.testing.assert_close(tensor, weights[1][name], rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize(
    "option, refusal",
    [
        ({"ent_coef": "auto"}, "a fixed alpha"),
        ({"target_update_interval": 2}, "its target critics every gradient step"),
        ({"use_sde": True}, "no state-dependent exploration"),
    ],
)
def test_sac_refuses_the_sb3_options_its_gradient_step_does_not_follow(option, refusal):
    spaces_only = DummyVecEnv([lambda: SpacesOnly(SMALL_OBSERVATIONS, SMALL_ACTIONS)])
    with pytest.raises(ValueError, match=refusal):
        DeepRacerSAC("MultiInputPolicy", spaces_only, replay_size=8, **{"ent_coef": 0.2, **option})


def test_sacs_gradient_steps_learn_as_sb3s_from_the_same_batches(env, monkeypatch):
    learner = learner_for(env, "sac", batch_size=8)
    model = learner.model
    model.replay.add(synthetic_episode(env, steps=12))
    start = copy.deepcopy(
        (
            model.policy.state_dict(),
            model.actor.optimizer.state_dict(),
            model.critic.optimizer.state_dict(),
        )
    )
    batches, sample = [], model.replay.sample
    monkeypatch.setattr(
        model.replay, "sample", lambda size: batches.append(sample(size)) or batches[-1]
    )
    torch.manual_seed(5)  # the actor's draws, in the same order in both
    model.train(gradient_steps=3, batch_size=8)
    ours = copy.deepcopy(model.policy.state_dict())

    model.policy.load_state_dict(start[0])
    model.actor.optimizer.load_state_dict(start[1])
    model.critic.optimizer.load_state_dict(start[2])
    monkeypatch.setattr(model.replay_buffer, "sample", lambda *_, **__: batches.pop(0))
    torch.manual_seed(5)
    SAC.train(model, gradient_steps=3, batch_size=8)  # SB3's own step
    assert not batches
    assert not torch.equal(start[0]["actor.mu.weight"], ours["actor.mu.weight"])
    for name, tensor in model.policy.state_dict().items():  # critics, actor, target critics
        torch.testing.assert_close(ours[name], tensor, rtol=1e-5, atol=1e-6)


def test_the_replay_buffer_overwrites_its_oldest_and_marks_only_an_ending_done(env):
    replay = Replay(5, env.observation_space, 2, "cpu", seed=0)
    first, second = synthetic_episode(env, steps=3), synthetic_episode(env, steps=3)
    first.rewards, second.rewards = np.array([1, 2, 3], "f"), np.array([4, 5, 6], "f")
    second.terminated = False  # truncated: its last state is not terminal
    for frames in first.observations.values():
        frames.flags.writeable = False  # as decoded from Redis (np.frombuffer)
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # torch warns of a read-only array it would share
        replay.add(first)
    replay.add(second)
    assert (replay.size, replay.position) == (5, 1)
    assert replay.rewards.flatten().tolist() == [6, 2, 3, 4, 5]
    assert replay.dones.flatten().tolist() == [0, 0, 1, 0, 0]
    camera = replay.next_observations["FRONT_FACING_CAMERA"]
    assert torch.equal(camera[0], torch.as_tensor(second.observations["FRONT_FACING_CAMERA"][3]))
    batch = replay.sample(64)
    assert batch.rewards.shape == (64, 1) and set(batch.rewards.flatten().tolist()) <= {
        2,
        3,
        4,
        5,
        6,
    }


def camera_frames(env, steps: int = 64) -> tuple[dict[str, np.ndarray], np.ndarray]:
    """Frames as a car sees them driving (not noise), and the random actions it drove."""
    observation, _ = env.reset(seed=0)
    frames, actions = [], []
    for _ in range(steps):
        frames.append(observation)
        actions.append(env.action_space.sample())
        observation, _, terminated, truncated, _ = env.step(actions[-1])
        if terminated or truncated:
            observation, _ = env.reset()
    return {name: np.stack([f[name] for f in frames]) for name in frames[0]}, np.stack(actions)


def test_bf16_features_move_the_log_probabilities_far_less_than_ppos_clip(env):
    learner = learner_for(env, num_epochs=1, batch_size=64)
    policy = learner.model.policy
    with torch.no_grad():
        policy.action_net.weight.mul_(100)  # a head of gain 1, as a policy that has learnt
    frames, actions = camera_frames(env)
    observations, _ = policy.obs_to_tensor(frames)
    actions = torch.as_tensor(actions)

    def log_probs(precision) -> torch.Tensor:
        with torch.no_grad(), lower_precision(policy, precision):
            return policy.evaluate_actions(observations, actions)[1]

    full, lower = log_probs(None), log_probs(torch.bfloat16)
    # Measured 0.013 at most (3-layer CNN, 64 frames of the Pitlane Oval), beside PPO's clip of
    # 0.2 on the ratio: the first minibatch's ratios start within 1.3% of 1, not exactly 1.
    assert 0 < (lower - full).abs().max() < 0.05
    assert torch.equal(log_probs(None), full)  # and acting is float32 again after the update


@pytest.mark.slow  # 2 s or more (make test-quick leaves it out)
def test_a_learner_computes_its_updates_features_in_the_precision_it_is_given(env):
    seen = []
    learner = Learner(
        algorithm="clipped_ppo",
        hyperparameters={**hyperparameters.defaults("clipped_ppo"), "num_epochs": 1},
        architecture="DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
        observation_space=env.observation_space,
        action_space=env.action_space,
        precision="bf16",
    )
    extractor = learner.model.policy.pi_features_extractor
    extractor.register_forward_hook(lambda module, *_: seen.append(module.precision))
    learner.learn([driven(learner, env, steps=8)])
    assert set(seen[1:]) == {torch.bfloat16}  # the first: driven's, outside the update
    assert extractor.precision is None
    assert update_precision("fp32", torch.device("cpu")) is None
    with pytest.raises(ValueError, match="one of fp32, bf16, auto, not 'fp16'"):
        update_precision("fp16", torch.device("cpu"))


def test_auto_precision_is_bf16_only_where_the_learners_device_computes_it_natively(monkeypatch):
    asked = []

    @contextlib.contextmanager
    def on(device):
        asked.append(("on", device))
        yield

    def gpu_has_bf16(including_emulation: bool = True) -> bool:
        asked.append(("emulation", including_emulation))
        return native

    monkeypatch.setattr(torch.cuda, "device", on)
    monkeypatch.setattr(torch.cuda, "is_bf16_supported", gpu_has_bf16)
    second_gpu = torch.device("cuda:1")
    for native in (True, False):
        for avx512, amx in ((native, False), (False, native)):
            monkeypatch.setattr(torch.cpu, "_is_avx512_bf16_supported", lambda v=avx512: v)
            monkeypatch.setattr(torch.cpu, "_is_amx_tile_supported", lambda v=amx: v)
            chosen = torch.bfloat16 if native else None
            assert update_precision("auto", torch.device("cpu")) == chosen
        assert update_precision("auto", second_gpu) == chosen
    # A GPU that only emulates bf16 (before Ampere) is not native; asked of the learner's own GPU.
    assert asked == [("on", second_gpu), ("emulation", False)] * 2


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a GPU")
def test_on_a_gpu_a_ppo_update_learns_there_what_it_learns_on_the_cpu(env, monkeypatch):
    monkeypatch.setattr(torch.backends.cudnn, "allow_tf32", False)  # float32 as the CPU's
    monkeypatch.setattr(torch.backends.cuda.matmul, "allow_tf32", False)
    weights, episode = {}, None
    for device in ("cpu", "cuda"):
        learner = Learner(
            algorithm="clipped_ppo",
            hyperparameters={
                **hyperparameters.defaults("clipped_ppo"),
                "num_epochs": 2,
                "batch_size": 16,
            },
            architecture="DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
            observation_space=env.observation_space,
            action_space=env.action_space,
            seed=7,
            device=device,
        )
        assert learner.device.startswith(device)
        # on the GPU its minibatch step is replayed from a CUDA graph (rl.graphed), the last
        # short one (40 steps, minibatches of 16) stepped eagerly: both are checked here
        assert (learner.model.graphed is not None) == (device == "cuda")
        episode = episode or driven(learner, env, steps=40)
        np.random.seed(3)
        learner.learn([episode])
        weights[device] = {k: v.cpu() for k, v in learner.model.policy.state_dict().items()}
    for name, tensor in weights["cpu"].items():
        torch.testing.assert_close(weights["cuda"][name], tensor, rtol=1e-4, atol=1e-5)


@pytest.mark.skipif(not torch.cuda.is_available(), reason="needs a GPU")
def test_on_a_gpu_sac_keeps_its_replay_buffer_and_learns_there(env):
    learner = Learner(
        algorithm="sac",
        hyperparameters={**hyperparameters.defaults("sac"), "batch_size": 8},
        architecture="DEEP_CONVOLUTIONAL_NETWORK_SHALLOW",
        observation_space=env.observation_space,
        action_space=env.action_space,
        device="cuda",
    )
    before = learner.model.actor.mu.weight.clone()
    learner.learn([synthetic_episode(env, steps=6)])
    assert learner.model.replay.rewards.device.type == "cuda"
    assert learner.model.replay.size == 6
    assert not torch.equal(before, learner.model.actor.mu.weight)
