"""DeepRacer models built with TensorFlow as deepracer-simapp builds them, for the import tests.

Written here from rl_coach's and simapp's network code, not from Pitlane's importer, so that the
importer is checked against DeepRacer's names rather than its own: in TensorFlow 1's graph mode,
each network under ``main_level/agent/<wrapper>/<copy>/network_<i>``, the ``online`` copy that
rl_coach's saver keeps and, to show that the importer leaves them alone, a ``target`` copy and
Adam's slots that published checkpoints do not hold; the
inputs as placeholders of the first network (general_network.py:245-262), the embedders' layers
``Conv2d_<2i>``/``Dense_<2i>`` (embedder.py:115-119), ``middleware_fc_embedder/Dense_0``, and the
heads of ppo_head.py, v_head.py and simapp's sac_head.py and sac_q_head.py. The layers those leave
unnamed are named as TensorFlow 1's layers name them in their scope (``dense``, ``dense_1``), or,
with ``keras_names``, as Keras numbers them across the graph.
"""

from __future__ import annotations

import itertools
import json
from dataclasses import dataclass

import numpy as np

from rl.networks import EMBEDDERS, MIDDLEWARE

ROOT = "main_level/agent"


@dataclass
class DeepRacerModel:
    """A built model: its session, placeholders and outputs by role."""

    tf: object
    session: object
    graph: object
    ppo: bool
    inputs: dict  # sensor -> its placeholders (SAC: the policy's and the Q network's)
    outputs: dict  # "policy", "log_std", "value" (PPO), "q1", "q2" (SAC) -> tensor
    action: object | None  # SAC's Q networks' action placeholder
    output_name: str  # the frozen graph's output node

    def run(self, what: str, observation: dict, action=None) -> np.ndarray:
        feed = {}
        for sensor, value in observation.items():
            feed |= {placeholder: nhwc(value) for placeholder in self.inputs[sensor]}
        if action is not None:
            feed[self.action] = np.asarray(action, np.float32)[None]
        return self.session.run(self.outputs[what], feed)

    def checkpoint(self, prefix: str) -> None:
        """rl_coach's checkpoint: every variable of the graph (online, target, Adam's slots)."""
        with self.graph.as_default():
            saver = self.tf.compat.v1.train.Saver()
            saver.save(self.session, prefix, write_meta_graph=False)

    def frozen_graph(self) -> bytes:
        """The policy as simapp freezes it (tensorflow_model.py:389-406): variables to constants,
        one output."""
        convert = self.tf.compat.v1.graph_util.convert_variables_to_constants
        frozen = convert(self.session, self.graph.as_graph_def(), [self.output_name])
        return frozen.SerializeToString()


def nhwc(value: np.ndarray) -> np.ndarray:
    """One of our observations (cameras CHW bytes) as the car's input: a batch of one, NHWC."""
    value = value[None].astype(np.float32)
    return value.transpose(0, 2, 3, 1) if value.ndim == 4 else value.reshape(1, -1)


def build(
    tf,
    algorithm: str,
    network: str,
    observation_space,
    action_count: int,
    discrete: bool,
    *,
    seed: int = 0,
    keras_names: bool = False,
    camera: str = "FRONT_FACING_CAMERA",
) -> DeepRacerModel:
    """A model with random weights, steep enough in the heads to tell frames apart; ``camera``
    names the front camera's scope (simapp before 2.0 called it ``observation``)."""
    tf1 = tf.compat.v1
    graph = tf.Graph()
    rng = np.random.default_rng(seed)
    counter = itertools.count()

    def unnamed() -> str:
        if not keras_names:
            return tf1.get_default_graph().unique_name("dense", mark_as_used=False).split("/")[-1]
        number = next(counter) + 7  # earlier layers of the graph took the first numbers
        return f"dense_{number}"

    def scoped(sensor: str) -> str:
        return camera if sensor == "FRONT_FACING_CAMERA" else sensor

    def variable(name: str, shape, scale: float) -> object:
        value = rng.normal(0.0, scale, shape).astype(np.float32)
        return tf1.get_variable(name, initializer=value)

    def dense(x, units: int, name: str, gain: float = 1.0):
        fan_in = int(x.shape[-1])
        with tf1.variable_scope(name):
            kernel = variable("kernel", (fan_in, units), gain / np.sqrt(fan_in))
            bias = variable("bias", (units,), 0.1)
        return tf.nn.bias_add(tf.tensordot(x, kernel, [[x.shape.ndims - 1], [0]]), bias)

    def conv(x, filters: int, size: int, stride: int, name: str):
        fan_in = int(x.shape[-1]) * size * size
        with tf1.variable_scope(name):
            kernel = variable(
                "kernel", (size, size, int(x.shape[-1]), filters), 1.0 / np.sqrt(fan_in)
            )
            bias = variable("bias", (filters,), 0.1)
        return tf.nn.bias_add(tf.nn.conv2d(x, kernel, [1, stride, stride, 1], "VALID"), bias)

    def embed(placeholders: dict):
        embedded = []
        for sensor in sorted(placeholders):
            x = placeholders[sensor]
            image = x.shape.ndims == 4
            with tf1.variable_scope(scoped(sensor)):
                if image:
                    x = x / 255.0
                for index, (kind, units, *shape) in enumerate(EMBEDDERS[network, sensor]):
                    name = f"{'Conv2d' if kind == 'conv' else 'Dense'}_{2 * index}"
                    x = conv(x, units, *shape, name) if kind == "conv" else dense(x, units, name)
                    x = tf.nn.relu(x)
                if image:
                    x = tf.reshape(x, [-1, int(np.prod(x.shape[1:]))])
            embedded.append(x)
        x = embedded[0] if len(embedded) == 1 else tf.concat(embedded, -1)
        with tf1.variable_scope("middleware_fc_embedder"):
            return tf.nn.relu(dense(x, MIDDLEWARE, "Dense_0"))

    def placeholders_for() -> dict:
        found = {}
        for sensor, space in observation_space.spaces.items():
            shape = space.shape
            shape = [None, shape[1], shape[2], shape[0]] if len(shape) == 3 else [None, shape[0]]
            with tf1.variable_scope(scoped(sensor)):
                found[sensor] = tf1.placeholder(tf.float32, shape, name=scoped(sensor))
        return found

    outputs, action, inputs, q_inputs = {}, None, {}, {}
    with graph.as_default():
        for copy in ("online", "target"):
            if algorithm == "clipped_ppo":
                with tf1.variable_scope(f"{ROOT}/main/{copy}"):
                    with tf1.variable_scope("network_0"):
                        inputs = placeholders_for() if copy == "online" else inputs
                        x = embed(inputs)
                        with tf1.variable_scope("v_values_head_0"):
                            value = dense(x, 1, "output")
                    with tf1.variable_scope("network_1"):
                        x = embed(inputs)
                        with tf1.variable_scope("ppo_head_0"):
                            if discrete:
                                logits = dense(x, action_count, "policy_fc", gain=30.0)
                                policy = tf.nn.softmax(logits, name="policy")
                                log_std = None
                            else:
                                mean = dense(x, action_count, "policy_mean", gain=3.0)
                                policy = tf.identity(mean, name="policy")
                                log_std = variable("policy_log_std", (1, action_count), 0.3)
                if copy == "online":
                    outputs = {"policy": policy, "value": value, "log_std": log_std}
                    output_name = policy.op.name
            else:
                with tf1.variable_scope(f"{ROOT}/policy/{copy}/network_0"):
                    inputs = placeholders_for() if copy == "online" else inputs
                    x = embed(inputs)
                    with tf1.variable_scope("sac_policy_head_0"):
                        hidden = tf.nn.relu(dense(x, 256, unnamed()))
                        mean = dense(hidden, action_count, "policy_mean", gain=3.0)
                        policy = tf.identity(mean, name="policy")
                        log_std = tf.clip_by_value(dense(hidden, action_count, unnamed()), -20, 2)
                with tf1.variable_scope(f"{ROOT}/q/{copy}/network_0"):
                    q_inputs = placeholders_for() if copy == "online" else q_inputs
                    x = embed(q_inputs)
                    with tf1.variable_scope("q_values_head_0"):
                        taken = tf1.placeholder(tf.float32, [None, action_count], "action")
                        qs = []
                        for number in (1, 2):
                            with tf1.variable_scope(f"q{number}_head"):
                                q = tf.concat([x, taken], -1)
                                q = tf.nn.relu(dense(q, 256, unnamed()))
                                q = tf.nn.relu(dense(q, 256, unnamed()))
                                qs.append(dense(q, 1, f"q{number}_output"))
                if copy == "online":
                    outputs = {"policy": policy, "log_std": log_std, "q1": qs[0], "q2": qs[1]}
                    output_name, action = policy.op.name, taken
        # Adam's slots beside the weights, as rl_coach's optimizer adds them (here the heads'
        # only, to keep the archives small), and the step counter.
        for weight in list(tf1.global_variables()):
            for slot in ("Adam", "Adam_1") if "_head_0/" in weight.op.name else ():
                tf1.get_variable(
                    f"{weight.op.name}/{slot}",
                    trainable=False,
                    initializer=np.zeros(weight.shape, np.float32),
                )
        tf1.get_variable(
            f"{ROOT}/main/online/global_step", initializer=np.int64(1234), trainable=False
        )
        session = tf1.Session(graph=graph)
        session.run(tf1.global_variables_initializer())
    ppo = algorithm == "clipped_ppo"
    inputs = {s: (inputs[s],) if ppo else (inputs[s], q_inputs[s]) for s in inputs}
    return DeepRacerModel(tf, session, graph, ppo, inputs, outputs, action, output_name)


def checkpoints_json(best: str, last: str) -> bytes:
    """simapp's deepracer_checkpoints.json (deepracer_checkpoint_json.py:83-131)."""
    return json.dumps(
        {
            "best_checkpoint": {"name": best, "time_stamp": 1700000000.0, "avg_eval_metric": 0.5},
            "last_checkpoint": {"name": last, "time_stamp": 1700000100.0, "avg_eval_metric": 0.4},
        }
    ).encode()
