"""DeepRacer's networks as Pitlane computes them."""

import pytest
import torch
from torch import nn

from rl.networks import CameraConv2d


@pytest.mark.parametrize(
    ("channels", "kernel", "stride", "size"),
    [(1, 8, 4, (120, 160)), (2, 8, 4, (120, 160)), (1, 5, 2, (120, 160)), (1, 5, 2, (33, 47))],
    ids=["3-layer camera", "3-layer stereo", "5-layer camera", "kernel past whole blocks"],
)
def test_a_cameras_first_convolution_learns_exactly_as_a_plain_one(channels, kernel, stride, size):
    """Space to depth is the same sums in another order: the same output and the same gradients
    as nn.Conv2d's, to float rounding, and the same weights by the same names."""
    torch.manual_seed(0)
    fast = CameraConv2d(channels, 32, kernel, stride)
    plain = nn.Conv2d(channels, 32, kernel, stride)
    plain.load_state_dict(fast.state_dict())
    assert fast.state_dict().keys() == plain.state_dict().keys()
    image = torch.rand(4, channels, *size)
    upstream = torch.rand_like(plain(image))
    outputs = []
    for layer in (fast, plain):
        output = layer(image)
        (output * upstream).sum().backward()
        outputs.append(output)
    torch.testing.assert_close(outputs[0], outputs[1], rtol=1e-5, atol=1e-5)
    torch.testing.assert_close(fast.weight.grad, plain.weight.grad, rtol=1e-4, atol=1e-4)
    torch.testing.assert_close(fast.bias.grad, plain.bias.grad, rtol=1e-4, atol=1e-4)
    with torch.no_grad():  # acting and the exports: nn.Conv2d's own path
        torch.testing.assert_close(fast(image), plain(image), rtol=0, atol=0)
