"""The planner turns passes on and off from measurable properties of the scene."""

import numpy as np

from jsss.render import parse_scene, plan_scene
from jsss.render.profiles import reduction_error
from tests.jsss.render.scenes import flat_plane, scene_dict


def test_close_marble_sphere_needs_diffusion_and_stretch_correction():
    plan = plan_scene(parse_scene(scene_dict()))
    assert plan.on("diffusion") and plan.on("stretch correction")
    assert not plan.on("layered profile")
    assert "RMS radius" in next(d.why for d in plan.decisions if d.name == "diffusion")


def test_far_away_object_is_shaded_lambert():
    scene = parse_scene(scene_dict(camera={"position": [0.0, -2.0e5, 0.0], "fov": 28, "resolution": [48, 36]}))
    plan = plan_scene(scene)
    assert not plan.on("diffusion") and not plan.on("stretch correction")
    why = next(d.why for d in plan.decisions if d.name == "diffusion")
    assert "Lambert" in why and "pixel footprint" in why
    assert plan.pixel_size > 4.0  # mm: wider than marble's profile


def test_plane_has_no_stretch_correction_and_no_translucent_shadows():
    plan = plan_scene(parse_scene(flat_plane({"name": "marble"})))
    assert plan.on("diffusion")
    assert not plan.on("stretch correction") and not plan.on("translucent shadow maps")


def test_thin_fin_lit_from_behind_uses_translucent_shadow_maps_thick_sphere_does_not():
    fin = scene_dict(geometry={"shape": "fin", "thickness": 1.0, "segments": 16}, material={"name": "skin1"},
                     lights=[{"type": "directional", "direction": [-1.0, 0.0, 0.0]}],
                     camera={"position": [-100.0, 0.0, 0.0], "fov": 30, "resolution": [32, 32]})
    assert plan_scene(parse_scene(fin)).on("translucent shadow maps")
    ball = scene_dict(geometry={"shape": "sphere", "radius": 40.0}, material={"name": "ketchup"})
    plan = plan_scene(parse_scene(ball))
    assert not plan.on("translucent shadow maps")
    assert "thinnest part light cuts through" in next(d.why for d in plan.decisions if d.name == "translucent shadow maps")


def test_layered_profile_only_for_layered_materials():
    assert plan_scene(parse_scene(scene_dict(material={"preset": "skin"}))).on("layered profile")
    assert not plan_scene(parse_scene(scene_dict(material={"name": "skin1"}))).on("layered profile")


def test_looser_target_gives_fewer_gaussians_and_each_meets_its_target():
    scene = parse_scene(scene_dict(material={"name": "ketchup"}))
    tight, loose = plan_scene(scene, accuracy=0.02), plan_scene(scene, accuracy=0.3)
    assert len(loose.variances) < len(tight.variances)
    assert loose.max_ratio > tight.max_ratio
    for plan, target in ((tight, 0.02), (loose, 0.3)):
        error = reduction_error(scene.material, plan.variances)
        assert np.max(error) <= target / 2 and np.isclose(np.max(error), plan.profile_error)


def test_specular_off_when_the_material_has_none():
    plan = plan_scene(parse_scene(scene_dict(material={"name": "marble", "specular": 0.0})))
    assert not plan.on("specular")
    assert "plan:" in plan.describe() and "specular" in plan.describe()
