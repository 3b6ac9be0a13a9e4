"""Mesh files (OBJ + MTL, glTF 2.0) through trimesh: units, UVs and the base-colour texture.

The texture's orientation is checked in a rendered frame, not in jsss's own arrays: a quad
whose image has four coloured quadrants, seen from above, must show each colour at the corner
the file's UVs put it (OBJ and glTF: UV (0, 0) is the image's bottom-left, as Blender and
Mitsuba read it; glTF stores v flipped and trimesh turns it back).
"""

import jax.numpy as jnp
import numpy as np
import pytest

from jsss.render import SceneError, parse_scene, plan_scene, render

QUADRANTS = {"top left": (1.0, 0.0, 0.0), "top right": (0.0, 1.0, 0.0), "bottom left": (0.0, 0.0, 1.0),
             "bottom right": (1.0, 1.0, 1.0)}


def _quad_image():
    image = np.zeros((64, 64, 3), np.uint8)
    for name, colour in QUADRANTS.items():
        rows = slice(0, 32) if name.startswith("top") else slice(32, 64)
        cols = slice(0, 32) if name.endswith("left") else slice(32, 64)
        image[rows, cols] = np.asarray(colour) * 255
    return image


def _write_quad(folder, suffix, side=0.1):
    """A square of ``side`` file units in the xy plane, UV (0, 0) at its (0, 0) corner."""
    import trimesh
    from PIL import Image

    vertices = np.array([[0, 0, 0], [side, 0, 0], [side, side, 0], [0, side, 0]], float)
    faces = np.array([[0, 1, 2], [0, 2, 3]])
    uv = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    image = Image.fromarray(_quad_image())
    if suffix == ".obj":
        visual = trimesh.visual.TextureVisuals(uv=uv, image=image)
    else:
        visual = trimesh.visual.TextureVisuals(uv=uv, material=trimesh.visual.material.PBRMaterial(
            baseColorTexture=image))
    path = folder / f"quad{suffix}"
    trimesh.Trimesh(vertices, faces, visual=visual, process=False).export(path)
    return path


def _scene(folder, path, **geometry):
    return parse_scene({"geometry": {"shape": "mesh", "path": path.name, **geometry},
                        "material": {"name": "marble", "specular": 0.0},
                        "lights": [{"type": "directional", "direction": [0.0, 0.0, -1.0]}],
                        "camera": {"position": [50.0, 50.0, 400.0], "look_at": [50.0, 50.0, 0.0], "up": [0, 1, 0],
                                   "fov": 16, "resolution": [40, 40]}}, base_dir=folder)


@pytest.mark.parametrize("suffix", [".glb", ".obj"])
def test_the_base_colour_texture_lands_where_the_uvs_put_it(tmp_path, suffix):
    path = _write_quad(tmp_path, suffix, side=100.0 if suffix == ".obj" else 0.1)  # OBJ in mm, glTF in metres
    scene = _scene(tmp_path, path)
    np.testing.assert_allclose(np.ptp(scene.mesh.vertices, axis=0)[:2], 100.0)
    assert scene.material.maps is not None and "base-colour texture" in scene.material.maps.files[0][1]
    plain = _scene(tmp_path, path, textures=False)
    frame, white = (np.asarray(render(s, plan_scene(s, method="lambert"), dtype=jnp.float64).radiance)
                    for s in (scene, plain))
    for name, colour in QUADRANTS.items():  # Lambert takes the colour once: the frame is the plain one times it
        rows = slice(8, 14) if name.startswith("top") else slice(26, 32)
        cols = slice(8, 14) if name.endswith("left") else slice(26, 32)
        seen = frame[rows, cols].reshape(-1, 3).sum(0) / white[rows, cols].reshape(-1, 3).sum(0)
        np.testing.assert_allclose(seen, colour, atol=0.02, err_msg=name)


def test_glTF_is_read_in_metres_unless_the_scene_says_otherwise(tmp_path):
    path = _write_quad(tmp_path, ".glb", side=0.1)
    assert np.ptp(_scene(tmp_path, path).mesh.vertices[:, 0]) == pytest.approx(100.0)
    assert np.ptp(_scene(tmp_path, path, units="cm").mesh.vertices[:, 0]) == pytest.approx(1.0)
    assert _scene(tmp_path, path, textures=False).material.maps is None


def test_a_missing_texture_is_named_with_the_file(tmp_path):
    path = _write_quad(tmp_path, ".obj", side=100.0)
    for png in tmp_path.glob("*.png"):
        png.unlink()
    with pytest.raises(SceneError, match=r"quad.obj: the texture or buffer .*\.png it names is missing"):
        _scene(tmp_path, path)


def _seamed_cylinder_obj(path, *, normals: bool):
    """A closed, capped cylinder whose UVs wrap: the OBJ repeats the seam's vertices with u = 0
    and u = 1 (as every unwrapped scan does), optionally with its own vn lines."""
    n, lines = 24, []
    angles = np.linspace(0, 2 * np.pi, n + 1)
    for z in (0.0, 10.0):
        lines += [f"v {5 * np.cos(a):.9f} {5 * np.sin(a):.9f} {z}" for a in angles]  # n + 1: the seam twice
    lines += ["v 0 0 0", "v 0 0 10"]
    lines += [f"vt {a / (2 * np.pi):.9f} {z / 10}" for z in (0.0, 10.0) for a in angles] + ["vt 0.5 0", "vt 0.5 1"]
    if normals:
        lines += [f"vn {np.cos(a):.9f} {np.sin(a):.9f} 0" for a in angles]
    ring = n + 1
    for i in range(n):
        a, b, c, d = i + 1, i + 2, ring + i + 2, ring + i + 1
        if normals:
            lines += [f"f {a}/{a}/{i + 1} {b}/{b}/{i + 2} {c}/{c}/{i + 2}", f"f {a}/{a}/{i + 1} {c}/{c}/{i + 2} {d}/{d}/{i + 1}"]
        else:
            lines += [f"f {a}/{a} {b}/{b} {c}/{c}", f"f {a}/{a} {c}/{c} {d}/{d}"]
        lines += [f"f {2 * ring + 1}/{2 * ring + 1} {b}/{b} {a}/{a}", f"f {2 * ring + 2}/{2 * ring + 2} {d}/{d} {c}/{c}"]
    path.write_text("\n".join(lines) + "\n")
    return path


def test_normals_are_smooth_across_a_uv_seam_and_a_files_own_normals_are_kept(tmp_path):
    """trimesh splits a vertex wherever its UVs jump; normals it computes from the split mesh
    differ between the copies, and the seam shades as a crease. Computed normals come from the
    welded surface (the copies agree, and lean neither way along the circle); a file's vn are kept."""
    from jsss.render.mesh import load_mesh, weld

    mesh, _ = load_mesh(_seamed_cylinder_obj(tmp_path / "cylinder.obj", normals=False))
    _, index, _ = weld(mesh)
    side = np.abs(mesh.vertices[:, 2] - 5.0) < 5.0 + 1e-9
    seam = side & (np.abs(mesh.vertices[:, 1]) < 1e-9) & (mesh.vertices[:, 0] > 0)  # u = 0 and u = 1 copies
    assert seam.sum() >= 4 and len(np.unique(index[seam])) < seam.sum()
    for welded in np.unique(index[seam]):
        copies = mesh.normals[index == welded]
        np.testing.assert_allclose(copies, copies[:1].repeat(len(copies), 0), atol=1e-12)
    # Symmetric about the seam's plane: no component along the circle (one copy alone leans ~4 degrees).
    x, y = mesh.vertices[seam, 0], mesh.vertices[seam, 1]
    tangent = np.stack([-y, x], -1) / np.hypot(x, y)[:, None]
    np.testing.assert_allclose((mesh.normals[seam][:, :2] * tangent).sum(1), 0.0, atol=1e-9)
    own, _ = load_mesh(_seamed_cylinder_obj(tmp_path / "own.obj", normals=True))
    on_side = np.abs(own.normals[:, 2]) < 1e-9
    np.testing.assert_allclose(np.linalg.norm(own.normals[on_side][:, :2], axis=1), 1.0, atol=1e-6)


def test_an_obj_without_a_material_library_has_no_colour_map(tmp_path):
    """trimesh offers a 2 x 2 image of its default grey for an OBJ with UVs and no MTL; that is
    no texture (it had rendered the head a uniform 0.13 grey)."""
    from jsss.render.mesh import load_mesh

    mesh, texture = load_mesh(_seamed_cylinder_obj(tmp_path / "cylinder.obj", normals=False))
    assert mesh.has_uvs and texture is None
