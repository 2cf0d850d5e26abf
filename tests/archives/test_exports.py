"""Downloads: the physical-car archive is what the car's model loader installs, and its graph
chooses the PyTorch policy's action; ONNX runs as PyTorch does; the virtual model holds everything
needed to go on training."""

import io
import json
import os
import tarfile
from pathlib import Path

import numpy as np
import onnxruntime
import openvino
import pytest
import torch
from django.core.management import CommandError, call_command
from django.urls import reverse

from archives import exports
from rl import cargraph, hyperparameters
from rl.policies import Policy
from tests.helpers.models import sensor_frames, trained_model
from training import artifacts
from training.models import RLModel

pytestmark = pytest.mark.django_db

CONTINUOUS = {"steering_angle": {"low": -30.0, "high": 30.0}, "speed": {"low": 0.5, "high": 2.0}}


def decisive(learner) -> None:
    """Policy heads that tell frames apart: the first weights' heads are near zero (SB3 starts
    them so), which would give every frame almost the same action."""
    policy = learner.model.policy
    head = policy.action_net if hasattr(policy, "action_net") else policy.actor.mu
    with torch.no_grad():
        head.weight.mul_(200.0)


def torch_policy(model: RLModel) -> Policy:
    policy = Policy.for_environment(
        model.algorithm, model.architecture, model.environment_settings()
    )
    policy.load_checkpoint(
        artifacts.read(artifacts.path(model, "checkpoints/iteration-1.safetensors"))
    )
    return policy


def archive_members(data: bytes) -> dict[str, bytes]:
    with tarfile.open(fileobj=io.BytesIO(data), mode="r:gz") as archive:
        return {m.name: archive.extractfile(m).read() for m in archive.getmembers() if m.isfile()}


def export(tmp_path, model: RLModel, *flags: str) -> dict[str, bytes]:
    output = tmp_path / "archive.tar.gz"
    call_command("exportmodel", model.name, *flags, "-o", str(output), stdout=io.StringIO())
    return archive_members(output.read_bytes())


def car_loader(archive: bytes, into: Path) -> tuple[bytes, dict]:
    """The car's model loader (aws-deepracer-systems-pkg model_loader_node.py:331-438 and
    model_install_state.py:99-123): extract the archive; every file whose extension is "in" the
    string ".pb" is a model (so a file without an extension is one too); exactly one may be there,
    installed as model.pb; model_metadata.json is read from the root."""
    with tarfile.open(fileobj=io.BytesIO(archive), mode="r:gz") as tar:
        tar.extractall(into, filter="data")
    found = [p for p in into.rglob("*") if p.is_file() and os.path.splitext(p.name)[1] in ".pb"]
    assert len(found) == 1, f"the car ignores the archive: {len(found)} models in it"
    return found[0].read_bytes(), json.loads((into / "model_metadata.json").read_text())


def test_the_car_installs_the_archive_and_its_graph_chooses_the_pytorch_policys_action(
    alice, tracks, tmp_path, tensorflow
):
    model = trained_model(alice, "discrete-camera", weights=decisive)
    output = tmp_path / "physicalmodel-discrete-camera.tar.gz"
    call_command("exportmodel", model.name, "--physical", "-o", str(output), stdout=io.StringIO())
    assert sorted(archive_members(output.read_bytes())) == ["agent/model.pb", "model_metadata.json"]
    graph, metadata = car_loader(output.read_bytes(), tmp_path / "car")
    assert metadata == model.metadata()
    assert metadata["sensor"] == ["FRONT_FACING_CAMERA"] and metadata["version"] == "5"

    graph_def = tensorflow.compat.v1.GraphDef.FromString(graph)
    with tensorflow.Graph().as_default() as loaded:
        tensorflow.compat.v1.import_graph_def(graph_def, name="")
    camera, output_node = (
        cargraph.input_name(True, "FRONT_FACING_CAMERA"),
        cargraph.output_name(True),
    )
    assert camera == (
        "main_level/agent/main/online/network_0/FRONT_FACING_CAMERA/FRONT_FACING_CAMERA"
    )
    policy, chosen = torch_policy(model), []
    with tensorflow.compat.v1.Session(graph=loaded) as session:
        for observation in sensor_frames(model.environment_settings()):
            action = policy.drive(observation)
            tensor, _ = policy.network.obs_to_tensor(observation)
            with torch.no_grad():
                expected = policy.network.get_distribution(tensor).distribution.probs.numpy()
            frame = observation["FRONT_FACING_CAMERA"][None].astype(np.float32)
            assert frame.shape == (1, 1, 120, 160)
            probabilities = session.run(
                f"{output_node}:0",
                {f"{camera}:0": frame.transpose(0, 2, 3, 1)},  # NHWC, 0-255
            )
            assert probabilities.shape == (1, len(model.action_space))
            np.testing.assert_allclose(probabilities, expected, atol=1e-4)
            assert int(probabilities.argmax()) == int(action)
            chosen.append(int(action))
    assert len(set(chosen)) > 1  # the frames are told apart: the comparison means something


@pytest.mark.slow
def test_a_continuous_stereo_lidar_policy_runs_as_onnx_on_onnx_runtime_and_openvino(
    alice, tracks, tmp_path
):
    model = trained_model(
        alice,
        "sac-stereo-lidar",
        weights=decisive,
        algorithm="sac",
        action_space=CONTINUOUS,
        sensors=["STEREO_CAMERAS", "LIDAR"],
    )
    members = export(tmp_path, model, "--onnx", "--checkpoint", "last")
    assert sorted(members) == ["model.onnx", "model_metadata.json"]
    onnx = onnxruntime.InferenceSession(members["model.onnx"])
    core = openvino.Core()
    (tmp_path / "model.onnx").write_bytes(members["model.onnx"])
    # fp32 throughout: the CPU plugin may otherwise compute in bf16 where the CPU has it.
    ir = core.compile_model(
        core.read_model(str(tmp_path / "model.onnx")), "CPU", {"INFERENCE_PRECISION_HINT": "f32"}
    )
    policy = torch_policy(model)
    for observation in sensor_frames(model.environment_settings(), count=6):
        expected = policy.drive(observation)
        inputs = {s: observation[s][None].astype(np.float32) for s in model.sensors}
        assert inputs["STEREO_CAMERAS"].shape == (1, 2, 120, 160)
        assert inputs["LIDAR"].shape == (1, 64)
        for action in (onnx.run(None, inputs)[0], ir(inputs)[0]):
            assert action.shape == (1, 2)
            np.testing.assert_allclose(action[0], expected, atol=1e-4)


@pytest.mark.slow
def test_a_model_with_pitlanes_first_networks_goes_to_onnx_but_not_to_the_car(
    alice, tracks, tmp_path
):
    new = RLModel._meta.get_field("network_layout").default
    assert new == hyperparameters.NETWORK_LAYOUT  # DeepRacer's
    model = trained_model(alice, "first-layout", network_layout=1)
    assert model.architecture == "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW:1"
    with pytest.raises(CommandError, match="trained before Pitlane's networks were DeepRacer's"):
        call_command("exportmodel", model.name, "--physical", "-o", str(tmp_path / "x.tar.gz"))
    members = export(tmp_path, model, "--onnx")
    policy = torch_policy(model)
    observation = sensor_frames(model.environment_settings(), count=1)[0]
    tensor, _ = policy.network.obs_to_tensor(observation)
    with torch.no_grad():
        expected = policy.network.get_distribution(tensor).distribution.probs.numpy()
    frame = {"FRONT_FACING_CAMERA": observation["FRONT_FACING_CAMERA"][None].astype(np.float32)}
    got = onnxruntime.InferenceSession(members["model.onnx"]).run(None, frame)[0]
    np.testing.assert_allclose(got, expected, atol=1e-4)
    # Its virtual archive keeps our checkpoints: DeepRacer's names do not fit its layers.
    virtual = export(tmp_path, model, "--virtual")
    assert not [name for name in virtual if name.startswith("model/")]
    policy.load_checkpoint(virtual["checkpoints/last.safetensors"])


@pytest.mark.slow
def test_the_virtual_model_holds_what_training_elsewhere_needs(alice, tracks, tmp_path):
    model = trained_model(alice, "to-move")
    members = export(tmp_path, model, "--virtual")
    assert {
        "model_metadata.json",
        "reward_function.py",
        "training_params.yaml",
        "hyperparameters.json",
        "pitlane.json",
        "model/deepracer_checkpoints.json",
        "model/1_Step-0.ckpt.index",
        "model/1_Step-0.ckpt.data-00000-of-00001",
    } <= set(members)
    assert members["reward_function.py"].decode() == model.reward_function
    assert json.loads(members["hyperparameters.json"]) == hyperparameters.defaults("clipped_ppo")
    assert members["ip/hyperparameters.json"] == members["hyperparameters.json"]  # DeepRacer's
    assert b"WORLD_NAME: pitlane-oval" in members["training_params.yaml"]
    settings = json.loads(members["pitlane.json"])
    assert settings["track"] == "pitlane-oval" and settings["name"] == "to-move"
    # The weights once, as simapp keeps them: their import back is test_imports' and
    # test_deepracer_on_aws's.
    assert not [name for name in members if name.endswith(".safetensors")]


def test_a_model_without_weights_has_nothing_to_download(alice, tracks, tmp_path, client):
    model = trained_model(alice, "untrained")
    model.jobs.update(last_checkpoint="", best_checkpoint="")
    with pytest.raises(CommandError, match="no trained weights yet"):
        call_command("exportmodel", model.name, "--physical", "-o", str(tmp_path / "x.tar.gz"))
    client.force_login(alice)
    response = client.get(reverse("archives:model-export-virtual", args=[model.pk]), follow=True)
    assert "no trained weights yet" in response.text
    # A READY model without a trained checkpoint says why there is nothing to download.
    assert '<p class="muted" data-untrained>No downloads: untrained is ' in response.text


@pytest.mark.slow
def test_the_model_page_offers_the_archives_to_its_owner_only(alice, bob, tracks, client):
    model = trained_model(alice, "downloadable")
    client.force_login(alice)
    page = client.get(reverse("training:model-detail", args=[model.pk])).text
    for kind in ("physicalmodel", "onnxmodel", "virtualmodel"):
        assert f"{kind}-downloadable.tar.gz" in page
    url = reverse("archives:model-export-physical", args=[model.pk])
    response = client.get(url, {"checkpoint": "last"})
    assert response.status_code == 200
    assert 'filename="physicalmodel-downloadable.tar.gz"' in response["Content-Disposition"]
    assert "agent/model.pb" in archive_members(b"".join(response.streaming_content))
    onnx = client.get(reverse("archives:model-export-onnx", args=[model.pk]))
    assert "model.onnx" in archive_members(b"".join(onnx.streaming_content))
    assert client.get(url, {"checkpoint": "worst"}).status_code == 302  # with a message

    client.force_login(bob)
    assert client.get(url).status_code == 404
    assert client.get(reverse("archives:model-export-virtual", args=[model.pk])).status_code == 404


@pytest.mark.slow
def test_a_download_holds_the_checkpoint_chosen_best_or_last(alice, tracks):
    model = trained_model(alice, "two-checkpoints")
    later = artifacts.read(
        trained_model(alice, "later", weights=decisive).jobs.get().last_checkpoint
    )
    name = artifacts.save(model, artifacts.checkpoint(2), later)
    model.jobs.update(last_checkpoint=name, iterations=2)
    best, last = exports.onnx(model, "best"), exports.onnx(model, "last")
    assert last.name.endswith(f"/exports/onnx-{exports._digest(later)}.tar.gz")
    assert best.name != last.name  # each archive is named by the weights it holds
