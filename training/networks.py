"""DeepRacer's networks as stable-baselines3 features extractors.

The camera (one channel, or two for stereo) goes through a CNN: DeepRacer's "3-layer" network
(conv 32@8x8/4, 64@4x4/2, 64@3x3/1, then dense 512) or its "5-layer" one (here: 32@5x5/2,
32@3x3/1, 64@3x3/2, 64@3x3/1, 128@3x3/2, then dense 512). A lidar's 64 distances or 8 sector bits
go through a dense layer of their own; the two are concatenated, and SB3's policy and value heads
follow.
"""

from __future__ import annotations

import gymnasium
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn

SHALLOW = "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"
DEEP = "DEEP_CONVOLUTIONAL_NETWORK"
CAMERAS = ("FRONT_FACING_CAMERA", "STEREO_CAMERAS")
LIDARS = ("LIDAR", "SECTOR_LIDAR")

LAYERS = {
    # (out channels, kernel, stride)
    SHALLOW: ((32, 8, 4), (64, 4, 2), (64, 3, 1)),
    DEEP: ((32, 5, 2), (32, 3, 1), (64, 3, 2), (64, 3, 1), (128, 3, 2)),
}
CAMERA_FEATURES = 512
LIDAR_FEATURES = {"LIDAR": 256, "SECTOR_LIDAR": 64}


class DeepRacerFeatures(BaseFeaturesExtractor):
    """The camera's CNN, plus the lidar's dense layer when the car has one."""

    def __init__(self, observation_space: gymnasium.spaces.Dict, network: str = SHALLOW) -> None:
        camera = next(key for key in observation_space.spaces if key in CAMERAS)
        lidar = next((key for key in observation_space.spaces if key in LIDARS), None)
        features = CAMERA_FEATURES + (LIDAR_FEATURES[lidar] if lidar else 0)
        super().__init__(observation_space, features_dim=features)
        self.camera, self.lidar = camera, lidar
        channels = observation_space[camera].shape[0]
        layers: list[nn.Module] = []
        for out_channels, kernel, stride in LAYERS[network]:
            layers += [nn.Conv2d(channels, out_channels, kernel, stride), nn.ReLU()]
            channels = out_channels
        layers.append(nn.Flatten())
        self.cnn = nn.Sequential(*layers)
        with torch.no_grad():
            sample = torch.as_tensor(observation_space[camera].sample()[None]).float()
            flat = self.cnn(sample).shape[1]
        self.camera_head = nn.Sequential(nn.Linear(flat, CAMERA_FEATURES), nn.ReLU())
        if lidar:
            size = gymnasium.spaces.flatdim(observation_space[lidar])
            self.lidar_head = nn.Sequential(nn.Linear(size, LIDAR_FEATURES[lidar]), nn.ReLU())

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        # SB3 has already scaled the camera's bytes to [0, 1].
        features = self.camera_head(self.cnn(observations[self.camera]))
        if self.lidar is None:
            return features
        lidar = observations[self.lidar].float().flatten(start_dim=1)
        return torch.cat([features, self.lidar_head(lidar)], dim=1)


def policy_kwargs(network: str) -> dict:
    """SB3 ``policy_kwargs`` for a DeepRacer network: our extractor, the heads straight on it."""
    return {
        "features_extractor_class": DeepRacerFeatures,
        "features_extractor_kwargs": {"network": network},
        "net_arch": {"pi": [64], "vf": [64]},
    }
