"""The network the cars' tests drive with (``test_cars``, ``test_served_policy``), built once a
module: each child would otherwise draw its own initial weights."""

import pytest

from rl.learner import weights_bytes
from rl.policies import Policy
from tests.helpers.sandbox import ENV, POLICY


@pytest.fixture(scope="module")
def policy() -> Policy:
    return Policy.for_environment(POLICY["algorithm"], POLICY["architecture"], ENV)


@pytest.fixture(scope="module")
def weights(policy) -> bytes:
    """One network for every child."""
    return weights_bytes(policy.weights_module.state_dict())
