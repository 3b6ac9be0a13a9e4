"""Warm frames: a second render() neither rasterizes nor compiles again, yet gives the frame a
cold render of the same scene gives; moving a light, the camera or the mesh is seen."""

import dataclasses

import jax
import jax.monitoring
import jax.numpy as jnp
import numpy as np
import pytest

from jsss.medium import Medium
from jsss.render import (
    frame_program,
    memory,
    parse_scene,
    plan_scene,
    prepare_renderer,
    programs,
    render,
    render_image,
    render_params,
)
from tests.jsss.render.scenes import scene_dict

_compiles: list = []
_counting = [False]


def _listener(name, seconds, **_):
    if _counting[0] and name == "/jax/core/compile/backend_compile_duration":
        _compiles.append(seconds)


jax.monitoring.register_event_duration_secs_listener(_listener)


def _compiled(fn):
    """(result of fn(), XLA compilations it ran)."""
    _compiles.clear()
    _counting[0] = True
    try:
        out = fn()
    finally:
        _counting[0] = False
    return out, len(_compiles)


def _cold(scene, plan):
    """The frame of a process that never rendered: kept geometry and programs dropped."""
    memory.forget()
    frame_program.cache_clear()
    programs.frame.cache_clear()
    return render(scene, plan, dtype=jnp.float32).radiance


def _scene(**changes):
    base = {"lights": [{"type": "point", "position": [30.0, -60.0, 50.0], "intensity": 2000.0}],
            "render": {"texture_size": 32, "accuracy": 0.1},
            "camera": {"position": [0.0, -110.0, 30.0], "fov": 28, "resolution": [24, 18]}}
    return parse_scene(scene_dict(**(base | changes)))


@pytest.fixture(scope="module")
def texture_plan():
    scene = _scene()
    return scene, plan_scene(scene, method="texture-space")


def _with_intensity(scene, intensity):
    return dataclasses.replace(scene, lights=tuple(dataclasses.replace(l, intensity=intensity) for l in scene.lights))


def test_a_brighter_light_neither_rasterizes_nor_compiles(texture_plan):
    """The second frame with the light twice as bright runs no XLA compilation, reads the same
    kept texels and shadow maps, and is exactly twice the first (images are linear in the
    intensity; float32's rounding of a doubling is exact)."""
    scene, plan = texture_plan
    first = render(scene, plan, dtype=jnp.float32)
    brighter, compiles = _compiled(lambda: render(_with_intensity(scene, 4000.0), plan, dtype=jnp.float32))
    assert compiles == 0
    assert brighter.prepared.texels is first.prepared.texels
    assert brighter.prepared.texel_lights[0] is first.prepared.texel_lights[0]
    np.testing.assert_array_equal(brighter.radiance, 2 * first.radiance)


def test_a_warm_frame_is_the_cold_frame_and_the_constant_geometry_frame(texture_plan):
    """A warm frame (geometry kept, program reused) equals, bit for bit, the frame of a process
    that never rendered, and to float32 rounding the frame with the geometry compiled in as
    constants (what render() ran before frames were kept)."""
    scene, plan = texture_plan
    warm = render(scene, plan, dtype=jnp.float32).radiance
    warm = render(scene, plan, dtype=jnp.float32).radiance
    cold = _cold(scene, plan)
    np.testing.assert_array_equal(warm, cold)
    params = render_params(scene, plan, dtype=jnp.float32)
    prepared = plan.method_config.prepare(scene, plan, params)
    constants = np.asarray(jax.jit(lambda p: render_image(p, prepared, plan))(params))
    np.testing.assert_allclose(warm, constants, rtol=2e-5, atol=1e-6 * float(np.max(constants)))


@pytest.mark.parametrize("change", ["light", "camera", "mesh"])
def test_moved_geometry_is_rendered_anew(texture_plan, change):
    """With the light moved, the camera turned or the sphere shrunk, the kept geometry is not
    reused: the frame differs from the first and equals a cold render of the changed scene.
    A light or camera moved keeps the layout, so its frame compiles nothing."""
    scene, plan = texture_plan
    first = render(scene, plan, dtype=jnp.float32).radiance
    if change == "light":
        changed = _scene(lights=[{"type": "point", "position": [-40.0, -50.0, 40.0], "intensity": 2000.0}])
    elif change == "camera":
        changed = _scene(camera={"position": [20.0, -105.0, 40.0], "fov": 28, "resolution": [24, 18]})
    else:
        changed = _scene(geometry={"shape": "sphere", "radius": 17.0, "segments": 48, "rings": 24})
    moved, compiles = _compiled(lambda: render(changed, plan, dtype=jnp.float32).radiance)
    if change != "mesh":
        assert compiles == 0
    assert np.max(np.abs(moved - first)) > 0.05 * np.max(first)
    np.testing.assert_array_equal(moved, _cold(changed, plan))


def _darker(material):
    m = material.medium
    return dataclasses.replace(material, medium=Medium(1.5 * np.asarray(m.sigma_a), m.sigma_s_prime, m.eta))


@pytest.mark.parametrize("method", ["texture-space", "normal-filtering"])
def test_the_prepared_renderer_is_render(texture_plan, method):
    """prepare_renderer's frames with another intensity and another material are render()'s of
    the scene changed so, with the same plan (normal filtering prepares again: its normals are
    filtered by the material's profile)."""
    scene, plan = texture_plan
    if method != "texture-space":
        plan = plan_scene(scene, method=method)
    renderer = prepare_renderer(scene, plan)
    np.testing.assert_allclose(renderer(), render(scene, plan).radiance, rtol=1e-6, atol=0)
    brighter, compiles = _compiled(lambda: renderer(light_intensities=[500.0]))
    assert compiles == 0
    np.testing.assert_allclose(brighter, render(_with_intensity(scene, 500.0), plan).radiance, rtol=1e-6, atol=0)
    darker = _darker(scene.material)
    expected = render(dataclasses.replace(scene, material=darker), plan).radiance
    np.testing.assert_allclose(renderer(material=darker), expected, rtol=1e-6, atol=0)
    assert not np.allclose(expected, renderer())  # the material did change the frame
    np.testing.assert_allclose(renderer.render(dataclasses.replace(scene, material=darker)).radiance, expected,
                               rtol=1e-6, atol=0)


def test_the_prepared_renderer_refuses_what_it_cannot_render(texture_plan):
    """Bad intensities and a scene with the light moved are refused, naming the argument."""
    scene, plan = texture_plan
    renderer = prepare_renderer(scene, plan)
    with pytest.raises(ValueError, match="light_intensities"):
        renderer(light_intensities=[1.0, 2.0])
    with pytest.raises(ValueError, match="light_intensities"):
        renderer(light_intensities=[-1.0])
    moved = _scene(lights=[{"type": "point", "position": [-40.0, -50.0, 40.0], "intensity": 2000.0}])
    with pytest.raises(ValueError, match="lights' kinds and positions"):
        renderer.render(moved)
    with pytest.raises(dataclasses.FrozenInstanceError):
        renderer.plan = plan


def test_kept_geometry_is_bounded_and_read_only(texture_plan, monkeypatch):
    """Past the byte budget the least recently used pieces go (the newest stays); kept arrays
    cannot be written."""
    scene, plan = texture_plan
    result = render(scene, plan, dtype=jnp.float32)
    with pytest.raises(ValueError):
        result.prepared.texels.position[0, 0, 0] = 1.0
    monkeypatch.setattr(memory, "KEPT_BYTES", 1)
    memory.kept("test", 1, lambda: np.zeros(10))
    assert memory.kept_bytes() == 80


def test_the_prepared_renderer_warns_when_a_material_chooses_another_profile_model(texture_plan):
    """Marble's plan is made for the dipole (auto at 10 %); ketchup's medium, left at auto, takes the
    transport tables, whose profile the plan's Gaussians were not chosen for: the call warns and
    names how to keep the plan's model, and a material pinned to it renders without a warning."""
    import warnings

    from jsss.materials import material as named

    scene, plan = texture_plan
    assert plan.profile.model == "dipole"
    renderer = prepare_renderer(scene, plan)
    ketchup = named("ketchup")
    switched = dataclasses.replace(scene.material, medium=ketchup)
    assert switched.profile_model == "transport"
    with pytest.warns(UserWarning, match="profile_model='dipole'"):
        renderer(material=switched)
    pinned = dataclasses.replace(scene.material, medium=ketchup, profile_model="dipole", profile=None)
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        renderer(material=pinned)
