"""The head example (examples/head.toml): the scan the papers render, its licence, its procedural
skin colour map, and a frame through every pass it plans (texture space, a layered profile, an
environment with visibility, translucent shadow maps through the ears)."""

import dataclasses
import importlib.util
from pathlib import Path

import numpy as np
import pytest

from jsss.render import load_scene, plan_scene, render
from jsss.render.mesh import is_closed, shadows_itself

EXAMPLES = Path(__file__).resolve().parents[3] / "examples"


@pytest.fixture(scope="module")
def head():
    return load_scene(EXAMPLES / "head.toml")


def test_the_head_is_a_closed_uv_mapped_scan_with_its_licence_and_attribution(head):
    mesh = head.mesh
    assert mesh.has_uvs and is_closed(mesh) and shadows_itself(mesh)
    lo, hi = mesh.bounds
    assert 180 < hi[0] - lo[0] < 600 and 300 < hi[2] - lo[2] < 600  # a bust in millimetres, +z up
    nose = mesh.vertices[np.argmin(mesh.vertices[:, 1])]
    assert nose[2] > lo[2] + 0.5 * (hi[2] - lo[2])  # the face looks along -y, above the shoulders
    licence = " ".join((EXAMPLES / "head" / "LICENSE.txt").read_text().split())
    for credit in ("Lee Perry-Smith", "Creative Commons Attribution 3.0", "triplegangers.com", "McGuire"):
        assert credit in licence
    assert "Lee Perry-Smith" in (EXAMPLES / "head" / "head.obj").read_text()[:400]  # the file credits itself too


def test_the_head_plan_carries_the_rim_light_through_the_ears(head):
    """Translucent shadow maps: the ears are a few mm thick against the rim light (the planner's
    rule counts a thin part by its area, 25 mm^2, not by a percentile of the shadowed side)."""
    plan = plan_scene(head)
    assert plan.method == "texture-space" and "set by the scene" in plan.method_why
    assert plan.on("translucent shadow maps") and plan.on("layered profile") and plan.on("surface maps")
    why = next(d.why for d in plan.decisions if d.name == "translucent shadow maps")
    thinnest = float(why.split("cuts through: ")[1].split(" mm")[0])
    assert 1.0 < thinnest < 10.0, why


def test_the_head_renders_lit_finite_and_skin_coloured(head):
    """Every planned pass, at a small frame: finite, non-negative, most of the head lit, and the
    colour of light skin (red > green > blue) where the key light falls."""
    small = dataclasses.replace(head, camera=dataclasses.replace(head.camera, width=80, height=100), texture_size=256)
    result = render(small)
    image = np.asarray(result.radiance)
    assert image.shape == (100, 80, 3) and np.all(np.isfinite(image)) and image.min() >= 0
    covered = image.sum(-1) > 0
    assert covered.mean() > 0.5
    bright = image[image.sum(-1) > np.percentile(image.sum(-1)[covered], 70)]
    r, g, b = bright.mean(0)
    assert r > g > b > 0.2 * r


def test_the_committed_skin_map_is_what_its_recipe_makes(tmp_path):
    """examples/head/make_skin_map.py regenerates skin_albedo.png to within one 8-bit step."""
    import imageio.v3 as iio

    spec = importlib.util.spec_from_file_location("make_skin_map", EXAMPLES / "head" / "make_skin_map.py")
    recipe = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(recipe)
    recipe.main(out=str(tmp_path / "skin.png"))
    made = iio.imread(tmp_path / "skin.png").astype(int)
    committed = iio.imread(EXAMPLES / "head" / "skin_albedo.png").astype(int)
    assert made.shape == committed.shape and np.abs(made - committed).max() <= 1


def test_the_recipe_absorption_is_the_published_chromophores():
    """Eumelanin and blood at the three band centres against the formulas' own numbers worked by
    hand (Jacques 1998; Prahl's table), in 1/mm: an independent check of the unit conversions."""
    spec = importlib.util.spec_from_file_location("make_skin_map", EXAMPLES / "head" / "make_skin_map.py")
    recipe = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(recipe)
    # 6.6e11 * 550^-3.33 = 494 /cm; 0.75 * 43016 + 0.25 * 53412 = 45615 /cm/M * ln 10 * 150 / 64500 M = 244 /cm
    np.testing.assert_allclose(recipe.melanin_absorption()[1], 49.4, rtol=5e-3)
    np.testing.assert_allclose(recipe.blood_absorption()[1], 24.4, rtol=5e-3)
    # The bloodless baseline at 650 nm: 0.244 + 85.3 exp(-496 / 66.2) = 0.2917 /cm
    np.testing.assert_allclose(recipe.baseline_absorption()[0], 0.02917, rtol=5e-3)
