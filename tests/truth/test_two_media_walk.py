"""The two-media walk (tests/truth/two_media_walk.py) is checked against the colour-layer walk,
which adding-doubling checks: with one medium on both sides, and far from the edge, each side
returns its own medium's uniform exitance (through a real dielectric, eta 1.3)."""

import numpy as np

from tests.truth.colour_layer_walk import uniform_total
from tests.truth.two_media_walk import edge_exitance

MARBLE = ([0.0021, 0.0041, 0.0071], [2.19, 2.62, 3.00])
SKIN1 = ([0.032, 0.17, 0.48], [0.74, 0.88, 1.01])


def test_one_medium_on_both_sides_is_the_uniform_half_space():
    _, exitance, stderr = edge_exitance(SKIN1, SKIN1, 1.3, photons=60_000, half_width=40.0,
                                        x_edges=np.linspace(-20, 20, 5), seed=1)
    total, total_err = uniform_total(*SKIN1, 1.3, photons=60_000, seed=2)
    np.testing.assert_array_less(np.abs(exitance.mean(0) - total), 4 * (stderr.max(0) + total_err))


def test_far_from_the_edge_each_side_is_its_own_medium():
    _, exitance, stderr = edge_exitance(MARBLE, SKIN1, 1.0, photons=200_000, half_width=60.0,
                                        x_edges=np.array([-40.0, -25.0, 25.0, 40.0]), seed=3)
    for side, medium in ((0, MARBLE), (2, SKIN1)):
        total, total_err = uniform_total(*medium, 1.0, photons=60_000, seed=4)
        np.testing.assert_array_less(np.abs(exitance[side] - total), 4 * (stderr[side] + total_err) + 0.01 * total)
