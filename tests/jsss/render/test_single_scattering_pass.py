"""The single-scattering render pass against quadrature of the single-scattering integral on a plane."""

import jax.numpy as jnp
import numpy as np
import pytest
from scipy.integrate import dblquad, quad

from jsss.render import parse_scene, plan_scene, render
from tests.helpers import external_diffuse_transmittance, fresnel_reflectance_numpy

SIGMA_A, SIGMA_S, ETA = np.array([0.3, 2.0, 5.0]), np.array([1.5, 1.0, 0.5]), 1.4
LIGHT_THETA = np.radians(35.0)


def _single_radiance(cos_i, cos_o, phi, sigma_a, sigma_s):
    """Radiance leaving a flat half-space after one isotropic scattering, per unit irradiance.

    Integrated over depth z here: the refracted beam (flux E Ft_i per area, path z / cos_i'
    to depth z) scatters with sigma_s / (4 pi) towards the refracted view ray (path z / cos_o'
    back up), and radiance leaves with Ft_o / eta^2.
    """
    sigma_t = sigma_a + sigma_s
    ci = np.sqrt(1 - (1 - cos_i**2) / ETA**2)
    co = np.sqrt(1 - (1 - cos_o**2) / ETA**2)
    ft = (1 - fresnel_reflectance_numpy(cos_i, ETA)) * (1 - fresnel_reflectance_numpy(cos_o, ETA))
    inside = quad(lambda z: sigma_s / (4 * np.pi) / ci / co * np.exp(-sigma_t * z * (1 / ci + 1 / co)), 0, np.inf)[0]
    return ft * inside / ETA**2


def _plane(single_on):
    data = {
        "geometry": {"shape": "plane", "width": 200.0},
        "material": {"sigma_a": SIGMA_A.tolist(), "sigma_s_prime": SIGMA_S.tolist(), "eta": ETA, "specular": 0.0},
        "lights": [{"type": "directional", "direction": [0.0, -np.sin(LIGHT_THETA), -np.cos(LIGHT_THETA)]}],
        "camera": {"position": [0.0, 120.0, 160.0], "look_at": [0.0, 0.0, 0.0], "up": [0.0, 0.0, 1.0],
                   "fov": 6, "resolution": [16, 16]},
        "render": {"texture_size": 64, "accuracy": 0.05},
    }
    scene = parse_scene(data)
    plan = plan_scene(scene, method="lambert")
    plan = plan.replace("single scattering", single_on, "test")
    # The closed form below spreads M1 by the flat diffusion lobe; with the exit-angle pass the
    # lobe of the rest differs between the two frames (first bounce apart or not).
    plan = plan.replace("exit angle", False, "test: the flat diffusion lobe")
    return render(scene, plan, dtype=jnp.float64).radiance[6:10, 6:10].reshape(-1, 3).mean(0)


def test_single_scattering_pass_is_the_quadrature_of_the_first_bounce_on_a_plane():
    """With the pass on, the frame gains L1 and gives up the Fresnel-lobe radiance of the
    single-scattered exitance M1 (the share it takes from diffusion); both by quadrature here."""
    cos_i = np.cos(LIGHT_THETA)
    view = np.array([0.0, 120.0, 160.0]) / 200.0
    cos_o = view[2]
    phi = 0.0  # light arrives from +y (travels towards -y), the camera sits at +y: same side
    on, off = _plane(True), _plane(False)
    t_dr = external_diffuse_transmittance(ETA)
    for c in range(3):
        L1 = _single_radiance(cos_i, cos_o, phi, SIGMA_A[c], SIGMA_S[c]) * cos_i
        M1 = dblquad(lambda t, p: _single_radiance(cos_i, np.cos(t), p, SIGMA_A[c], SIGMA_S[c])
                     * np.cos(t) * np.sin(t), 0, 2 * np.pi, 0, np.pi / 2, epsabs=1e-11)[0] * cos_i
        lobe = (1 - fresnel_reflectance_numpy(cos_o, ETA)) / (np.pi * t_dr)
        assert on[c] - off[c] == pytest.approx(L1 - M1 * lobe, rel=2e-3, abs=1e-6), c


def test_planner_turns_single_scattering_on_for_low_albedo_and_says_how_much():
    from jsss.render import load_scene

    ketchup = plan_scene(load_scene("examples/ketchup_plane.toml"))
    assert ketchup.on("single scattering")
    assert "% of the light leaving" in ketchup.describe()
    skin = plan_scene(load_scene("examples/skin_backlit.toml"))
    assert not skin.on("single scattering")  # layered: no homogeneous medium to scatter once in


def test_an_index_matched_frame_is_finite_off_the_object_too():
    """eta = 1 (no Fresnel boundary, the index-matched truth of benchmarks/inverse_rendering.py):
    the background pixels, whose normals are zero, graze in and out at once; the frame and its
    gradient must stay finite there (a NaN background had turned a whole fit into NaN)."""
    import jax

    data = {
        "geometry": {"shape": "plane", "width": 40.0},
        "material": {"sigma_a": [0.06, 0.9, 1.4], "sigma_s_prime": [0.18, 0.07, 0.03], "eta": 1.0, "specular": 0.0},
        "lights": [{"type": "point", "position": [5.0, -5.0, 30.0], "intensity": 1000.0}],
        "camera": {"position": [0.0, -70.0, 55.0], "look_at": [0.0, 0.0, 0.0], "fov": 40, "resolution": [24, 18]},
        "render": {"texture_size": 64, "accuracy": 0.05},
    }
    scene = parse_scene(data)
    plan = plan_scene(scene, method="lambert").replace("single scattering", True, "test")
    frame = np.asarray(render(scene, plan, dtype=jnp.float64).radiance)
    assert np.isfinite(frame).all() and (frame[0, 0] == 0).all() and frame.max() > 0

    from fitting.render import _medium, _model_for

    render_fn, model_data = _model_for(scene, plan, jnp.float64, "dipole", 0.0)
    theta = jnp.log(jnp.array([0.06, 0.9, 1.4, 0.18, 0.07, 0.03]))
    grad = jax.grad(lambda t: render_fn(_medium(t, jnp.ones(3)), model_data).sum())(theta)
    assert np.isfinite(np.asarray(grad)).all()
