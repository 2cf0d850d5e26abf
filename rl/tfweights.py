"""A DeepRacer model's weights, by their TensorFlow names, into our networks (layout 2).

Our networks are DeepRacer's layer for layer (``rl.networks``), so a DeepRacer model's
weights load into them once each tensor is found under its name and laid out as PyTorch lays it:

- names: the policy network and, for training on, PPO's value network and SAC's Q network; each
  the ``online`` copy, which is all rl_coach's saver keeps in the checkpoints racers published
  (anything else a checkpoint holds, such as ``gradients_from_head_*-rescalers``, target copies or
  an optimizer's slots, is not read). Under a network's scope: ``<SENSOR>/<layer>`` for the
  embedders, ``middleware_fc_embedder/Dense_0``, then the heads (``cargraph`` names the scopes):

  ==========  ===========================================================================
  PPO         ``network_1/ppo_head_0/policy_fc`` (discrete) or ``policy_mean`` and the variable
              ``policy_log_std`` [1, n] (continuous; rl_coach heads/ppo_head.py:112-140);
              ``network_0/v_values_head_0/output`` (value; heads/v_head.py:34-52)
  SAC         ``policy/online/network_0/sac_policy_head_0``: an unnamed dense 256, ``policy_mean``
              and an unnamed dense for the log-std (simapp multi_agent_coach/.../sac_head.py:
              55-59); ``q/online/network_0/q_values_head_0/q1_head`` and ``q2_head``, each two
              unnamed dense 256 on [embedding, action] and ``q1_output``/``q2_output``
              (sac_q_head.py:32-97)
  ==========  ===========================================================================

  A layer rl_coach leaves unnamed is named by the layer library that built it (``dense``,
  ``dense_1`` by TensorFlow 1's layers, numbered across the whole graph by Keras's), so it is found
  by its shape among the unnamed kernels of its head; within one head no two share a shape.
  Models of simapp before 2.0 call the camera ``observation`` (model_metadata.py:229-241).
- layout: a kernel is [in, out] (dense) or [height, width, in, out] (convolution); PyTorch's are
  [out, in] and [out, in, height, width]. A dense layer after a camera's convolutions is our
  1x1 convolution.

SAC's actions reach its Q network in [-1, 1] as ours do (simapp action_space_configs.py:74-76);
rl_coach's SAC also trains a state-value network, which SB3's SAC does without (its target Q
networks start as copies of the Q networks).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from dataclasses import dataclass

import numpy as np
import torch
from torch import nn

from rl import cargraph
from rl.networks import DeepRacerFeatures
from rl.policies import Policy
from simulator.config import LEGACY_CAMERA

SENSOR_NAMES = {"FRONT_FACING_CAMERA": ("FRONT_FACING_CAMERA", LEGACY_CAMERA)}
MIDDLEWARE = "middleware_fc_embedder/Dense_0"
PPO_VALUE_SCOPE = f"{cargraph.ROOT}/main/online/network_0"
SAC_Q_SCOPE = f"{cargraph.ROOT}/q/online/network_0"


class Unfit(ValueError):
    """The weights are not those of the model's network; the message names what is wrong."""


def wanted(names: Iterable[str], ppo: bool) -> list[str]:
    """Of a checkpoint's tensor names, those ``load`` may read: the weights of the online policy
    and value (PPO) or Q (SAC) networks, not an optimizer's slots."""
    value = PPO_VALUE_SCOPE if ppo else SAC_Q_SCOPE
    prefixes = (f"{cargraph.policy_scope(ppo)}/", f"{value}/")
    return [
        name
        for name in names
        if name.startswith(prefixes)
        and "Adam" not in name
        and name.endswith(("/kernel", "/bias", "/policy_log_std"))
    ]


def load(policy: Policy, tensors: Mapping[str, np.ndarray], *, complete: bool) -> None:
    """Set ``policy``'s weights from DeepRacer's ``tensors``: a checkpoint's when ``complete``
    (the policy with its spread, and the value (PPO) or Q (SAC) networks), else a frozen graph's,
    which keeps only what the policy's output needs: its mean. ``Unfit`` when one is missing or
    misshapen; nothing is changed unless everything fits."""
    found = [(slot, slot.value(tensors)) for slot in _slots(policy, complete, _Found(tensors))]
    network = policy.network
    with torch.no_grad():
        for slot, value in found:
            slot.parameter.copy_(torch.from_numpy(value))
        if not policy.ppo and complete:
            network.critic_target.load_state_dict(network.critic.state_dict())


def tensors(policy: Policy) -> dict[str, np.ndarray]:
    """``policy``'s weights by DeepRacer's names, laid out as TensorFlow lays them: what
    ``load`` reads from a checkpoint, and all rl_coach's saver restores (its trainable variables;
    simapp's rl_coach tensorflow_components/savers.py:34-41, 01f5f01). The layers rl_coach leaves
    unnamed are named as TensorFlow 1's layers name them in their head: ``dense``, ``dense_1``."""
    return {slot.name: slot.deepracer() for slot in _slots(policy, True, _Named())}


@dataclass(frozen=True)
class _Slot:
    """One tensor of DeepRacer's network: its ``name``, the ``parameter`` it is, TensorFlow's
    ``shape`` of it and its ``layout``: ``dense`` ([in, out]), ``pixel`` (a camera's per-pixel
    dense layer, our 1x1 convolution), ``conv`` ([height, width, in, out]) or ``plain``."""

    name: str
    parameter: torch.Tensor
    shape: tuple[int, ...]
    layout: str = "plain"

    def value(self, tensors: Mapping[str, np.ndarray]) -> np.ndarray:
        """The parameter's value from ``tensors``, as PyTorch lays it out."""
        if self.name not in tensors:
            raise Unfit(f"it has no {self.name}")
        value = np.asarray(tensors[self.name], dtype=np.float32)
        if tuple(value.shape) != self.shape:
            raise Unfit(
                f"its {self.name} has the shape {list(value.shape)}, where the network of "
                f"model_metadata.json has {list(self.shape)}"
            )
        if self.layout == "dense":
            value = value.T
        elif self.layout == "pixel":
            value = value.T[:, :, None, None]
        elif self.layout == "conv":
            value = value.transpose(3, 2, 0, 1)
        return np.ascontiguousarray(value.reshape(self.parameter.shape))

    def deepracer(self) -> np.ndarray:
        """The parameter as TensorFlow lays it out."""
        value = self.parameter.detach().cpu().numpy().astype(np.float32)
        if self.layout == "dense":
            value = value.T
        elif self.layout == "pixel":
            value = value[:, :, 0, 0].T
        elif self.layout == "conv":
            value = value.transpose(2, 3, 1, 0)
        return np.ascontiguousarray(value.reshape(self.shape))


class _Found:
    """Names as a checkpoint has them: the camera's scope as the model's simapp named it, an
    unnamed layer by its shape among its head's."""

    def __init__(self, tensors: Mapping[str, np.ndarray]) -> None:
        self.tensors = tensors

    def sensor(self, scope: str, sensor: str, first: str) -> str:
        names = SENSOR_NAMES.get(sensor, (sensor,))
        return next((n for n in names if f"{scope}/{n}/{first}/kernel" in self.tensors), names[0])

    def unnamed(self, head: str, layer: nn.Linear, taken: set[str]) -> str:
        """The unnamed dense layer directly in ``head`` whose kernel fits ``layer``; it is
        taken, so that no other layer gets it."""
        shape = (layer.in_features, layer.out_features)
        for name in sorted(self.tensors):
            inside = name.startswith(f"{head}/") and name.count("/") == head.count("/") + 2
            kernel = inside and name.endswith("/kernel") and name not in taken
            if kernel and tuple(np.shape(self.tensors[name])) == shape:
                taken.add(name)
                return name.removesuffix("/kernel")
        raise Unfit(f"it has no dense layer of {shape[0]} by {shape[1]} in {head}")


class _Named:
    """Names as today's simapp gives them: the camera's own, unnamed layers in their order."""

    def sensor(self, scope: str, sensor: str, first: str) -> str:
        return SENSOR_NAMES.get(sensor, (sensor,))[0]

    def unnamed(self, head: str, layer: nn.Linear, taken: set[str]) -> str:
        count = sum(name.startswith(f"{head}/dense") for name in taken)
        name = f"{head}/dense" + (f"_{count}" if count else "")
        taken.add(f"{name}/kernel")
        return name


def _slots(policy: Policy, complete: bool, names: _Found | _Named) -> list[_Slot]:
    """``policy``'s tensors in DeepRacer's network (see the module's table)."""
    ppo, network = policy.ppo, policy.network
    found: list[_Slot] = []
    if ppo:
        scope = cargraph.policy_scope(ppo)
        found += _extractor(names, scope, network.pi_features_extractor)
        head = f"{scope}/ppo_head_0"
        if hasattr(network, "log_std"):  # a continuous action space
            found += _layer(f"{head}/policy_mean", network.action_net)
            if complete:
                spread = (1, *network.log_std.shape)
                found.append(_Slot(f"{head}/policy_log_std", network.log_std, spread))
        else:
            found += _layer(f"{head}/policy_fc", network.action_net)
        if complete:
            found += _extractor(names, PPO_VALUE_SCOPE, network.vf_features_extractor)
            found += _layer(f"{PPO_VALUE_SCOPE}/v_values_head_0/output", network.value_net)
    else:
        actor, scope = network.actor, cargraph.policy_scope(ppo)
        found += _extractor(names, scope, actor.features_extractor)
        head = f"{scope}/sac_policy_head_0"
        (hidden,) = _linears(actor.latent_pi)
        found += _layer(f"{head}/policy_mean", actor.mu)
        taken = {f"{head}/policy_mean/kernel"}
        found += _layer(names.unnamed(head, hidden, taken), hidden)
        if complete:
            found += _layer(names.unnamed(head, actor.log_std, taken), actor.log_std)
            critic = network.critic
            found += _extractor(names, SAC_Q_SCOPE, critic.features_extractor)
            for number, q in enumerate(critic.q_networks, start=1):
                q_head = f"{SAC_Q_SCOPE}/q_values_head_0/q{number}_head"
                *inner, output = _linears(q)
                taken = {f"{q_head}/q{number}_output/kernel"}
                found += _layer(f"{q_head}/q{number}_output", output)
                for layer in inner:
                    found += _layer(names.unnamed(q_head, layer, taken), layer)
    return found


def _extractor(names: _Found | _Named, scope: str, extractor: DeepRacerFeatures) -> list[_Slot]:
    found = []
    for sensor in extractor.sensors:
        embedder = extractor.embedders[sensor]
        named = names.sensor(scope, sensor, embedder.tf_names[0])
        for layer, name in zip(embedder.layers, embedder.tf_names, strict=True):
            found += _layer(f"{scope}/{named}/{name}", layer)
    return found + _layer(f"{scope}/{MIDDLEWARE}", extractor.middleware)


def _layer(name: str, layer: nn.Module) -> list[_Slot]:
    """A layer's kernel and bias."""
    out, into, *window = layer.weight.shape
    if not window:
        kernel = _Slot(f"{name}/kernel", layer.weight, (into, out), "dense")
    elif window == [1, 1]:
        kernel = _Slot(f"{name}/kernel", layer.weight, (into, out), "pixel")
    else:
        kernel = _Slot(f"{name}/kernel", layer.weight, (*window, into, out), "conv")
    return [kernel, _Slot(f"{name}/bias", layer.bias, (out,))]


def _linears(module: nn.Module) -> list[nn.Linear]:
    return [layer for layer in module.modules() if isinstance(layer, nn.Linear)]
