"""A policy as an ONNX graph: what ``onnxmodel-<name>.tar.gz`` carries for custom cars and other
runtimes (``archives.exports``). Inputs are named after the sensors (camera bytes 0-255 as float32,
NCHW; the lidar in metres or sector bits); the output is ``probabilities`` over the discrete
actions, or ``action``: steering and speed each in [-1, 1] of its range."""

from __future__ import annotations

import tempfile
from pathlib import Path

import torch
from stable_baselines3.common.preprocessing import preprocess_obs
from torch import nn

from rl.policies import Policy
from simulator.config import CAMERAS, LIDARS

OPSET = 17


class CarNetwork(nn.Module):
    """The policy as the car runs it: sensor inputs in, the action's distribution out."""

    def __init__(self, policy: Policy, discrete: bool) -> None:
        super().__init__()
        self.network = policy.network  # a submodule: its weights go into the graph
        self.ppo, self.discrete = policy.ppo, discrete
        space = policy.network.observation_space
        self.camera = next(key for key in space.spaces if key in CAMERAS)
        self.lidar = next((key for key in space.spaces if key in LIDARS), None)

    def forward(self, camera: torch.Tensor, lidar: torch.Tensor | None = None) -> torch.Tensor:
        observation = {self.camera: camera}
        if self.lidar is not None:
            observation[self.lidar] = lidar
        network = self.network
        if self.ppo:
            # SB3 scales image inputs to [0, 1] in its preprocessing, inside the graph.
            features = network.pi_features_extractor(
                preprocess_obs(observation, network.observation_space)
            )
            latent = network.mlp_extractor.forward_actor(features)
            out = network.action_net(latent)
            return torch.softmax(out, dim=1) if self.discrete else out.clamp(-1.0, 1.0)
        mean, _, _ = network.actor.get_action_dist_params(observation)
        return torch.tanh(mean)

    def sample_inputs(self) -> tuple[torch.Tensor, ...]:
        space = self.network.observation_space
        inputs = [torch.zeros((1, *space[self.camera].shape), dtype=torch.float32)]
        if self.lidar is not None:
            inputs.append(torch.zeros((1, *space[self.lidar].shape), dtype=torch.float32))
        return tuple(inputs)

    @property
    def input_names(self) -> list[str]:
        return [self.camera] + ([self.lidar] if self.lidar else [])

    @property
    def output_name(self) -> str:
        return "probabilities" if self.discrete else "action"


def onnx_graph(policy: Policy, discrete: bool) -> bytes:
    """``policy`` as the car runs it, in ONNX (opset ``OPSET``)."""
    network = CarNetwork(policy, discrete)
    network.eval()
    with tempfile.TemporaryDirectory(prefix="pitlane-export-") as directory:
        path = Path(directory) / "model.onnx"
        with torch.no_grad():
            torch.onnx.export(
                network,
                network.sample_inputs(),
                str(path),
                dynamo=False,
                opset_version=OPSET,
                input_names=network.input_names,
                output_names=[network.output_name],
            )
        return path.read_bytes()
