"""The policy as DeepRacer's frozen graph: TensorFlow runs it, and OpenVINO's TensorFlow front end
converts it with the car's input names and shapes, and both choose the PyTorch policy's action on
rendered sensor frames, for every algorithm, action space type, sensor set and network."""

import gymnasium
import numpy as np
import openvino
import pytest
import torch

import simulator
from rl import cargraph, tfgraph
from rl.networks import DEEP, SHALLOW
from rl.policies import Policy
from tests.helpers.models import sensor_frames

DISCRETE = [
    {"steering_angle": -30, "speed": 0.6}, {"steering_angle": 0, "speed": 1.0},
    {"steering_angle": 30, "speed": 0.6},
]  # fmt: skip
CONTINUOUS = {"steering_angle": {"low": -30.0, "high": 30.0}, "speed": {"low": 0.5, "high": 2.0}}
KINDS = [("clipped_ppo", DISCRETE), ("clipped_ppo", CONTINUOUS), ("sac", CONTINUOUS)]
SENSORS = [
    ["FRONT_FACING_CAMERA"], ["STEREO_CAMERAS"], ["FRONT_FACING_CAMERA", "LIDAR"],
    ["STEREO_CAMERAS", "SECTOR_LIDAR"],
]  # fmt: skip
CASES = [(algorithm, space, sensors, SHALLOW) for algorithm, space in KINDS for sensors in SENSORS]
# The 5-layer networks are large (stereo: 57 million weights); one sensor set each way.
CASES += [
    ("clipped_ppo", DISCRETE, ["FRONT_FACING_CAMERA", "LIDAR"], DEEP),
    ("sac", CONTINUOUS, ["STEREO_CAMERAS"], DEEP),
]


def case_id(case) -> str:
    algorithm, space, sensors, network = case
    kind = "discrete" if isinstance(space, list) else "continuous"
    return f"{algorithm}-{kind}-{'+'.join(sensors)}-{'3' if network == SHALLOW else '5'}-layer"


def build(algorithm, space, sensors, network):
    environment = {"track": "rookie-loop", "sensors": sensors, "action_space": space}
    env = gymnasium.make(simulator.ENV_ID, **environment)
    torch.manual_seed(5)
    policy = Policy.build(algorithm, network, env.observation_space, env.action_space)
    # Heads that tell frames apart: SB3 starts them near zero, which would give every frame
    # almost the same action (and not so steep that a squashed action saturates at +-1).
    head = policy.network.action_net if policy.ppo else policy.network.actor.mu
    with torch.no_grad():
        head.weight.mul_(200.0 if isinstance(space, list) else 20.0)
    env.close()
    return policy, sensor_frames(environment, count=4)


def expected(policy, observation, discrete: bool) -> np.ndarray:
    """What the car must get: the probabilities (discrete) or the deterministic action."""
    tensor, _ = policy.network.obs_to_tensor(observation)
    with torch.no_grad():
        if discrete:
            return policy.network.get_distribution(tensor).distribution.probs.numpy()
    action = policy.drive(observation)
    return action[None]


def car_inputs(policy, observation) -> dict[str, np.ndarray]:
    """The car's inputs: sensor values as float32, cameras as NHWC bytes (0-255)."""
    inputs = {}
    for sensor, value in observation.items():
        value = value[None].astype(np.float32)
        if value.ndim == 4:
            value = value.transpose(0, 2, 3, 1)
        inputs[cargraph.input_name(policy.ppo, sensor)] = value
    return inputs


@pytest.mark.parametrize(
    ("algorithm", "space", "sensors", "network"), CASES, ids=[case_id(case) for case in CASES]
)
def test_tensorflow_and_openvino_run_the_car_graph_as_pytorch_does(
    algorithm, space, sensors, network, tensorflow, tmp_path
):
    discrete = isinstance(space, list)
    policy, frames = build(algorithm, space, sensors, network)
    data = cargraph.car_graph(policy, discrete)
    output = cargraph.output_name(policy.ppo)

    graph_def = tensorflow.compat.v1.GraphDef.FromString(data)
    assert [n.name for n in graph_def.node if n.op == "Placeholder"] == [
        cargraph.input_name(policy.ppo, sensor) for sensor in sorted(sensors)
    ]
    with tensorflow.Graph().as_default() as graph:
        tensorflow.compat.v1.import_graph_def(graph_def, name="")
        session = tensorflow.compat.v1.Session(graph=graph)

    # As the car's optimizer converts it: the .pb, its input names and the car's shapes. (OpenVINO
    # 2021's mo_tf.py takes the node's name; the front end of 2022 on, the tensor's: name:0. The
    # same holds for a graph TensorFlow wrote.)
    (tmp_path / "model.pb").write_bytes(data)
    observed = policy.network.observation_space
    car_inputs_named = [
        (f"{cargraph.input_name(policy.ppo, s)}:0", cargraph.input_shape(observed[s]))
        for s in sensors
    ]
    converted = openvino.convert_model(str(tmp_path / "model.pb"), input=car_inputs_named)
    (only,) = converted.outputs  # the output the car reads, by DeepRacer's name
    assert f"{output}:0" in only.get_names()
    compiled = openvino.Core().compile_model(converted, "CPU", {"INFERENCE_PRECISION_HINT": "f32"})

    chosen = []
    for observation in frames:
        wanted = expected(policy, observation, discrete)
        inputs = car_inputs(policy, observation)
        feed = {f"{name}:0": value for name, value in inputs.items()}
        from_tensorflow = session.run(f"{output}:0", feed)
        from_openvino = compiled(feed)[0]
        for got in (from_tensorflow, from_openvino):
            assert got.shape == wanted.shape == (1, len(space) if discrete else 2)
            np.testing.assert_allclose(got, wanted, atol=1e-4)
        chosen.append(tuple(np.round(wanted[0], 3)))
    session.close()
    assert len(set(chosen)) > 1  # the frames are told apart: the comparison means something


def test_the_graphs_weights_read_back_under_deepracers_names():
    policy, _ = build("clipped_ppo", DISCRETE, ["FRONT_FACING_CAMERA", "LIDAR"], SHALLOW)
    weights = tfgraph.constants(cargraph.car_graph(policy, discrete=True))
    prefix = "main_level/agent/main/online/network_1"
    extractor = policy.network.pi_features_extractor
    conv = extractor.embedders["FRONT_FACING_CAMERA"].layers[0].weight.detach().numpy()
    np.testing.assert_array_equal(
        weights[f"{prefix}/FRONT_FACING_CAMERA/Conv2d_0/kernel"], conv.transpose(2, 3, 1, 0)
    )
    assert weights[f"{prefix}/FRONT_FACING_CAMERA/Conv2d_4/kernel"].shape == (3, 3, 64, 64)
    assert weights[f"{prefix}/LIDAR/Dense_2/kernel"].shape == (256, 256)
    # The camera's 11 x 16 x 64 embedding and the lidar's 256, as rl_coach flattens them.
    assert weights[f"{prefix}/middleware_fc_embedder/Dense_0/kernel"].shape == (11264 + 256, 512)
    assert weights[f"{prefix}/ppo_head_0/policy_fc/kernel"].shape == (512, 3)
