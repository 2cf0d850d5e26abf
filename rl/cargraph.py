"""A policy as DeepRacer's frozen graph: what the physical car's model optimizer converts.

The graph is the one deepracer-simapp freezes (bundle/markov/boto/s3/files/checkpoint_files/
tensorflow_model.py:389-406, 01f5f01): the policy network only, its variables turned into
constants under their checkpoint names, and one output node. Names, shapes and layout are
DeepRacer's, so that the car's model optimizer finds what it feeds and reads
(aws-deepracer-model-optimizer-pkg model_optimizer_pkg/constants.py:55-90):

- inputs ``main_level/agent/<head>/online/network_0/<SENSOR>/<SENSOR>``, where ``<head>`` is
  ``main`` for PPO and ``policy`` for SAC; cameras as NHWC bytes (0-255, float32) [N, 120, 160, 1]
  or [N, 120, 160, 2] (stereo: left, right), the lidar as [N, 64] metres or [N, 8] sector bits.
  The graph divides images by 255 itself, as rl_coach's embedders do (embedder.py:107);
- the output (simapp bundle/markov/boto/s3/constants.py:84-87):
  PPO ``main_level/agent/main/online/network_1/ppo_head_0/policy``, the softmax over the actions of
  ``model_metadata.json`` (discrete; rl_coach heads/ppo_head.py:121-123) or the Gaussian's mean,
  steering then speed, each in [-1, 1] of its range (continuous; ppo_head.py:139-140);
  SAC ``main_level/agent/policy/online/network_0/sac_policy_head_0/policy``, the mean.

One departure: DeepRacer's SAC ``policy`` node is the mean before its tanh (heads/sac_head.py:58),
which the simulator squashes (:80-89) and the car only clamps to [-1, 1] (deepracer-custom-car
deepracer_navigation_node.py:119-146), so DeepRacer's car drives another action than its simulator
trained. Here the node is the squashed mean: the car drives what the policy chose.
"""

from __future__ import annotations

import numpy as np
import torch

from rl import tfgraph
from rl.networks import Embedder
from rl.policies import Policy

ROOT = "main_level/agent"


def input_name(ppo: bool, sensor: str) -> str:
    return f"{ROOT}/{'main' if ppo else 'policy'}/online/network_0/{sensor}/{sensor}"


def policy_scope(ppo: bool) -> str:
    """Where the policy network sits: PPO's second network (the value's is the first), SAC's
    policy wrapper's only one."""
    return f"{ROOT}/main/online/network_1" if ppo else f"{ROOT}/policy/online/network_0"


def output_name(ppo: bool) -> str:
    return f"{policy_scope(ppo)}/{'ppo_head_0' if ppo else 'sac_policy_head_0'}/policy"


def input_shape(space) -> list[int]:
    """The car's shape of one sensor's input: NHWC for cameras (the space is CHW)."""
    if len(space.shape) == 3:
        channels, height, width = space.shape
        return [1, height, width, channels]
    return [1, int(np.prod(space.shape))]


def car_graph(policy: Policy, discrete: bool) -> bytes:
    """The serialized frozen graph (``GraphDef``) of ``policy``, a layout-2 network."""
    network, ppo = policy.network, policy.ppo
    prefix = policy_scope(ppo)
    extractor = network.pi_features_extractor if ppo else network.actor.features_extractor
    graph = tfgraph.Graph()
    embedded = []
    for sensor in extractor.sensors:
        shape = input_shape(network.observation_space[sensor])
        x = graph.placeholder(input_name(ppo, sensor), [-1, *shape[1:]])
        embedded.append(_embed(graph, f"{prefix}/{sensor}", x, extractor.embedders[sensor]))
    x = embedded[0] if len(embedded) == 1 else graph.concat(f"{prefix}/merger", embedded, -1)
    x = _dense(graph, f"{prefix}/middleware_fc_embedder/Dense_0", x, extractor.middleware)
    x = graph.unary(f"{prefix}/middleware_fc_embedder/Dense_0/Relu", "Relu", x)
    if ppo:
        head = f"{prefix}/ppo_head_0"
        if discrete:
            x = _dense(graph, f"{head}/policy_fc", x, network.action_net)
            graph.unary(output_name(ppo), "Softmax", x)
        else:
            x = _dense(graph, f"{head}/policy_mean", x, network.action_net)
            graph.unary(output_name(ppo), "Identity", x)
    else:
        head, actor = f"{prefix}/sac_policy_head_0", network.actor
        (hidden,) = [layer for layer in actor.latent_pi if isinstance(layer, torch.nn.Linear)]
        x = graph.unary(f"{head}/dense/Relu", "Relu", _dense(graph, f"{head}/dense", x, hidden))
        x = _dense(graph, f"{head}/policy_mean", x, actor.mu)
        graph.unary(output_name(ppo), "Tanh", x)
    return graph.serialize()


def _embed(graph: tfgraph.Graph, scope: str, x: str, embedder: Embedder) -> str:
    if embedder.image:
        x = graph.divide(f"{scope}/truediv", x, 255.0)
    for layer, name in zip(embedder.layers, embedder.tf_names, strict=True):
        if isinstance(layer, torch.nn.Conv2d):
            kernel = _array(layer.weight).transpose(2, 3, 1, 0)  # OIHW -> TensorFlow's HWIO
            x = graph.conv2d(f"{scope}/{name}", x, kernel, _array(layer.bias), layer.stride[0])
        else:
            x = _dense(graph, f"{scope}/{name}", x, layer)
        x = graph.unary(f"{scope}/{name}/Relu", "Relu", x)
    if embedder.image:
        x = graph.reshape(f"{scope}/Flatten/flatten/Reshape", x, [-1, embedder.size])
    return x


def _dense(graph: tfgraph.Graph, scope: str, x: str, layer: torch.nn.Linear) -> str:
    return graph.dense(scope, x, _array(layer.weight).T, _array(layer.bias))


def _array(tensor: torch.Tensor) -> np.ndarray:
    return tensor.detach().cpu().numpy().astype(np.float32)
