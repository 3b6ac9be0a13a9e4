"""The oblique-incidence pass: what the planner decides and what it changes in a frame."""

import jax.numpy as jnp
import numpy as np
import pytest

from jsss import Medium
from jsss.diffusion.incidence import incidence_ratio
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


@pytest.mark.parametrize("eta", [1.0, 1.4])
def test_a_point_lights_irradiance_is_read_at_the_deposit_depth(eta):
    """Lambert frames (no spread) of a plane 30 mm under a point light, looking at the lamp's
    foot: the deposit-depth pass scales each pixel by d^2 / (d^2 + 2 delta d cos + delta^2),
    delta = 1 / (2 sigma_t' eta), which under the lamp is the inverse square of a lamp
    30 + delta mm up (closed form from the pixels' own positions)."""
    from jsss.render.image_space import camera_buffers

    sigma_a, sigma_s = np.array([0.06, 0.5, 1.0]), np.array([0.18, 0.3, 0.2])
    data = {
        "geometry": {"shape": "plane", "width": 80.0},
        "material": {"sigma_a": sigma_a.tolist(), "sigma_s_prime": sigma_s.tolist(), "eta": eta, "specular": 0.0},
        "lights": [{"type": "point", "position": [0.0, 0.0, 30.0], "intensity": 1000.0}],
        "camera": {"position": [0.0, -20.0, 120.0], "look_at": [0.0, 0.0, 0.0], "fov": 20, "resolution": [12, 12]},
        "render": {"texture_size": 64, "accuracy": 0.05},
    }
    scene = parse_scene(data)
    plan = plan_scene(scene, method="lambert")
    assert plan.on("deposit depth")
    plan = plan.replace("single scattering", False, "test").replace("oblique incidence", False, "test")
    off, on = (np.asarray(render(scene, plan.replace("deposit depth", flag, "test"), dtype=jnp.float64).radiance)
               for flag in (False, True))
    position = camera_buffers(scene.mesh, scene.camera).position
    d = np.linalg.norm(np.array([0.0, 0.0, 30.0]) - position, axis=-1)[..., None]
    cos = (30.0 / d)
    delta = 1 / (2 * (sigma_a + sigma_s) * eta)
    expected = d**2 / (d**2 + 2 * delta * d * cos + delta**2)
    np.testing.assert_allclose(on[5:7, 5:7] / off[5:7, 5:7], expected[5:7, 5:7], rtol=1e-9)
    centre = (30.0 / (30.0 + delta)) ** 2
    assert np.all(np.abs(on[5:7, 5:7] / off[5:7, 5:7] / centre - 1) < 0.02)


def test_parallel_light_is_not_read_deeper():
    scene = _slanted_plane(1.0)
    plan = plan_scene(scene, method="lambert")
    assert not plan.on("deposit depth") and "no point light" in plan.describe()


def test_irradiance_takes_a_solved_law_in_place_of_the_medium_and_not_both():
    """Normal filtering lights a frame once per channel's normals with one solved law: the
    same irradiance as solving it from the medium, to the last bit; both at once is refused."""
    from jsss.diffusion.incidence import incidence_law
    from jsss.render.lighting import LightGeometry, irradiance

    cosine = np.linspace(0.05, 1.0, 12)
    ones = np.ones_like(cosine)
    light = LightGeometry(cosine=cosine, falloff=ones, visible=ones, thickness=0 * ones,
                          front_uv=np.zeros((12, 2)), behind=0 * ones, to_light=np.zeros((12, 3)))
    medium = Medium([0.01, 0.1, 1.0], [1.0, 1.0, 1.0], [1.3, 1.3, 1.3])
    radiant, eta = np.ones((1, 3)), np.full(3, 1.3)
    solved = irradiance([light], radiant, eta, law=incidence_law(medium))
    np.testing.assert_array_equal(solved, irradiance([light], radiant, eta, medium=medium))
    assert np.all(np.asarray(solved)[:-1] / np.asarray(irradiance([light], radiant, eta))[:-1] > 1)  # slant: more
    with pytest.raises(ValueError, match="not both"):
        irradiance([light], radiant, eta, medium=medium, law=incidence_law(medium))
