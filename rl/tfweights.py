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
    ppo, network = policy.ppo, policy.network
    found: list[tuple[str, torch.Tensor, np.ndarray]] = []
    if ppo:
        scope = cargraph.policy_scope(ppo)
        found += _extractor(tensors, scope, network.pi_features_extractor)
        head = f"{scope}/ppo_head_0"
        if hasattr(network, "log_std"):  # a continuous action space
            found += _layer(tensors, f"{head}/policy_mean", network.action_net)
            if complete:
                spread = (1, *network.log_std.shape)
                found.append(_fit(tensors, f"{head}/policy_log_std", network.log_std, spread))
        else:
            found += _layer(tensors, f"{head}/policy_fc", network.action_net)
        if complete:
            found += _extractor(tensors, PPO_VALUE_SCOPE, network.vf_features_extractor)
            found += _layer(tensors, f"{PPO_VALUE_SCOPE}/v_values_head_0/output", network.value_net)
    else:
        actor, scope = network.actor, cargraph.policy_scope(ppo)
        found += _extractor(tensors, scope, actor.features_extractor)
        head = f"{scope}/sac_policy_head_0"
        (hidden,) = _linears(actor.latent_pi)
        found += _layer(tensors, f"{head}/policy_mean", actor.mu)
        taken = {f"{head}/policy_mean/kernel"}
        found += _layer(tensors, _unnamed(tensors, head, hidden, taken), hidden)
        if complete:
            log_std = _unnamed(tensors, head, actor.log_std, taken)
            found += _layer(tensors, log_std, actor.log_std)
            critic = network.critic
            found += _extractor(tensors, SAC_Q_SCOPE, critic.features_extractor)
            for number, q in enumerate(critic.q_networks, start=1):
                q_head = f"{SAC_Q_SCOPE}/q_values_head_0/q{number}_head"
                *inner, output = _linears(q)
                taken = {f"{q_head}/q{number}_output/kernel"}
                found += _layer(tensors, f"{q_head}/q{number}_output", output)
                for layer in inner:
                    found += _layer(tensors, _unnamed(tensors, q_head, layer, taken), layer)
    with torch.no_grad():
        for _, parameter, value in found:
            parameter.copy_(torch.from_numpy(value))
        if not ppo and complete:
            network.critic_target.load_state_dict(network.critic.state_dict())


def _extractor(tensors, scope: str, extractor: DeepRacerFeatures) -> list:
    found = []
    for sensor in extractor.sensors:
        embedder = extractor.embedders[sensor]
        names = SENSOR_NAMES.get(sensor, (sensor,))
        first = embedder.tf_names[0]
        named = next((n for n in names if f"{scope}/{n}/{first}/kernel" in tensors), names[0])
        for layer, name in zip(embedder.layers, embedder.tf_names, strict=True):
            found += _layer(tensors, f"{scope}/{named}/{name}", layer)
    return found + _layer(tensors, f"{scope}/{MIDDLEWARE}", extractor.middleware)


def _layer(tensors, name: str, layer: nn.Module) -> list:
    """A layer's kernel and bias, each as PyTorch lays it out."""
    out, into, *window = layer.weight.shape
    if not window:  # dense: TensorFlow's [in, out]
        return [
            _fit(tensors, f"{name}/kernel", layer.weight, (into, out), lambda k: k.T),
            _fit(tensors, f"{name}/bias", layer.bias, (out,)),
        ]
    if window == [1, 1]:  # a camera's per-pixel dense layer: TensorFlow's [in, out]
        kernel = _fit(
            tensors, f"{name}/kernel", layer.weight, (into, out), lambda k: k.T[:, :, None, None]
        )
    else:  # TensorFlow's [height, width, in, out]
        kernel = _fit(
            tensors,
            f"{name}/kernel",
            layer.weight,
            (*window, into, out),
            lambda k: k.transpose(3, 2, 0, 1),
        )
    return [kernel, _fit(tensors, f"{name}/bias", layer.bias, (out,))]


def _fit(tensors, name: str, parameter: torch.Tensor, shape: tuple, layout=None) -> tuple:
    """``parameter``'s value: the tensor ``name``, of TensorFlow's ``shape``, laid out as
    PyTorch's by ``layout``."""
    if name not in tensors:
        raise Unfit(f"it has no {name}")
    value = np.asarray(tensors[name], dtype=np.float32)
    if tuple(value.shape) != tuple(int(size) for size in shape):
        raise Unfit(
            f"its {name} has the shape {list(value.shape)}, where the network of "
            f"model_metadata.json has {[int(size) for size in shape]}"
        )
    value = layout(value) if layout else value.reshape(parameter.shape)
    return name, parameter, np.ascontiguousarray(value)


def _linears(module: nn.Module) -> list[nn.Linear]:
    return [layer for layer in module.modules() if isinstance(layer, nn.Linear)]


def _unnamed(tensors, head: str, layer: nn.Linear, taken: set[str]) -> str:
    """The name of the unnamed dense layer directly in ``head`` whose kernel fits ``layer``;
    it is taken, so that no other layer gets it."""
    shape = (layer.in_features, layer.out_features)
    for name in sorted(tensors):
        inside = name.startswith(f"{head}/") and name.count("/") == head.count("/") + 2
        kernel = inside and name.endswith("/kernel") and name not in taken
        if kernel and tuple(np.shape(tensors[name])) == shape:
            taken.add(name)
            return name.removesuffix("/kernel")
    raise Unfit(f"it has no dense layer of {shape[0]} by {shape[1]} in {head}")
