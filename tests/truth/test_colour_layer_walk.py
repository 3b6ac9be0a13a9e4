"""The colour-layer walk (tests/truth/colour_layer_walk.py) is itself checked against what shares
nothing with it: adding-doubling (iadpython) for the uniformly lit half-space, and the layer's
own algebra (a constant map k scales every tally by exactly k for the same seed)."""

import numpy as np
import pytest

from tests.truth.colour_layer_walk import step_exitance, uniform_total

iadpython = pytest.importorskip("iadpython")


@pytest.mark.parametrize("albedo, eta", [(0.95, 1.4), (0.6, 1.0), (0.99, 1.33)])
def test_uniform_half_space_matches_adding_doubling(albedo, eta):
    sigma_s = albedo
    sigma_a = 1.0 - albedo
    total, stderr = uniform_total([sigma_a] * 3, [sigma_s] * 3, eta, photons=60_000, seed=3)
    sample = iadpython.Sample(a=albedo, b=1000.0, g=0.0, n=eta, n_above=1.0, n_below=1.0, quad_pts=16)
    ur1, _, _, _ = sample.rt()
    specular = ((eta - 1) / (eta + 1)) ** 2
    # iadpython's UR1 includes the specular F(0), the walk does not; 0.002 is iadpython's own error.
    np.testing.assert_allclose(total, ur1 - specular, atol=4 * stderr.max() + 0.002)


def test_a_constant_map_scales_every_bin_exactly():
    args = ([0.02, 0.05, 0.1], [1.0, 1.2, 1.5], 1.3)
    kwargs = {"photons": 20_000, "half_width": 5.0, "bin_width": 1.0, "seed": 5, "batches": 8}
    _, white, _ = step_exitance(*args, (1, 1, 1), (1, 1, 1), **kwargs)
    _, grey, _ = step_exitance(*args, (0.3, 0.5, 0.8), (0.3, 0.5, 0.8), **kwargs)
    np.testing.assert_allclose(grey, white * np.array([0.3, 0.5, 0.8]), rtol=1e-12)
