"""DeepRacer's networks, layer for layer, as stable-baselines3 features extractors.

Built as deepracer-simapp (01f5f01) builds them with rl_coach, so that a DeepRacer model's weights
load here and ours run on the car:

- Every sensor has an embedder of its own: convolutions for a camera, dense layers for a lidar
  (``EMBEDDERS``), each followed by a ReLU. simapp's sensor tables also list batch-norm, dropout
  and tanh, but its embedder factory reads only the layer sizes, and rl_coach's "scheme"
  embedders apply ReLU alone (markov/architecture/embedder_factory.py:25-48, agents/utils.py:63-73;
  rl_coach embedders/embedder.py:73-78). Convolutions are unpadded ('valid').
- A dense layer after a camera's convolutions acts on each pixel's channels (rl_coach flattens
  only at the end, embedder.py:115-121): here a 1x1 convolution.
- Each embedding is flattened as TensorFlow lays it out (height, width, channels; embedder.py:121)
  and the embeddings are concatenated in the sensors' alphabetical order
  (rl_coach general_network.py:253,277).
- The middleware, dense 512 with ReLU, follows (custom_architectures.py:34-38), and the heads sit
  directly on it: SB3's policy and value layers for PPO, each with its own copy of the embedders
  and middleware as DeepRacer's "separate networks per head" (rl_coach clipped_ppo_agent.py:43-49);
  for SAC, the actor's dense 256 then mean and log-std (heads/sac_head.py:37,57-60) and two Q heads
  of dense 256, 256 on the observation's embedding and the action (heads/sac_q_head.py;
  head_parameters.py:24).

Images arrive as bytes; SB3 scales them to [0, 1] first, as rl_coach divides by 255 inside its
graph (embedder.py:107, embedder_parameters.py:33-36).

Models trained before Pitlane's networks matched DeepRacer's (layout 1) keep theirs
(``PitlaneV1Features``): their weights are for it.
"""

from __future__ import annotations

import contextlib
import math
from collections.abc import Iterator

import gymnasium
import torch
from stable_baselines3.common.torch_layers import BaseFeaturesExtractor
from torch import nn
from torch.nn import functional

from rl import hyperparameters as hp
from simulator.config import CAMERAS, LIDARS

SHALLOW = "DEEP_CONVOLUTIONAL_NETWORK_SHALLOW"  # DeepRacer's "3-layer CNN"
DEEP = "DEEP_CONVOLUTIONAL_NETWORK"  # DeepRacer's "5-layer CNN"
MIDDLEWARE = 512

# ("conv", filters, kernel, stride) or ("dense", units), per network and sensor, from simapp's
# bundle/markov/sensors/utils.py:82-110 (camera), :174-194 (stereo), :199-212 (lidars).
_SHALLOW_CAMERA = (("conv", 32, 8, 4), ("conv", 64, 4, 2), ("conv", 64, 3, 1))
_LIDAR = (("dense", 256), ("dense", 256))
EMBEDDERS = {
    (SHALLOW, "FRONT_FACING_CAMERA"): _SHALLOW_CAMERA,
    (DEEP, "FRONT_FACING_CAMERA"): (
        ("conv", 32, 5, 2),
        ("conv", 32, 3, 1),
        ("conv", 64, 3, 2),
        ("conv", 64, 3, 1),
        ("dense", 64),
    ),
    (SHALLOW, "STEREO_CAMERAS"): _SHALLOW_CAMERA,
    (DEEP, "STEREO_CAMERAS"): (
        ("conv", 32, 3, 1),
        ("conv", 64, 3, 2),
        ("conv", 64, 3, 1),
        ("conv", 128, 3, 2),
        ("conv", 128, 3, 1),
    ),
    **{(network, lidar): _LIDAR for network in (SHALLOW, DEEP) for lidar in LIDARS},
}


def architecture(network: str, layout: int = hp.NETWORK_LAYOUT) -> str:
    """What builds a model's network: its DeepRacer name, and the layout when it is an old one."""
    return network if layout == hp.NETWORK_LAYOUT else f"{network}:{layout}"


def _parse(name: str) -> tuple[str, int]:
    network, _, layout = name.partition(":")
    return network, int(layout or hp.NETWORK_LAYOUT)


class CameraConv2d(nn.Conv2d):
    """A camera's first convolution (one or two channels, strided), with a backward that is fast
    on the CPU.

    oneDNN's weight gradient of DeepRacer's first layer (a grey image, 32@8x8 stride 4) took
    46 ms a minibatch of 64 on torch 2.13's CPU build, 16 times its forward, and most of a PPO
    update (bench/bench_training.py --update). While gradients are taken, the layer is computed
    as the same sums in another order: the image cut into stride x stride blocks stacked as
    channels (space to depth), convolved with the kernel cut the same way (zero-padded to whole
    blocks) at stride 1; 3.6 times faster for that layer, equal to float rounding. Acting, the
    exports and the weights (their shape and names) are nn.Conv2d's."""

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        stride = self.stride[0]
        if not torch.is_grad_enabled() or stride == 1 or self.stride[1] != stride:
            return super().forward(x)
        height, width = x.shape[2:]
        kernel_h, kernel_w = self.kernel_size
        blocks_h, blocks_w = math.ceil(kernel_h / stride), math.ceil(kernel_w / stride)
        rows = ((height - kernel_h) // stride + blocks_h) * stride
        columns = ((width - kernel_w) // stride + blocks_w) * stride
        x = x[:, :, :rows, :columns]  # what the convolution reads; zeros under padded kernels
        x = functional.pad(x, (0, columns - x.shape[3], 0, rows - x.shape[2]))
        kernel = functional.pad(
            self.weight, (0, blocks_w * stride - kernel_w, 0, blocks_h * stride - kernel_h)
        )
        return functional.conv2d(
            _space_to_depth(x, stride), _space_to_depth(kernel, stride), self.bias
        )


def _space_to_depth(x: torch.Tensor, stride: int) -> torch.Tensor:
    """(N, C, H, W) as (N, C * stride^2, H / stride, W / stride): each stride x stride block's
    pixels become channels, in the same order for an image and a kernel."""
    n, channels, height, width = x.shape
    blocks = x.reshape(n, channels, height // stride, stride, width // stride, stride)
    return blocks.permute(0, 1, 3, 5, 2, 4).reshape(
        n, channels * stride * stride, height // stride, width // stride
    )


class Embedder(nn.Module):
    """One sensor's embedder; ``size``: the length of its flattened embedding. ``tf_names`` are
    its layers' names in DeepRacer's graph: rl_coach
    numbers the layers together with the activation block after each (Conv2d_0, Conv2d_2, ...;
    embedder.py:115-119)."""

    def __init__(self, layers: tuple, space: gymnasium.Space) -> None:
        super().__init__()
        self.image = len(space.shape) == 3
        size = space.shape[0] if self.image else gymnasium.spaces.flatdim(space)
        modules, self.tf_names = [], []
        for index, (kind, units, *shape) in enumerate(layers):
            if kind == "conv":
                # Space to depth pays for a camera's few channels only (a 32-channel layer
                # learns slower that way): the first layer.
                conv = CameraConv2d if index == 0 else nn.Conv2d
                modules.append(conv(size, units, *shape))
                self.tf_names.append(f"Conv2d_{2 * index}")
            else:
                modules.append(nn.Conv2d(size, units, 1) if self.image else nn.Linear(size, units))
                self.tf_names.append(f"Dense_{2 * index}")
            size = units
        self.layers = nn.ModuleList(modules)
        with torch.no_grad():
            self.size = self(torch.zeros((1, *space.shape))).shape[1]

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        if not self.image:
            x = x.flatten(start_dim=1)
        for layer in self.layers:
            x = torch.relu(layer(x))
        if self.image:
            x = x.permute(0, 2, 3, 1)  # flattened as TensorFlow's NHWC
        return x.flatten(start_dim=1)


class LowerPrecision:
    """A features extractor whose convolutions and middleware may run in a lower precision, its
    ``precision`` (None: float32, unless ``lower_precision`` sets it for a while). The weights
    stay float32, as do the features it returns: autocast casts copies of the weights for the
    convolutions and matrix products, where the FLOPs are, and the heads, losses,
    log-probabilities and optimiser see float32 as ever."""

    precision: torch.dtype | None = None

    def _precision(self, like: torch.Tensor) -> contextlib.AbstractContextManager:
        if self.precision is None:
            return contextlib.nullcontext()
        # no cache of cast weights: each is cast once a pass anyway, and a CUDA graph's capture
        # (rl.graphed) must not keep casts made outside it
        return torch.autocast(like.device.type, dtype=self.precision, cache_enabled=False)


@contextlib.contextmanager
def lower_precision(module: nn.Module, precision: torch.dtype | None) -> Iterator[None]:
    """Within: every features extractor in ``module`` computes in ``precision`` (None: float32),
    as a policy update may; acting and the exports stay float32."""
    extractors = [m for m in module.modules() if isinstance(m, LowerPrecision)]
    for extractor in extractors:
        extractor.precision = precision
    try:
        yield
    finally:
        for extractor in extractors:
            extractor.precision = None


class DeepRacerFeatures(LowerPrecision, BaseFeaturesExtractor):
    """DeepRacer's embedders, one per sensor, and its middleware."""

    def __init__(self, observation_space: gymnasium.spaces.Dict, network: str = SHALLOW) -> None:
        sensors = sorted(observation_space.spaces)
        embedders = {s: Embedder(EMBEDDERS[network, s], observation_space[s]) for s in sensors}
        super().__init__(observation_space, features_dim=MIDDLEWARE)
        self.sensors = sensors
        self.embedders = nn.ModuleDict(embedders)
        self.middleware = nn.Linear(sum(e.size for e in embedders.values()), MIDDLEWARE)

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        with self._precision(observations[self.sensors[0]]):
            embedded = [self.embedders[s](observations[s].float()) for s in self.sensors]
            features = torch.relu(self.middleware(torch.cat(embedded, dim=1)))
        return features.float()


class PitlaneV1Features(LowerPrecision, BaseFeaturesExtractor):
    """Layout 1, before the networks were DeepRacer's: a camera CNN (3-layer as DeepRacer's; the
    "5-layer" 32@5x5/2, 32@3x3/1, 64@3x3/2, 64@3x3/1, 128@3x3/2) into dense 512, and the lidar
    through a dense layer of its own, concatenated; heads of 64 on a shared extractor."""

    V1_LAYERS = {
        SHALLOW: ((32, 8, 4), (64, 4, 2), (64, 3, 1)),
        DEEP: ((32, 5, 2), (32, 3, 1), (64, 3, 2), (64, 3, 1), (128, 3, 2)),
    }
    V1_LIDAR = {"LIDAR": 256, "SECTOR_LIDAR": 64}

    def __init__(self, observation_space: gymnasium.spaces.Dict, network: str = SHALLOW) -> None:
        camera = next(key for key in observation_space.spaces if key in CAMERAS)
        lidar = next((key for key in observation_space.spaces if key in LIDARS), None)
        features = MIDDLEWARE + (self.V1_LIDAR[lidar] if lidar else 0)
        super().__init__(observation_space, features_dim=features)
        self.camera, self.lidar = camera, lidar
        channels = observation_space[camera].shape[0]
        layers: list[nn.Module] = []
        for out_channels, kernel, stride in self.V1_LAYERS[network]:
            conv = nn.Conv2d if layers else CameraConv2d
            layers += [conv(channels, out_channels, kernel, stride), nn.ReLU()]
            channels = out_channels
        layers.append(nn.Flatten())
        self.cnn = nn.Sequential(*layers)
        with torch.no_grad():
            sample = torch.as_tensor(observation_space[camera].sample()[None]).float()
            flat = self.cnn(sample).shape[1]
        self.camera_head = nn.Sequential(nn.Linear(flat, MIDDLEWARE), nn.ReLU())
        if lidar:
            size = gymnasium.spaces.flatdim(observation_space[lidar])
            self.lidar_head = nn.Sequential(nn.Linear(size, self.V1_LIDAR[lidar]), nn.ReLU())

    def forward(self, observations: dict[str, torch.Tensor]) -> torch.Tensor:
        with self._precision(observations[self.camera]):
            features = self.camera_head(self.cnn(observations[self.camera]))
            if self.lidar is not None:
                lidar = observations[self.lidar].float().flatten(start_dim=1)
                features = torch.cat([features, self.lidar_head(lidar)], dim=1)
        return features.float()


def optimizer_kwargs(algorithm: str) -> dict:
    """Adam as SB3 sets it up (its epsilon of 1e-5 for PPO, stable_baselines3/common/policies.py
    ActorCriticPolicy), fused: one pass over each tensor rather than one per operation. Over the
    middleware's 11 million weights a step took 52 ms on two CPU threads, 7 ms fused (torch
    2.13), as long as the rest of a minibatch's update; the same arithmetic."""
    return {"eps": 1e-5, "fused": True} if algorithm == hp.PPO else {"fused": True}


def policy_kwargs(algorithm: str, architecture: str) -> dict:
    """SB3 ``policy_kwargs`` for ``algorithm`` with a network built as ``architecture`` says."""
    network, layout = _parse(architecture)
    if layout == 1:
        heads = {"pi": [64], "vf": [64]} if algorithm == hp.PPO else {"pi": [64], "qf": [64]}
        return {
            "features_extractor_class": PitlaneV1Features,
            "features_extractor_kwargs": {"network": network},
            "optimizer_kwargs": optimizer_kwargs(algorithm),
            "net_arch": heads,
        }
    kwargs = {
        "features_extractor_class": DeepRacerFeatures,
        "features_extractor_kwargs": {"network": network},
        "optimizer_kwargs": optimizer_kwargs(algorithm),
    }
    if algorithm == hp.PPO:
        return kwargs | {"net_arch": {"pi": [], "vf": []}, "share_features_extractor": False}
    return kwargs | {"net_arch": {"pi": [256], "qf": [256, 256]}}
