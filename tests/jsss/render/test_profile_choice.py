"""The profile model a homogeneous medium renders with (jsss.render.profile_choice).

Truth for the predicted errors: adding-doubling (iadpython), which shares nothing with the
dipole or the transport tables. The rest are the rules the scene file promises: ``auto`` by
default, an explicit model obeyed with its predicted error stated, clear reasons where the
tables do not reach.
"""

import dataclasses
import re

import jax
import numpy as np
import pytest

from jsss import Medium, materials
from jsss.diffusion import dipole
from jsss.gaussians.gaussian_sum import GaussianSum
from jsss.render import Material, SceneError, parse_scene, plan_scene
from jsss.render.profile_choice import choose_profile
from jsss.render.profiles import choose_variances, exact_profile, render_profile
from tests.jsss.render.scenes import flat_plane, scene_dict

iadpython = pytest.importorskip("iadpython")


def _adding_doubling_total(medium):
    """Semi-infinite R_d per unit entering flux (normal beam, g = 0 in reduced coefficients)."""
    eta = float(np.asarray(medium.eta).ravel()[0])
    specular = ((eta - 1) / (eta + 1)) ** 2
    out = []
    for albedo in np.asarray(medium.reduced_albedo, float):
        sample = iadpython.Sample(a=float(albedo), b=1000.0, g=0.0, n=eta, n_above=1.0, n_below=1.0, quad_pts=16)
        reflected, _, _, _ = sample.rt()
        out.append((reflected - specular) / (1 - specular))
    return np.array(out)


@pytest.mark.parametrize("name", ["ketchup", "marble", "skin1"])
def test_the_dipoles_predicted_error_is_its_error_against_adding_doubling(name):
    """The dipole's predicted error R_dip / R_tr - 1 equals R_dip / R_ad - 1 within 3 of the
    tables' own stated errors (ketchup's green and blue were +2 % at eta 1.3 and albedo' < 0.1,
    2-2.5 of them, until the tables' early part took that noise out). Auto at 5 % keeps the dipole exactly where the truth's
    error is within a quarter of it (marble, -0.9 to -1.2 %)."""
    medium = materials.material(name)
    choice = choose_profile(medium, target=0.05)
    truth = np.asarray(dipole.total_reflectance(medium)) / _adding_doubling_total(medium) - 1
    np.testing.assert_array_less(np.abs((1 + choice.dipole_error) / (1 + truth) - 1),
                                 3 * choice.transport_error + 1e-3)
    assert choice.requested == "auto"
    assert choice.model == ("dipole" if np.max(np.abs(truth)) <= 0.05 / 4 else "transport")
    expected = choice.dipole_error if choice.model == "dipole" else choice.transport_error
    assert choice.predicted_error == pytest.approx(np.max(np.abs(expected)))


def test_auto_weighs_the_dipole_against_the_scenes_own_target():
    coarse = parse_scene(scene_dict(material={"name": "marble"}, render={"texture_size": 64, "accuracy": 0.05}))
    fine = parse_scene(scene_dict(material={"name": "marble"}, render={"texture_size": 64, "accuracy": 0.01}))
    assert coarse.material.profile_model == "dipole" and fine.material.profile_model == "transport"
    assert fine.material.profile.target == 0.01
    assert "> a quarter of the target (0.25 %)" in plan_scene(fine).describe()


def _stated_dipole_errors(text):
    """The three relative errors a plan prints for the dipole's R_d (R / G / B)."""
    found = re.search(r"the dipole's R_d is ([+-][\d.]+) / ([+-][\d.]+) / ([+-][\d.]+) % off the transport "
                      r"truth's \(R / G / B\)", text)
    assert found, text
    return np.array([float(x) for x in found.groups()]) / 100


def _ketchups_dipole_error():
    """Ketchup's dipole R_d against adding-doubling, with nothing of the tables: +10.9 / +17.6 / +17.2 %."""
    medium = materials.material("ketchup")
    return np.asarray(dipole.total_reflectance(medium)) / _adding_doubling_total(medium) - 1


def test_a_scene_defaults_to_auto_and_the_plan_says_why():
    """The plan names the profile, why, and the dipole's error it weighed: the printed numbers are
    the truth's within 0.3 % (the tables' own error at ketchup's albedos is below 0.15 %; the
    print rounds to 0.1 %)."""
    scene = parse_scene(scene_dict(material={"name": "ketchup"}))
    assert scene.material.profile_model == "transport"
    text = plan_scene(scene).describe()
    assert "profile: transport -- auto: the dipole's R_d is " in text
    assert "off the transport truth's (R / G / B), > a quarter of the target (2.5 %)" in text
    np.testing.assert_allclose(_stated_dipole_errors(text), _ketchups_dipole_error(), atol=3e-3)


def test_an_explicit_dipole_is_obeyed_and_its_error_stated():
    scene = parse_scene(scene_dict(material={"name": "ketchup", "profile": "dipole"}))
    assert scene.material.profile_model == "dipole"
    line = plan_scene(scene).profile.describe()
    assert line.startswith("profile: dipole -- set by the scene; predicted error: the dipole's R_d is ")
    np.testing.assert_allclose(_stated_dipole_errors(line), _ketchups_dipole_error(), atol=3e-3)
    assert 'profile = "transport" removes it' in line


def test_media_the_tables_do_not_cover_fall_back_to_the_dipole_with_the_reason():
    dense = parse_scene(scene_dict(material={"sigma_a": [0.01] * 3, "sigma_s_prime": [1.0] * 3, "eta": 1.8}))
    assert dense.material.profile_model == "dipole"
    assert "transport tables cover eta 1.0-1.6" in dense.material.profile.why
    untabulated_g = parse_scene(scene_dict(material={"name": "marble", "g": 0.3}))
    assert untabulated_g.material.profile_model == "dipole"
    assert "g in (0.0, 0.5, 0.8, 0.9)" in untabulated_g.material.profile.why
    with pytest.raises(SceneError, match=r"\[material\] profile: transport tables cover eta"):
        parse_scene(scene_dict(material={"sigma_a": [0.01] * 3, "sigma_s_prime": [1.0] * 3, "eta": 1.8,
                                         "profile": "transport"}))
    with pytest.raises(SceneError, match="profile"):
        parse_scene(scene_dict(material={"name": "marble", "profile": "diffusion"}))


def test_replacing_the_medium_chooses_again_and_a_replaced_model_is_a_new_request():
    ketchup = Material("k", np.full(3, 1.3), medium=materials.material("ketchup"))  # auto at 5 %
    assert ketchup.profile_model == "transport"
    dense = dataclasses.replace(ketchup, medium=Medium([0.01] * 3, [1.0] * 3, 1.8))
    assert dense.profile_model == "dipole" and dense.profile.requested == "auto"
    back = dataclasses.replace(dense, medium=materials.material("ketchup"))
    assert back.profile_model == "transport"
    forced = dataclasses.replace(ketchup, profile_model="dipole")
    assert forced.profile_model == "dipole" and forced.profile.requested == "dipole"
    given = Material("given", np.full(3, 1.4), gaussians=GaussianSum(np.ones((1, 3)), np.ones(1)))
    assert given.profile is None and given.profile_model == "auto"


def test_auto_needs_concrete_numbers_under_jit():
    medium = materials.material("marble")

    def total(sigma_a, model):
        m = Material("m", np.full(3, 1.5), medium=Medium(sigma_a, medium.sigma_s_prime, medium.eta),
                     profile_model=model)
        return m.medium.sigma_a.sum()

    assert np.isfinite(jax.jit(lambda s: total(s, "transport"))(medium.sigma_a))
    with pytest.raises(ValueError, match="traced"):
        jax.jit(lambda s: total(s, "auto"))(medium.sigma_a)


def test_the_transport_profiles_gaussians_place_its_flux_beyond_a_pixel():
    """Ketchup's transport profile rises like 1/r at the source (single scattering), which a
    sum of Gaussians fits poorly in d'Eon's RMS error (weight r R^2): the planner measures it
    from half a pixel out (inside, the camera sees only the flux, which the fit keeps) and
    still reports it unreached -- 15 % against 34 % over every radius. What the camera sees is
    checked another way: the flux inside each radius from one pixel out, exact profile against
    the plan's Gaussians, is misplaced by less than the profile's half of the target (measured
    0.3 / 2.2 / 0.9 %)."""
    scene = parse_scene(flat_plane({"name": "ketchup"}))
    plan = plan_scene(scene, method="texture-space")
    material = scene.material
    assert material.profile_model == "transport"
    everywhere = choose_variances(material, scene.accuracy / 2)[1]
    assert plan.profile_error < everywhere
    assert "target not reachable" in plan.describe()
    gs = render_profile(material, plan.variances)
    r = np.geomspace(1e-5, 400, 20000)
    exact = exact_profile(material, r)
    dr = np.gradient(r)[:, None]
    exact_inside = np.cumsum(2 * np.pi * r[:, None] * exact * dr, axis=0)
    v, w = np.asarray(gs.variances), np.asarray(gs.weights)
    fitted_inside = (w[None] * (1 - np.exp(-r[:, None, None] ** 2 / (2 * v[None, :, None])))).sum(1)
    outside = r >= plan.pixel_size
    misplaced = np.max(np.abs(fitted_inside[outside] - exact_inside[outside]) / exact_inside[-1], axis=0)
    assert np.all(misplaced < scene.accuracy / 2), misplaced


def test_a_pinned_model_survives_a_new_medium_and_auto_follows_the_plans_target():
    """Review findings: ``replace(..., profile=None)`` pins a model even when auto had chosen
    the same one; a concrete material built inside someone's jit works; ``with_accuracy``
    chooses again, ``plan_scene(accuracy=...)`` says that it did not."""
    marble = parse_scene(scene_dict(material={"name": "marble"}))
    assert marble.material.profile_model == "dipole"
    pinned = dataclasses.replace(marble.material, medium=materials.material("ketchup"), profile_model="dipole",
                                 profile=None)
    assert pinned.profile_model == "dipole" and pinned.profile.requested == "dipole"
    medium = materials.material("marble")
    built = jax.jit(lambda x: (Material("m", np.full(3, 1.5), medium=medium, profile_model="dipole"), x)[1])(1.0)
    assert built == 1.0
    assert marble.with_accuracy(0.01).material.profile_model == "transport"
    with pytest.warns(UserWarning, match="would take transport"):
        plan = plan_scene(marble, accuracy=0.01)
    assert plan.profile.model == "dipole" and "at this plan's 1 % auto would take transport" in plan.profile.why


def test_submodules_stay_attributes_of_the_lazy_packages():
    import jsss
    from jsss import render

    assert jsss.medium.Medium is Medium and render.scene.Material is Material
    assert callable(render.linear_frame)


def test_auto_checks_a_parameter_maps_texels_not_only_its_base():
    """A marble base with a checker of an absorbing medium (examples/checker_plane.toml's): the
    base alone keeps the dipole, but at the absorbing texels the dipole's R_d is 3-23 % off, as
    adding-doubling confirms, so auto takes the tables and says why. A map of marble's own
    values keeps the dipole; an artist's map keeps the base's choice (its coefficients were
    converted with that model)."""
    from jsss.render.surface_maps import SurfaceMaps

    marble = materials.material("marble")
    absorbing = Medium(np.array([0.06, 0.25, 0.4]), np.asarray(marble.sigma_s_prime), marble.eta)
    truth = np.asarray(dipole.total_reflectance(absorbing)) / _adding_doubling_total(absorbing) - 1
    assert np.max(np.abs(truth)) > 0.05  # the absorbing texels really are beyond a quarter of 5 %
    checker = (np.indices((8, 8)).sum(0) % 2).astype(bool)[..., None]
    sigma_a = np.where(checker, np.asarray(absorbing.sigma_a), np.asarray(marble.sigma_a))
    sigma_s = np.broadcast_to(np.asarray(marble.sigma_s_prime), sigma_a.shape)

    def built(files, a=sigma_a):
        maps = SurfaceMaps(sigma_a=a, sigma_s_prime=sigma_s, files=files)
        return Material("m", np.broadcast_to(np.asarray(marble.eta, float), (3,)).copy(), medium=marble, maps=maps)

    textured = built((("sigma_a", "checker.exr"),))
    assert textured.profile_model == "transport"
    assert "over the parameter map's texels" in textured.profile.why
    worst = float(textured.profile.why.split("up to ")[1].split(" %")[0]) / 100
    assert worst == pytest.approx(np.max(np.abs(truth)), rel=0.15)  # the predicted worst texel, against the truth
    uniform = built((("sigma_a", "marble.exr"),), a=np.broadcast_to(np.asarray(marble.sigma_a), sigma_a.shape))
    assert uniform.profile_model == "dipole" and "over the parameter map" in uniform.profile.why
    assert built((("diffuse_reflectance", "painted.exr"),)).profile_model == "dipole"


def test_render_profile_with_numbers_is_the_traced_fit_and_a_singular_basis_stays_nan():
    """With numbers the weights are solved in NumPy (no LAPACK program at a command's start):
    equal to the jitted solve a fit traces, to float64 rounding; two equal variances make the
    system singular, which gives NaN weights as the jitted solve does, not an exception."""
    material = Material("marble", np.ones(3), medium=materials.jensen2001("marble"))
    variances = np.array([0.01, 0.1, 1.0, 10.0])
    concrete = render_profile(material, variances)
    radii = concrete_radii(material)
    traced = jax.jit(lambda medium: render_profile(material, variances, radii=radii, medium=medium).weights)(
        material.medium)
    np.testing.assert_allclose(np.asarray(concrete.weights), np.asarray(traced), rtol=1e-9, atol=1e-12)
    singular = render_profile(material, np.array([0.1, 0.1, 1.0]))
    assert np.isnan(np.asarray(singular.weights)).any() or np.isinf(np.asarray(singular.weights)).any()


def concrete_radii(material):
    from jsss.render.profiles import full_profile, profile_radii

    return np.asarray(profile_radii(full_profile(material)))
