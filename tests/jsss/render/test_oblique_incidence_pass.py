"""The oblique-incidence pass: what the planner decides and what it changes in a frame."""

import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium
from jsss.incidence import incidence_ratio
from jsss.render import load_scene, parse_scene, plan_scene, render


def _slanted_plane(eta, theta_deg=60.0):
    theta = np.radians(theta_deg)
    data = {
        "geometry": {"shape": "plane", "width": 200.0},
        "material": {"sigma_a": [0.061, 0.97, 1.45], "sigma_s_prime": [0.18, 0.07, 0.03], "eta": eta, "specular": 0.0},
        "lights": [{"type": "directional", "direction": [np.sin(theta), 0.0, -np.cos(theta)]}],
        "camera": {"position": [0.0, -60.0, 160.0], "look_at": [0.0, 0.0, 0.0], "fov": 4, "resolution": [8, 8]},
        "render": {"texture_size": 64, "accuracy": 0.05},
    }
    return parse_scene(data)


@pytest.mark.parametrize("eta", [1.0, 1.3])
def test_a_uniformly_lit_plane_gains_exactly_the_incidence_ratio(eta):
    """Light at 60 degrees on a large plane (no gradient for the profile to act on): with the
    pass on, the diffuse light is the pass-off light times incidence_ratio(medium, cos 60)."""
    scene = _slanted_plane(eta)
    frames = []
    for on in (False, True):
        plan = plan_scene(scene, method="lambert").replace("single scattering", False, "test")
        plan = plan.replace("oblique incidence", on, "test")
        frames.append(np.asarray(render(scene, plan, dtype=jnp.float64).radiance)[3:5, 3:5].reshape(-1, 3).mean(0))
    medium = Medium(jnp.array([0.061, 0.97, 1.45]), jnp.array([0.18, 0.07, 0.03]), jnp.full(3, eta))
    np.testing.assert_allclose(frames[1] / frames[0], np.asarray(incidence_ratio(medium, 0.5)), rtol=1e-9)


def test_the_planner_turns_the_pass_on_where_slanted_light_returns_a_quarter_of_the_target_more():
    ketchup = plan_scene(load_scene("examples/ketchup_plane.toml"))
    assert ketchup.on("oblique incidence") and "60 degrees" in ketchup.describe()
    marble = load_scene("examples/marble_sphere.toml")
    assert plan_scene(marble, accuracy=0.01).on("oblique incidence")  # +1.0-1.5 % >= 0.25 %
    assert not plan_scene(marble, accuracy=0.2).on("oblique incidence")  # < 5 %
    skin = plan_scene(load_scene("examples/skin_backlit.toml"))
    assert not skin.on("oblique incidence")  # layered: no single albedo to take the law from
