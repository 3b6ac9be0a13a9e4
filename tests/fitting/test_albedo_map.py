"""A colour (albedo) map and the mean free path from a photo (fitting.albedo_map).

The photos are jsss's own renders of a plane with a known checker colour map (pre-post
texturing) plus Gaussian noise of a known level: these tests check the fit -- recovery within
its stated errors, the errors themselves against the exact (J^T J)^-1, bad input -- not the
renderer's physics (benchmarks/ compare it with a path tracer).
"""

import dataclasses
import tomllib

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from fitting.albedo_map import AlbedoMapError, fit_albedo_map, without_legs
from jsss.render import Pass, parse_scene, plan_scene, render
from jsss.render.surface_maps import SurfaceMaps

SCENE = """
[geometry]
shape = "plane"
width = 20.0

[material]
sigma_a = [0.05, 0.1, 0.2]
sigma_s_prime = [1.5, 1.8, 2.0]
eta = 1.4
roughness = 0.3

[[lights]]
type = "directional"
direction = [-1.0, 0.2, -0.8]
intensity = 2.0

[camera]
position = [0.0, -20.0, 28.0]
look_at = [0.0, 0.0, 0.0]
fov = 40
resolution = [64, 48]

[render]
texture_size = 64
"""
MAP = 16  # texels per side of the fitted map: about two fitted pixels per texel
GAIN = 2.0
NOISE = 0.01


def _checker(size):
    rows, cols = np.indices((size, size))
    check = ((rows * 4 // size + cols * 4 // size) % 2)[..., None]
    return np.where(check, [0.9, 0.6, 0.3], [0.4, 0.7, 0.8])


@pytest.fixture(scope="module")
def problem():
    """The scene (material without its map), the true map, a photo (with fireflies), its noise and the true mfp."""
    scene = parse_scene(tomllib.loads(SCENE), source="plane.toml")
    truth = _checker(MAP)
    textured = dataclasses.replace(scene, material=dataclasses.replace(scene.material,
                                                                       maps=SurfaceMaps(albedo=truth)))
    # the passes the fit models
    plan = without_legs(plan_scene(textured, accuracy=0.001, method="texture-space"))
    clean = np.asarray(render(textured, plan, dtype=jnp.float64).radiance)
    sigma = NOISE * np.maximum(clean, 0.01 * clean.max())
    rng = np.random.default_rng(1)
    photo = GAIN * (clean + sigma * rng.standard_normal(clean.shape))
    # A path tracer's fireflies: 0.5 % of the pixels at 3x their value (hundreds of errors off),
    # which the default Huber loss must keep from steering their texels
    fireflies = rng.random(clean.shape[:2]) < 0.005
    photo[fireflies] *= 3.0
    medium = scene.material.medium
    mfp = 1.0 / (np.asarray(medium.sigma_a) + np.asarray(medium.sigma_s_prime))
    return scene, truth, photo, GAIN * sigma, mfp


@pytest.fixture(scope="module")
def fits(problem):
    """One fit with the probed error map and one with the exact one. The mean free path starts at
    the truth, which keeps each fit to one compilation (a start far off re-plans the Gaussians):
    the map starts from the photo's own ratio to a white render, and the fit moves the mean
    free path within its errors."""
    scene, _, photo, sigma, mfp = problem
    common = dict(gain=GAIN, sigma=sigma, map_size=MAP, init_mean_free_path=mfp, model_error=0)  # jsss's own photo
    return (fit_albedo_map(scene, photo, errors="probe", **common),
            fit_albedo_map(scene, photo, errors="exact", **common))


def test_map_recovered_within_its_errors(problem, fits):
    """Every well-seen texel within 4 stated errors of the truth (about 750 values: 4 sigma is
    exceeded by chance with probability 0.05), and the errors neither too wide nor too narrow,
    with the photo's fireflies in the fit (the default Huber loss; chi^2/dof from the median
    square, so that the fireflies do not widen every error)."""
    _, truth, _, _, _ = problem
    fit = fits[0]
    assert fit.converged
    assert fit.seen.sum() >= 200  # most of the plane is in view
    z = ((fit.albedo - truth) / fit.albedo_err)[fit.seen]
    assert np.all(np.abs(z) < 4), np.abs(z).max()
    assert 0.7 <= np.sqrt(np.mean(z**2)) <= 1.4
    assert 0.7 <= fit.chi2_reduced <= 1.4


def test_unseen_texels_are_flagged_not_invented(fits):
    """Texels the camera does not look up keep the start and get an infinite error; no NaN anywhere."""
    fit = fits[0]
    assert (~fit.seen).any()
    assert np.all(np.isinf(fit.albedo_err[~fit.seen]))
    assert np.all(np.isfinite(fit.albedo)) and np.all(np.isfinite(fit.albedo_err[fit.seen]))


def test_probed_errors_match_the_exact_inverse(fits):
    """The probing estimate of diag (J^T J)^-1 against the inverse of J^T J formed from the full
    Jacobian, on the same problem: within 15 % per texel on the median, 40 % at worst (one
    random-sign probe per colour: its scatter is the inverse's entries between texels four apart)."""
    probe, exact = fits
    seen = probe.seen
    ratio = probe.albedo_err[seen] / exact.albedo_err[seen]
    assert np.median(np.abs(ratio - 1)) < 0.15
    assert np.all(np.abs(ratio - 1) < 0.4), ratio
    assert np.allclose(probe.mean_free_path_err, exact.mean_free_path_err, rtol=0.05)


def test_mean_free_path_within_its_errors(problem, fits):
    _, _, _, _, mfp = problem
    fit = fits[1]
    assert np.all(np.isfinite(fit.mean_free_path_err)) and np.all(fit.mean_free_path_err > 0)
    assert np.all(np.abs(fit.mean_free_path - mfp) < 3 * fit.mean_free_path_err), (fit.mean_free_path, mfp)


def test_a_channels_light_scaled_moves_its_map_alone_and_the_model_error_widens_it():
    """The model error's meaning: a photo whose channels' subsurface light is scaled by 1 + eps is
    drawn exactly by the map scaled by 1 + eps at the same mean free path (the frame is linear
    in c), so the renderer's relative error in a channel's light is one more error shared by
    that channel's texels, added in quadrature (relative), and none on the mean free path."""
    scene = parse_scene(tomllib.loads(SMALL), source="plane.toml")
    painted = dataclasses.replace(scene, material=dataclasses.replace(scene.material, maps=SurfaceMaps(albedo=_checker(4))))
    plan = without_legs(plan_scene(painted, accuracy=0.001, method="texture-space"))
    plan = plan.replace(Pass.SPECULAR, False, "subsurface light only: the model error is the subsurface light's")
    clean = np.asarray(render(painted, plan, dtype=jnp.float64).radiance)
    options = {"gain": 1.0, "noise": 0.01, "map_size": 4, "specular": False}
    eps = np.array([0.1, 0.0, -0.1])
    plain = fit_albedo_map(scene, clean, model_error=0.0, **options)
    scaled = fit_albedo_map(scene, clean * (1 + eps), model_error=0.02, **options)
    seen = plain.seen
    assert plain.converged and scaled.converged and seen.sum() >= 8
    assert np.allclose(scaled.albedo[seen], plain.albedo[seen] * (1 + eps), rtol=2e-3)
    assert np.allclose(scaled.mean_free_path, plain.mean_free_path, rtol=2e-3)
    # the photo's relative noise scales with it: the same relative errors, and 2 % in quadrature
    plain_rel, scaled_rel = (f.albedo_err[seen] / f.albedo[seen] for f in (plain, scaled))
    assert np.allclose(scaled_rel**2, plain_rel**2 + 0.02**2, rtol=0.02)
    assert np.allclose(scaled.mean_free_path_err, plain.mean_free_path_err, rtol=0.02)
    assert scaled.model_error == 0.02 and any("renderer's own" in line for line in scaled.history)
    with pytest.raises(AlbedoMapError, match=r"model_error must be a relative error in \[0, 1\)"):
        fit_albedo_map(scene, clean, model_error=1.0, **options)


@pytest.mark.parametrize("dtype", [jnp.float64, jnp.float32])
def test_the_fits_conjugate_gradients_are_lineaxs_without_restarts(dtype):
    """fitting.albedo_map's CG loop against lineax.CG(stabilise_every=None) on a random symmetric
    positive definite system given as a pytree: the same iterates, step count and solution."""
    import lineax as lx
    import optimistix as optx

    from fitting.albedo_map import _conjugate_gradients

    rng = np.random.default_rng(0)
    m = rng.standard_normal((60, 60))
    a = jnp.asarray(m @ m.T + 60 * np.eye(60) * np.linspace(0.01, 1, 60), dtype)
    b = {"u": jnp.asarray(rng.standard_normal(57), dtype), "ell": jnp.asarray(rng.standard_normal(3), dtype)}
    def flat(t):
        return jnp.concatenate([t["u"], t["ell"]])

    def mv(t):
        y = a @ flat(t)
        return {"u": y[:57], "ell": y[57:]}

    atol = 1e-6 * float(jnp.linalg.norm(flat(b)))
    ours, steps, ok = _conjugate_gradients(mv, b, atol, 500)
    operator = lx.FunctionLinearOperator(mv, jax.eval_shape(lambda: b), tags=lx.positive_semidefinite_tag)
    theirs = lx.linear_solve(operator, b, lx.CG(rtol=0.0, atol=atol, norm=optx.two_norm, stabilise_every=None,
                                                max_steps=500), throw=False)
    assert bool(ok) and int(steps) == int(theirs.stats["num_steps"]) > 10
    assert np.allclose(flat(ours), flat(theirs.value), rtol=0, atol=1e-12 if dtype == jnp.float64 else 1e-5)


def test_bad_input_names_the_value_and_the_fix(problem):
    scene, _, photo, sigma, _ = problem
    with pytest.raises(AlbedoMapError, match="gain: the photo's exposure is required"):
        fit_albedo_map(scene, photo)
    with pytest.raises(AlbedoMapError, match="one direction with the map's scale"):
        fit_albedo_map(scene, photo, gain="fit")
    with pytest.raises(ValueError, match="set \\[camera\\] resolution"):
        fit_albedo_map(scene, photo[:-1], gain=GAIN)
    with pytest.raises(AlbedoMapError, match="map_size must be an integer from 2"):
        fit_albedo_map(scene, photo, gain=GAIN, sigma=sigma, map_size=1)
    with pytest.raises(AlbedoMapError, match="errors must be"):
        fit_albedo_map(scene, photo, gain=GAIN, errors="hutchinson")


SMALL = SCENE.replace("resolution = [64, 48]", "resolution = [40, 30]").replace("texture_size = 64",
                                                                                 "texture_size = 32")


def test_the_command_writes_a_map_that_renders_the_photo(tmp_path, capsys):
    """``jsss-render fit --albedo-map``: the .fit.toml it writes names the fitted map, and rendered
    as it is, it reproduces the photo within the photo's noise. A map written upside down or
    transposed would put the checker's colours on the wrong squares (tens of % off)."""
    import json

    from jsss.render import load_scene
    from measure import export
    from measure.commands import render as render_command
    from measure.exr import read_exr, write_exr

    (tmp_path / "plane.toml").write_text(SMALL)
    scene = parse_scene(tomllib.loads(SMALL), source="plane.toml")
    rows, cols = np.indices((8, 8))
    truth = np.where(((rows // 4 + cols // 2) % 2)[..., None], [0.9, 0.6, 0.3], [0.4, 0.7, 0.8])  # not symmetric
    painted = dataclasses.replace(scene, material=dataclasses.replace(scene.material, maps=SurfaceMaps(albedo=truth)))
    plan = without_legs(plan_scene(painted, accuracy=0.001, method="texture-space"))  # the passes the fit models
    clean = np.asarray(render(painted, plan, dtype=jnp.float64).radiance)
    photo = clean * (1 + 0.01 * np.random.default_rng(3).standard_normal(clean.shape))
    write_exr(tmp_path / "photo.exr", photo.astype(np.float32))
    status = render_command.main(["fit", str(tmp_path / "plane.toml"), str(tmp_path / "photo.exr"), "-o", str(tmp_path),
                                  "--no-gain", "--albedo-map", "8", "--noise", "0.01", "-q", "--json", "--model-error", "0",
                                  "--export", "mitsuba", "--export", "blender"])
    summary = json.loads(capsys.readouterr().out)
    assert status == 0 and summary["converged"] and summary["texels_seen"] >= 40 and summary["model_error"] == 0
    assert {p.name for p in tmp_path.iterdir()} >= {"photo.albedo.exr", "photo.albedo_err.exr", "photo.fit.toml",
                                                    "photo.fit.json", "photo.fit.png", "photo.fit_mitsuba.xml",
                                                    "photo.fit_mitsuba_transmittance.exr", "photo.fit_blender.py",
                                                    "photo.fit_blender_colour.exr"}
    # The exports' textures are the fitted map in its file's layout: sqrt(c) for Mitsuba, Cycles'
    # colour of c R_d for Blender, each naming its file
    fitted_map = read_exr(tmp_path / "photo.albedo.exr").pixels
    transmittance = read_exr(tmp_path / "photo.fit_mitsuba_transmittance.exr").pixels
    assert np.allclose(transmittance ** 2, fitted_map, rtol=1e-6)
    medium = load_scene(tmp_path / "photo.fit.toml").material.medium
    colour = read_exr(tmp_path / "photo.fit_blender_colour.exr").pixels
    assert np.allclose(colour, export.blender_colour_map(medium, fitted_map.astype(float)), rtol=1e-6, atol=1e-7)
    assert 'value="photo.fit_mitsuba_transmittance.exr"' in (tmp_path / "photo.fit_mitsuba.xml").read_text()
    assert "'photo.fit_blender_colour.exr'" in (tmp_path / "photo.fit_blender.py").read_text()
    fitted = load_scene(tmp_path / "photo.fit.toml")
    assert fitted.material.maps.colour is not None
    again = np.asarray(render(fitted, without_legs(plan_scene(fitted, accuracy=0.001, method="texture-space")),
                              dtype=jnp.float64).radiance)
    lit = clean > 0.05 * clean.max()
    # The fit's pixels, not the silhouette's: within 3 % (the noise is 1 % per pixel, each texel
    # is seen by a few pixels); a flipped map is 30-50 % off on the checker's squares
    assert np.median(np.abs(again / np.where(lit, clean, 1) - 1)[lit]) < 0.01
    assert np.percentile(np.abs(again / np.where(lit, clean, 1) - 1)[lit], 90) < 0.03


@pytest.mark.parametrize("flags, named", [(["--fit-gain"], "--fit-gain does not go with --albedo-map"),
                                          (["--no-gain", "--highlight", "mask"], "--highlight mask does not go"),
                                          (["--no-gain", "--method", "lambert"], "--method lambert does not go"),
                                          (["--no-gain", "--albedo-map", "1"], "--albedo-map must be 'auto'"),
                                          (["--no-gain", "--export", "pbrt"], "--export pbrt does not go with")])
def test_the_command_names_a_flag_the_map_fit_cannot_take(tmp_path, capsys, flags, named):
    from measure.commands import render as render_command
    from measure.exr import write_exr

    (tmp_path / "plane.toml").write_text(SMALL)
    write_exr(tmp_path / "photo.exr", np.ones((30, 40, 3), np.float32))
    argv = ["fit", str(tmp_path / "plane.toml"), str(tmp_path / "photo.exr"), "-o", str(tmp_path), "-q"]
    argv += flags if "--albedo-map" in flags else flags + ["--albedo-map"]
    assert render_command.main(argv) == 2
    err = capsys.readouterr().err
    assert named in err and len(err.strip().splitlines()) == 1 and "Traceback" not in err


def test_a_second_fit_of_the_same_scene_compiles_none_of_the_fits_programs(caplog):
    """The fit's programs (residuals, images, diagonal, solves) are kept per structure, with the
    geometry's arrays as arguments: a second photo of the same scene traces and compiles none of
    them again (they had been closures per fit: 22 s of a 66 s fit recompiled every call). The
    options are this test's own (cg_max_steps), so that the first call must compile them."""
    import logging

    import jax

    scene = parse_scene(tomllib.loads(SMALL), source="plane.toml")
    painted = dataclasses.replace(scene, material=dataclasses.replace(scene.material, maps=SurfaceMaps(albedo=_checker(4))))
    clean = np.asarray(render(painted, without_legs(plan_scene(painted, accuracy=0.001, method="texture-space")),
                              dtype=jnp.float64).radiance)
    options = {"gain": 1.0, "noise": 0.01, "map_size": 4, "errors": "none", "replans": 0, "max_steps": 2,
               "cg_max_steps": 77}
    compiled = []
    for seed in (3, 4):
        photo = clean * (1 + 0.01 * np.random.default_rng(seed).standard_normal(clean.shape))
        caplog.clear()
        with jax.log_compiles(True), caplog.at_level(logging.WARNING, logger="jax"):
            fit = fit_albedo_map(scene, photo, **options)
        assert np.all(np.isfinite(fit.albedo))
        compiled.append({m.split("jit(")[1].split(")")[0] for m in (r.getMessage() for r in caplog.records)
                         if m.startswith("Compiling jit(")})
    programs = {"raw_residuals", "_images", "_diagonal", "_solve"}
    assert programs <= compiled[0], compiled[0]
    assert not programs & compiled[1], compiled[1]
