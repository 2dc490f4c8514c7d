"""Actor/Critic shapes, flat vectors in Eq. 1 order, numpy versus torch."""

import numpy as np
import pytest
import torch

from lonlib.ddpg.nets import BatchedMLP
from lonlib.task.policy import actor_spec, critic_spec, forward_numpy


def test_paper_parameter_count_for_two_carts():
    assert actor_spec(2).sizes == (20, 20, 20, 20, 2)
    assert critic_spec(2).sizes == (22, 20, 20, 20, 1)
    assert actor_spec(2).n_params + critic_spec(2).n_params == 2623


@pytest.mark.parametrize("n_carts", [1, 2, 5])
def test_flat_round_trip_and_eq1_order(n_carts):
    spec = actor_spec(n_carts)
    flat = spec.initial(np.random.default_rng(n_carts))
    net = BatchedMLP(spec, flat[None])
    np.testing.assert_array_equal(net.flat()[0], flat)
    # Eq. 1: layer 1's weights (neuron by neuron) come first, then layer 1's biases.
    first_w = net.weights[0].detach().numpy()[0]
    fan_in, fan_out = spec.layers[0]
    np.testing.assert_array_equal(flat[: fan_in * fan_out], first_w.ravel())
    np.testing.assert_array_equal(
        flat[fan_in * fan_out : fan_in * fan_out + fan_out], net.biases[0].detach().numpy()[0]
    )
    other = spec.initial(np.random.default_rng(99))
    net.load_flat(other[None])
    np.testing.assert_array_equal(net.flat()[0], other)


@pytest.mark.parametrize("spec", [actor_spec(2), critic_spec(2)])
def test_numpy_forward_matches_torch(spec):
    rng = np.random.default_rng(0)
    flats = np.stack([spec.initial(rng) for _ in range(3)])
    x = rng.uniform(size=(3, 50, spec.sizes[0])).astype(np.float32)
    torch_out = BatchedMLP(spec, flats)(torch.as_tensor(x)).detach().numpy()
    for i in range(3):
        np.testing.assert_allclose(forward_numpy(spec, flats[i], x[i]), torch_out[i], atol=1e-6)
    # one parameter vector per row evaluates row b with network b
    per_row = forward_numpy(spec, flats[[0, 1, 2]], x[[0, 1, 2], 0])
    np.testing.assert_allclose(per_row, torch_out[[0, 1, 2], 0], atol=1e-6)
    if spec.sigmoid_output:
        assert (torch_out > 0).all() and (torch_out < 1).all()


def test_wrong_sizes_are_refused():
    with pytest.raises(ValueError, match="2623|entries"):
        actor_spec(2).unflatten(np.zeros(10))
