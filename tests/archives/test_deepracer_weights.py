"""DeepRacer models come in with their weights: checkpoints and frozen graphs built with TensorFlow
under DeepRacer's names import as READY models whose networks give TensorFlow's outputs on
rendered sensor frames, the policy's for every algorithm and action space type, the value's and
Q's too when the model trains on; a car archive imports as a model to evaluate and race only."""

import io
import json

import boto3
import gymnasium
import numpy as np
import pytest
import torch
from django.core.management import CommandError, call_command
from django.urls import reverse

import simulator
from archives import exports, imports
from rl import tfcheckpoint, tfweights
from rl.networks import SHALLOW
from rl.policies import Policy
from tests.archives.deepracer_tf import build, checkpoints_json
from tests.helpers.archives import DEEPRACER_METADATA, deepracer_export, drfc_layout, tar_gz
from tests.helpers.models import ready_model, sensor_frames
from training import artifacts, services
from training.models import EvaluationJob, RLModel

pytestmark = pytest.mark.django_db

DISCRETE = DEEPRACER_METADATA["action_space"]
CONTINUOUS = {"steering_angle": {"low": -30.0, "high": 30.0}, "speed": {"low": 0.5, "high": 2.0}}


def metadata(algorithm: str, space, sensors: list[str], **more) -> dict:
    kind = "discrete" if isinstance(space, list) else "continuous"
    return {
        "action_space": space,
        "sensor": sensors,
        "neural_network": SHALLOW,
        "version": "5",
        "training_algorithm": algorithm,
        "action_space_type": kind,
        **more,
    }


def environment(space, sensors) -> dict:
    return {"track": "rookie-loop", "sensors": sensors, "action_space": space}


def deepracer_model(tensorflow, algorithm, space, sensors, **options):
    env = gymnasium.make(simulator.ENV_ID, **environment(space, sensors))
    discrete = isinstance(space, list)
    count = len(space) if discrete else 2
    model = build(tensorflow, algorithm, SHALLOW, env.observation_space, count, discrete, **options)
    env.close()
    return model


def imported_policy(model: RLModel, which: str = "best_checkpoint") -> Policy:
    policy = Policy.for_environment(
        model.algorithm, model.architecture, model.environment_settings()
    )
    policy.load_checkpoint(artifacts.read(getattr(model.jobs.get(), which)))
    return policy


def ours(policy: Policy, what: str, observation: dict, action=None) -> np.ndarray:
    """Our network's counterpart of ``DeepRacerModel.run(what, ...)``."""
    tensor, _ = policy.network.obs_to_tensor(observation)
    network = policy.network
    with torch.no_grad():
        if what == "value":
            return network.predict_values(tensor).numpy()
        if what in ("q1", "q2"):
            taken = torch.as_tensor(np.asarray(action, np.float32)[None])
            return network.critic(tensor, taken)[int(what[1]) - 1].numpy()
        if policy.ppo:
            distribution = network.get_distribution(tensor).distribution
            if what == "log_std":
                return network.log_std.numpy()[None]
            return (
                distribution.probs.numpy()
                if hasattr(distribution, "probs")
                else (distribution.mean.numpy())
            )
        mean, log_std, _ = network.actor.get_action_dist_params(tensor)
        return (mean if what == "policy" else log_std).numpy()


def assert_same(deepracer, policy: Policy, frames: list[dict], parts: list[str]) -> None:
    told_apart = set()
    for observation in frames:
        action = np.random.default_rng(len(told_apart)).uniform(-1, 1, 2)
        for part in parts:
            expected = deepracer.run(part, observation, action if part[0] == "q" else None)
            got = ours(policy, part, observation, action)
            assert got.shape == np.shape(expected), part
            np.testing.assert_allclose(got, expected, atol=1e-4, err_msg=part)
        told_apart.add(tuple(np.round(deepracer.run("policy", observation)[0], 3)))
    assert len(told_apart) > 1  # frames told apart: the comparison means something


def drfc_archive(files: dict[str, bytes], meta: dict, **more) -> bytes:
    members = deepracer_export(**{"model_metadata.json": json.dumps(meta).encode()}, **more)
    return tar_gz(drfc_layout({**members, **files}))


def checkpoint_files(deepracer, tmp_path, name: str) -> dict[str, bytes]:
    deepracer.checkpoint(str(tmp_path / name))
    return {
        f"model/{name}{suffix}": (tmp_path / f"{name}{suffix}").read_bytes()
        for suffix in (tfcheckpoint.SUFFIX_INDEX, tfcheckpoint.SUFFIX_DATA)
    }


@pytest.fixture
def drfc_bucket(s3_server, settings, monkeypatch):
    """DeepRacer for Cloud's bucket (its MinIO, here moto's S3 API), with the console's keys for
    it; a boto3 client to fill it as DeepRacer's training does."""
    keys = {"aws_access_key_id": "minio", "aws_secret_access_key": "miniostorage"}
    settings.PITLANE_DRFC_S3 = {"endpoint_url": s3_server, "region_name": "us-east-1", **keys}
    s3 = boto3.client("s3", **settings.PITLANE_DRFC_S3)
    s3.create_bucket(Bucket="bucket")
    return s3


def test_a_ppo_model_comes_in_from_deepracer_for_clouds_bucket_with_its_best_and_last_checkpoints(
    alice, tracks, tensorflow, tmp_path, drfc_bucket, capsys
):
    """`manage.py importmodel s3://bucket/prefix` reads a model's prefix as DeepRacer for Cloud
    and its training leave it (pitlane_client.drfc cites where each file comes from): the best
    and the last checkpoint by deepracer_checkpoints.json's names, not the others kept; the
    first worker's training_params; nothing of the bucket's other models. The model evaluates."""
    sensors = ["FRONT_FACING_CAMERA"]
    deepracer = deepracer_model(tensorflow, "clipped_ppo", DISCRETE, sensors, seed=1)
    frames = sensor_frames(environment(DISCRETE, sensors), count=4)
    files = checkpoint_files(deepracer, tmp_path, "3_Step-2200.ckpt")
    best = {part: [deepracer.run(part, f) for f in frames] for part in ("policy", "value")}
    with deepracer.graph.as_default():  # training went on: the last checkpoint differs
        for variable in deepracer.tf.compat.v1.trainable_variables():
            deepracer.session.run(variable.assign(variable * 0.8))
    files |= checkpoint_files(deepracer, tmp_path, "5_Step-3900.ckpt")
    files |= {  # a checkpoint neither best nor last, which is not read
        "model/4_Step-3100.ckpt.index": b"not read",
        "model/4_Step-3100.ckpt.data-00000-of-00001": b"not read",
        "model/5_Step-3900.ckpt.meta": b"not read: TensorFlow's graph, not its weights",
        "model/deepracer_checkpoints.json": checkpoints_json(
            best="3_Step-2200.ckpt", last="5_Step-3900.ckpt"
        ),
        "model/.coach_checkpoint": b"5_Step-3900.ckpt",
        "model/model_5.pb": deepracer.frozen_graph(),
        "training-simtrace/0-iteration.csv": b"episode,steps\n",
        "metrics/TrainingMetrics_1.json": b"{}",
    }
    members = drfc_layout(
        deepracer_export(
            **{
                "model_metadata.json": json.dumps(
                    metadata("clipped_ppo", DISCRETE, sensors)
                ).encode()
            }
        )
    )
    params = members.pop("training_params.yaml")
    members |= {
        "training_params_1.yaml": params,
        "training_params_2.yaml": b"WORLD_NAME: Oval_track",
    }
    for path, data in {**members, **files}.items():
        drfc_bucket.put_object(Bucket="bucket", Key=f"rl-deepracer-sagemaker/{path}", Body=data)
    drfc_bucket.put_object(
        Bucket="bucket", Key="rl-deepracer-sagemaker-2/reward_function.py", Body=b"x"
    )

    call_command("importmodel", "s3://bucket/rl-deepracer-sagemaker", "--owner", "alice")
    said = capsys.readouterr().out
    assert "ready" in said and "model/3_Step-2200.ckpt, model/5_Step-3900.ckpt" in said
    assert "training_params_1.yaml gave the track and race" in said

    model = RLModel.objects.get(owner=alice)
    assert model.status == RLModel.Status.READY and model.trainable
    policy = imported_policy(model, "best_checkpoint")
    for index, observation in enumerate(frames):
        for part in ("policy", "value"):
            np.testing.assert_allclose(
                ours(policy, part, observation), best[part][index], atol=1e-4
            )
    assert_same(deepracer, imported_policy(model, "last_checkpoint"), frames, ["policy", "value"])

    call_command("evaluate", model.name, "--track", "pitlane-oval", "--max-resets", "0")
    evaluated = EvaluationJob.objects.get(model=model)
    assert evaluated.status == EvaluationJob.Status.COMPLETED and evaluated.trial_rows.count() == 3
    with pytest.raises(CommandError, match="Nothing is stored under s3://bucket/nope"):
        call_command("importmodel", "s3://bucket/nope", "--owner", "alice")
    with pytest.raises(CommandError, match="NoSuchBucket"):
        call_command("importmodel", "s3://elsewhere/rl-deepracer-sagemaker", "--owner", "alice")


CASES = {
    "PPO continuous, stereo cameras and lidar": (
        "clipped_ppo",
        CONTINUOUS,
        ["STEREO_CAMERAS", "LIDAR"],
        ["policy", "log_std", "value"],
        {},
    ),
    "SAC, camera and sector lidar, Keras's layer names": (
        "sac",
        CONTINUOUS,
        ["FRONT_FACING_CAMERA", "SECTOR_LIDAR"],
        ["policy", "log_std", "q1", "q2"],
        {"keras_names": True},
    ),
    "SAC, camera, TensorFlow 1's layer names": (
        "sac",
        CONTINUOUS,
        ["FRONT_FACING_CAMERA"],
        ["policy", "log_std", "q1", "q2"],
        {},
    ),
}


@pytest.mark.parametrize("case", CASES)
def test_every_kind_of_model_comes_in_with_the_weights_of_its_checkpoint(
    case, alice, tracks, tensorflow, tmp_path
):
    algorithm, space, sensors, parts, options = CASES[case]
    deepracer = deepracer_model(tensorflow, algorithm, space, sensors, **options)
    files = checkpoint_files(deepracer, tmp_path, "12_Step-9000.ckpt")
    files["model/checkpoint"] = b'model_checkpoint_path: "12_Step-9000.ckpt"\n'
    archive = drfc_archive(files, metadata(algorithm, space, sensors))
    imported = imports.import_model(owner=alice, archive=io.BytesIO(archive))
    policy = imported_policy(imported.model)
    assert_same(deepracer, policy, sensor_frames(environment(space, sensors), count=4), parts)
    if algorithm == "sac":  # the target Q networks start as the Q networks
        critic = policy.network.critic.state_dict()
        target = policy.network.critic_target.state_dict()
        assert all(torch.equal(critic[key], target[key]) for key in critic)


def test_a_frozen_graph_without_checkpoints_brings_the_policy(alice, tracks, tensorflow):
    sensors = ["FRONT_FACING_CAMERA"]
    deepracer = deepracer_model(tensorflow, "sac", CONTINUOUS, sensors, keras_names=True)
    archive = drfc_archive(
        {"model/model_4.pb": deepracer.frozen_graph()}, metadata("sac", CONTINUOUS, sensors)
    )
    imported = imports.import_model(owner=alice, archive=io.BytesIO(archive))
    assert imported.model.trainable
    assert any("spread and the Q networks start from new weights" in n for n in imported.notes)
    frames = sensor_frames(environment(CONTINUOUS, sensors), count=4)
    assert_same(deepracer, imported_policy(imported.model), frames, ["policy"])


def test_a_car_archive_comes_in_to_evaluate_and_race_but_not_to_train(
    alice, tracks, tensorflow, client
):
    # simapp before 2.0: no sensor in the metadata, the camera called "observation".
    legacy = {key: value for key, value in DEEPRACER_METADATA.items() if key != "sensor"}
    legacy["version"] = "1"
    deepracer = deepracer_model(
        tensorflow, "clipped_ppo", DISCRETE, ["FRONT_FACING_CAMERA"], camera="observation"
    )
    archive = tar_gz(
        {
            "model_metadata.json": json.dumps(legacy).encode(),
            "agent/model.pb": deepracer.frozen_graph(),
        }
    )
    imported = imports.import_model(owner=alice, archive=io.BytesIO(archive), name="from-the-car")
    model = imported.model
    assert model.status == RLModel.Status.READY and not model.trainable
    assert model.sensors == ["FRONT_FACING_CAMERA"] and model.reward_function == ""
    assert any("not trained on or cloned" in note for note in imported.notes)
    assert not any("sensor" in note for note in imported.notes)  # observation is the camera
    frames = sensor_frames(environment(DISCRETE, ["FRONT_FACING_CAMERA"]), count=4)
    assert_same(deepracer, imported_policy(model), frames, ["policy"])

    # The model page offers evaluating and downloading, not cloning, and says why.
    client.force_login(alice)
    page = client.get(reverse("training:model-detail", args=[model.pk])).text
    assert reverse("training:evaluation-create", args=[model.pk]) in page
    assert f"?clone={model.pk}" not in page
    assert "brought no reward function and no critics" in page
    response = client.get(reverse("training:model-create") + f"?clone={model.pk}", follow=True)
    assert "cannot be cloned" in response.text
    evaluation = services.evaluation_start(model=model, settings={}, enqueue=False)
    assert evaluation.model == model  # (evaluations need no reward function: test_evaluation)


@pytest.mark.slow
def test_our_car_download_comes_back_as_the_same_policy(alice, bob, tracks):
    original = ready_model(alice)
    with artifacts.default_storage.open(exports.physical(original).name, "rb") as file:
        archive = file.read()
    imported = imports.import_model(owner=bob, archive=io.BytesIO(archive))
    assert not imported.model.trainable
    theirs, mine = imported_policy(original), imported_policy(imported.model)
    for observation in sensor_frames(original.environment_settings(), count=3):
        np.testing.assert_allclose(
            ours(mine, "policy", observation), ours(theirs, "policy", observation), atol=1e-5
        )


def test_weights_that_do_not_fit_the_metadata_are_refused_by_name(
    alice, tracks, tensorflow, tmp_path
):
    deepracer = deepracer_model(tensorflow, "clipped_ppo", DISCRETE, ["FRONT_FACING_CAMERA"])
    files = checkpoint_files(deepracer, tmp_path, "2_Step-100.ckpt")
    two_actions = metadata("clipped_ppo", DISCRETE[:2], ["FRONT_FACING_CAMERA"])
    with pytest.raises(
        imports.ImportRefused,
        match=r"ppo_head_0/policy_fc/kernel has the shape "
        r"\[512, 3\], where the network of model_metadata.json has \[512, 2\]",
    ):
        imports.import_model(owner=alice, archive=io.BytesIO(drfc_archive(files, two_actions)))
    damaged = {**files, "model/2_Step-100.ckpt.index": files["model/2_Step-100.ckpt.index"][:-60]}
    with pytest.raises(imports.ImportRefused, match="not a TensorFlow checkpoint index"):
        imports.import_model(
            owner=alice,
            archive=io.BytesIO(
                drfc_archive(damaged, metadata("clipped_ppo", DISCRETE, ["FRONT_FACING_CAMERA"]))
            ),
        )
    assert not RLModel.objects.filter(owner=alice).exists()


def test_only_the_online_networks_weights_are_read_from_a_checkpoint():
    names = [
        "main_level/agent/main/online/network_1/ppo_head_0/policy_fc/kernel",
        "main_level/agent/main/online/network_1/ppo_head_0/policy_fc/kernel/Adam",
        "main_level/agent/main/target/network_1/ppo_head_0/policy_fc/kernel",
        "main_level/agent/main/online/network_0/v_values_head_0/output/bias",
        "main_level/agent/main/online/global_step",
    ]
    assert tfweights.wanted(names, ppo=True) == [names[0], names[3]]
