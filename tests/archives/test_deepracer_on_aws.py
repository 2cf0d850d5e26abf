"""The virtual archive, unpacked, is a folder DeepRacer on AWS imports (aws-solutions/
deepracer-on-aws 61af778): the files its browser asks for and its server reads, the track named
as it names tracks, the metrics where it looks; and simapp's model/ folder, which its import runs
simapp's validator on (validation_worker.py:60-105, 141-144, deepracer-simapp 01f5f01): pointers
naming checkpoints whose tensors TensorFlow restores, under rl_coach's names, into the networks
simapp builds, where they give our policy's outputs."""

import io
import json
import tarfile

import gymnasium
import pytest
import torch
import yaml
from django.core.files.storage import default_storage

import simulator
from archives import exports, history, imports
from rl import tfcheckpoint
from rl.networks import SHALLOW
from rl.policies import Policy
from tests.archives.deepracer_tf import build
from tests.archives.test_deepracer_weights import CONTINUOUS, DISCRETE, assert_same
from tests.archives.test_exports import decisive, torch_policy
from tests.helpers.models import sensor_frames, trained_model
from training import artifacts, selectors
from training.models import Iteration, RLModel

pytestmark = pytest.mark.django_db


def on_a_two_way_track(owner, algorithm: str, space) -> RLModel:
    """A model trained an iteration on a track DeepRacer drives both ways, with its metrics."""
    settings = {"algorithm": algorithm, "action_space": space, "weights": decisive}
    where = {"track": "2022_april_open", "direction": "clockwise"}
    model = trained_model(owner, "to-aws", **settings, **where)
    artifacts.save(model, artifacts.TRAINING_METRICS, b'{"metrics": [], "version": "2"}')
    return model


def two_checkpoints(owner, algorithm: str, space) -> RLModel:
    """``on_a_two_way_track``'s model trained two iterations: its best checkpoint the first, its
    last the second (other weights), with their steps and evaluations."""
    model = on_a_two_way_track(owner, algorithm, space)
    policy = torch_policy(model)
    with torch.no_grad():  # other weights: the last checkpoint is not the best
        for parameter in policy.network.parameters():
            parameter.mul_(1.02)
    last = artifacts.save(model, artifacts.checkpoint(2), policy.checkpoint())
    job = model.jobs.get()
    job.last_checkpoint, job.iterations = last, 2
    job.save()
    for number, steps, completion in ((1, 500, 61.5), (2, 700, 40.0)):
        Iteration.objects.create(
            job=job, number=number, reward=1.0, completion=completion, episodes=20,
            steps=steps, wall_seconds=60.0, evaluation_completion=completion,
        )  # fmt: skip
    return model


def unpacked(model: RLModel) -> dict[str, bytes]:
    """The virtual archive's files, as DeepRacer on AWS's folder upload sends them."""
    with default_storage.open(exports.virtual(model).name) as stored:
        data = stored.read()
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as archive:
        return {m.name: archive.extractfile(m).read() for m in archive if m.isfile()}


def restored(tensorflow, deepracer, prefix: str) -> None:
    """The checkpoint at ``prefix`` restored into ``deepracer``'s graph as rl_coach's saver
    restores one: each trainable variable but the target network's, by its name
    (tensorflow_components/savers.py:34-41, 104-121); here every one must be there."""
    tf1 = tensorflow.compat.v1
    reader = tf1.train.load_checkpoint(prefix)  # TensorFlow's reader: it checks every checksum
    with deepracer.graph.as_default():
        variables = [v for v in tf1.trainable_variables() if "/target" not in v.name]
        for variable in variables:
            name = variable.name.split(":")[0]
            assert reader.has_tensor(name), name
            deepracer.session.run(variable.assign(reader.get_tensor(name)))


def test_the_virtual_archive_unpacked_is_what_deepracer_on_aws_imports(
    alice, tracks, tensorflow, tmp_path
):
    """SAC's networks, whose layers rl_coach partly leaves unnamed (a PPO model's names are read
    back below by the importer, which test_deepracer_weights holds to TensorFlow's); one
    checkpoint, both best and last."""
    model = on_a_two_way_track(alice, "sac", CONTINUOUS)
    files = unpacked(model)
    # The browser's check, by name in any folder (ImportModel/constants.ts:6-11), and the server's
    # reads (ImportHelper.ts:38, 54, 69, 139).
    for name in ("model_metadata.json", "reward_function.py", "training_params.yaml"):
        assert name in files
    assert json.loads(files["ip/hyperparameters.json"])["batch_size"] > 0
    params = yaml.safe_load(files["training_params.yaml"])
    assert (params["WORLD_NAME"], params["TRACK_DIRECTION_CLOCKWISE"]) == ("2022_april_open", True)
    assert params["REVERSE_DIR"] is False
    metrics = [k for k in files if k.startswith("metrics/training/") and "training-" in k]
    assert [files[k] for k in metrics] == [files[artifacts.TRAINING_METRICS]]  # ts:84-91

    # simapp's validator: model/model_metadata.json, then the last and the best checkpoints by
    # deepracer_checkpoints.json (here the same), rl_coach's pointer to the last.
    assert files["model/model_metadata.json"] == files["model_metadata.json"]
    pointers = json.loads(files["model/deepracer_checkpoints.json"])
    names = {pointers[f"{which}_checkpoint"]["name"] for which in ("best", "last")}
    assert names == {"1_Step-0.ckpt"} == {files["model/.coach_checkpoint"].decode()}
    for suffix in (tfcheckpoint.SUFFIX_INDEX, tfcheckpoint.SUFFIX_DATA):
        (tmp_path / f"1_Step-0.ckpt{suffix}").write_bytes(files[f"model/1_Step-0.ckpt{suffix}"])
    deepracer = build(tensorflow, "sac", SHALLOW, observation_space(model), 2, False)
    restored(tensorflow, deepracer, str(tmp_path / "1_Step-0.ckpt"))
    frames = sensor_frames(model.environment_settings(), count=4)
    policy = policy_of(model, stored_weights(model, "last"))
    assert_same(deepracer, policy, frames, ["policy", "log_std", "q1", "q2"])
    # The checkpoint, its pointers and metadata: nothing else of simapp's (its frozen graphs are
    # the car's, the physical download), and the weights once (no safetensors).
    assert len([name for name in files if name.startswith("model/")]) == 5
    assert not [name for name in files if name.endswith(".safetensors")]


def policy_of(model: RLModel, weights: bytes) -> Policy:
    policy = Policy.for_environment(
        model.algorithm, model.architecture, model.environment_settings()
    )
    policy.load_checkpoint(weights)
    return policy


def observation_space(model: RLModel):
    env = gymnasium.make(simulator.ENV_ID, **model.environment_settings())
    try:
        return env.observation_space
    finally:
        env.close()


@pytest.mark.slow
def test_deepracers_files_alone_import_back_with_the_same_weights(alice, bob, tracks):
    """What DeepRacer's tools keep of the archive (simapp's files, not Pitlane's own records:
    no pitlane.json, no pitlane-history.json) imports here as the same model: the pointers name
    the best and the last checkpoints by iteration and steps, whose TensorFlow checkpoints hold
    every weight of the policy and its value network, and training_params.yaml the track and its
    direction."""
    model = two_checkpoints(alice, "clipped_ppo", DISCRETE)
    files = unpacked(model)
    pointers = json.loads(files["model/deepracer_checkpoints.json"])
    best, last = (pointers[f"{which}_checkpoint"] for which in ("best", "last"))
    assert (best["name"], last["name"]) == ("1_Step-500.ckpt", "2_Step-1200.ckpt")
    assert best["avg_eval_metric"] == 61.5  # progress, the model's best-checkpoint measure
    assert files["model/.coach_checkpoint"].decode() == last["name"]
    ours = (exports.PITLANE_SETTINGS, history.EXACT)
    archive = io.BytesIO()
    with tarfile.open(fileobj=archive, mode="w") as tar:  # as unpacked: no need to pack it
        for name, data in files.items():
            if name not in ours:
                info = tarfile.TarInfo(name)
                info.size = len(data)
                tar.addfile(info, io.BytesIO(data))
    imported = imports.import_model(owner=bob, archive=io.BytesIO(archive.getvalue()))
    assert (imported.model.track.name, imported.model.direction) == ("2022_april_open", "clockwise")
    assert "The weights are DeepRacer's, from model/1_Step-500.ckpt, model/2_Step-1200.ckpt." in (
        imported.notes
    )
    job = imported.model.jobs.get()
    for which, stored in (("best", job.best_checkpoint), ("last", job.last_checkpoint)):
        expected = policy_of(model, stored_weights(model, which)).network.state_dict()
        got = policy_of(imported.model, artifacts.read(stored)).network.state_dict()
        assert expected.keys() == got.keys()
        for key in expected:
            torch.testing.assert_close(got[key], expected[key], rtol=0, atol=0, msg=key)


def stored_weights(model: RLModel, which: str) -> bytes:
    return artifacts.read(selectors.model_checkpoint(model=model, which=which))
