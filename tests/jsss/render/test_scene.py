"""Scene files: what they may say, and errors that name the key; meshes; the jsss-render command."""

import os
import subprocess
import sys

import numpy as np
import pytest

from jsss.render import SceneError, load_obj, load_scene, parse_scene
from jsss.render.mesh import box, fin, plane, uv_sphere
from jsss.render.texture_space import bake_texels
from tests.jsss.render.scenes import scene_dict

ROOT = os.path.dirname(os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__)))))


@pytest.mark.parametrize("change, message", [
    (lambda d: d["material"].update(name="jade"), r"\[material\] name: unknown material 'jade'"),
    (lambda d: d.update(material={"sigma_a": [-0.1, 0, 0], "sigma_s_prime": 1.0}), r"sigma_a: must be >= 0"),
    (lambda d: d.update(material={"sigma_a": 0.1, "sigma_s_prime": 1.0, "eta": 0.0}), r"eta: must be > 0"),
    (lambda d: d["geometry"].update(radius=-1), r"\[geometry\] radius: must be > 0"),
    (lambda d: d["geometry"].update(shape="torus"), r"shape: must be one of"),
    (lambda d: d["camera"].update(fov=200), r"\[camera\] fov"),
    (lambda d: d.update(lights=[]), r"lights: must be a non-empty array"),
    (lambda d: d["lights"][0].update(colour=[1, 1, 1]), r"\[lights\[0\]\] colour: unknown key"),
    (lambda d: d["render"].update(accuracy=2.0), r"\[render\] accuracy"),
    (lambda d: d.pop("camera"), r"\[scene\] camera: missing"),
    (lambda d: d["material"].update(sigma_a=[0.1] * 3), r"give exactly one of"),
    # before: "[scene] material: missing (required)."
    (lambda d: d.update(materail=d.pop("material")),
     r"\[scene\] materail: unknown section \(misspelt\?\); did you mean 'material'\?"),
    (lambda d: d["camera"].update(fvo=30), r"\[camera\] fvo: unknown key \(misspelt\?\); did you mean 'fov'\?"),
])
def test_bad_scenes_name_the_key_and_the_problem(change, message):
    data = scene_dict()
    change(data)
    with pytest.raises(SceneError, match=message):
        parse_scene(data, source="s.toml")


def test_unreadable_toml_names_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[geometry\nshape = 1")
    with pytest.raises(SceneError, match="broken.toml: not valid TOML"):
        load_scene(path)
    with pytest.raises(SceneError, match="no such scene file"):
        load_scene(tmp_path / "missing.toml")


def test_example_scenes_load():
    for name in ("marble_sphere", "skin_backlit", "ketchup_plane", "marble_veins", "checker_plane", "skin_studio", "head"):
        scene = load_scene(os.path.join(ROOT, "examples", f"{name}.toml"))
        assert scene.lights and scene.camera.width > 0


@pytest.mark.parametrize("mesh", [uv_sphere(10.0), plane(20.0), box(10.0), fin(20.0, 30.0, 1.0)])
def test_texel_area_sums_to_the_surface_area(mesh):
    p = mesh.vertices[mesh.faces]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1).sum()
    texels = bake_texels(mesh, 256)
    assert texels.area.sum() == pytest.approx(area, rel=0.03)
    assert np.allclose(np.linalg.norm(texels.normal[texels.mask], axis=-1), 1.0)


def test_obj_with_uvs_loads_and_without_uvs_loads_marked(tmp_path):
    good = tmp_path / "quad.obj"
    good.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
                    "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")
    mesh = load_obj(good)
    assert len(mesh.faces) == 2 and mesh.uvs.min() >= 0 and mesh.uvs.max() <= 1
    assert mesh.has_uvs
    bare = tmp_path / "nouv.obj"
    bare.write_text("v 0 0 0\nv 1 0 0\nv 1 1 0\nf 1 2 3\n")
    assert not load_obj(bare).has_uvs


def _uvless_sphere(folder):
    """A sphere OBJ with positions and faces only (what a scan or a CAD export often is)."""
    import trimesh

    trimesh.creation.icosphere(subdivisions=3, radius=20.0).export(folder / "ball.obj", include_texture=False)
    return {"geometry": {"shape": "obj", "path": "ball.obj"}, "material": {"name": "marble"},
            "lights": [{"type": "directional", "direction": [0.6, 0.8, -0.5]}],
            "camera": {"position": [0.0, -110.0, 30.0], "resolution": [40, 30]}}


@pytest.mark.parametrize("method", ["lambert", "image-space", "normal-filtering"])
def test_a_mesh_without_uvs_renders_with_the_pixel_methods(tmp_path, method):
    """It had been refused for every method, though only texture space and maps need a UV layout."""
    import jax.numpy as jnp

    from jsss.render import parse_scene, plan_scene, render

    scene = parse_scene(_uvless_sphere(tmp_path), base_dir=tmp_path)
    assert not scene.mesh.has_uvs
    radiance = np.asarray(render(scene, plan_scene(scene, method=method), dtype=jnp.float64).radiance)
    assert np.all(np.isfinite(radiance)) and radiance.max() > 0


def test_a_mesh_without_uvs_is_planned_away_from_texture_space(tmp_path):
    from jsss.render import Method, SceneError, parse_scene, plan_scene

    data = _uvless_sphere(tmp_path)
    scene = parse_scene(data, base_dir=tmp_path)
    plan = plan_scene(scene)
    assert plan.method != Method.TEXTURE_SPACE and all(e.method != Method.TEXTURE_SPACE for e in plan.estimates)
    with pytest.raises(ValueError, match="texture-space needs the mesh's UV layout, and ball has none"):
        plan_scene(scene, method="texture-space")
    import imageio.v3 as iio

    iio.imwrite(tmp_path / "c.png", np.full((4, 4, 3), 200, np.uint8))
    data["material"]["maps"] = {"albedo": "c.png"}
    with pytest.raises(SceneError, match=r"\[material\] maps: the mesh ball has no UV layout"):
        parse_scene(data, base_dir=tmp_path)


def _run(*args, cwd):
    env = dict(os.environ, CI="true")
    return subprocess.run([sys.executable, "-m", "measure.commands.render", *args], capture_output=True, text=True,
                          cwd=cwd, env=env, stdin=subprocess.DEVNULL, timeout=600)


def test_command_line_renders_png_and_exr_and_prints_the_plan(tmp_path):
    scene = tmp_path / "small.toml"
    scene.write_text('[geometry]\nshape = "sphere"\nradius = 15\nsegments = 32\nrings = 16\n'
                     '[material]\nname = "marble"\n[[lights]]\ntype = "directional"\ndirection = [0.5, 1, -0.5]\n'
                     '[camera]\nposition = [0, -90, 20]\nresolution = [40, 30]\n[render]\ntexture_size = 64\n')
    out = _run(str(scene), "-o", str(tmp_path / "out.png"), "--plan", "--timings", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "plan:" in out.stdout and "diffusion" in out.stdout and "timings (ms)" in out.stdout
    import matplotlib.image

    from measure.exr import read_exr

    png = matplotlib.image.imread(tmp_path / "out.png")
    assert png.shape[:2] == (30, 40)
    exr = read_exr(tmp_path / "out.exr")
    assert exr.pixels.shape == (30, 40, 3) and np.all(np.isfinite(exr.pixels)) and exr.pixels.max() > 0


def test_command_line_bad_scene_is_one_line_and_exit_2(tmp_path):
    scene = tmp_path / "bad.toml"
    scene.write_text('[geometry]\nshape = "sphere"\nradius = -3\n')
    out = _run(str(scene), cwd=tmp_path)
    assert out.returncode == 2
    assert out.stderr.strip().count("\n") == 0 and "radius: must be > 0" in out.stderr


def test_command_line_method_override_renders_with_it(tmp_path):
    scene = tmp_path / "small.toml"
    scene.write_text('[geometry]\nshape = "sphere"\nradius = 15\nsegments = 32\nrings = 16\n'
                     '[material]\nname = "marble"\n[[lights]]\ntype = "directional"\ndirection = [0.5, 1, -0.5]\n'
                     '[camera]\nposition = [0, -90, 20]\nresolution = [40, 30]\n')
    out = _run(str(scene), "-o", str(tmp_path / "out.png"), "--plan", "--method", "image-space", "--samples", "4",
               "--no-exr", cwd=tmp_path)
    assert out.returncode == 0, out.stderr
    assert "method: image-space -- set by the caller" in out.stdout and "4 samples per pixel" in out.stdout
    bad = _run(str(scene), "--samples", "0", "--method", "image-space", cwd=tmp_path)
    assert bad.returncode == 2 and "samples" in bad.stderr


SMALL_SCENE = ('[geometry]\nshape = "sphere"\nradius = 15\nsegments = 16\nrings = 8\n'
               '[material]\nname = "marble"\n[[lights]]\ntype = "directional"\ndirection = [0.5, 1, -0.5]\n'
               '[camera]\nposition = [0, -90, 20]\nresolution = [16, 12]\n[render]\ntexture_size = 32\n')


def test_command_line_renders_several_scenes_and_reports_the_bad_one(tmp_path):
    """Several scenes in one call (before: one per call): -o is then a directory; a bad scene
    is one error line while the others still render, and the exit status is 2."""
    for name in ("a", "b"):
        (tmp_path / f"{name}.toml").write_text(SMALL_SCENE)
    (tmp_path / "bad.toml").write_text(SMALL_SCENE.replace("[material]", "[materail]"))
    out = _run("a.toml", "bad.toml", "b.toml", "-o", "renders", "--method", "lambert", "--no-exr", cwd=tmp_path)
    assert out.returncode == 2
    assert sorted(p.name for p in (tmp_path / "renders").iterdir()) == ["a.png", "b.png"]
    errors = [line for line in out.stderr.splitlines() if "error" in line]
    assert len(errors) == 1 and "bad.toml: [scene] materail: unknown section" in errors[0]


def test_the_scene_may_fix_the_method_and_the_plan_says_so():
    """[render] method is obeyed (any spelling the command line takes), a caller's method still
    wins, and "auto" or no key leaves the choice to the planner."""
    from jsss.render import plan_scene

    data = scene_dict(render={"texture_size": 64, "accuracy": 0.1, "method": "normal-filtering"})
    plan = plan_scene(parse_scene(data))
    assert plan.method == "normal filtering" and plan.method_why == "set by the scene ([render] method)"
    assert plan_scene(parse_scene(data), method="lambert").method == "lambert"
    data["render"]["method"] = "auto"
    assert parse_scene(data).method is None
    data["render"]["method"] = "fast"
    with pytest.raises(SceneError, match=r"\[render\] method: must be auto, lambert, .*got 'fast'"):
        parse_scene(data, source="s.toml")
