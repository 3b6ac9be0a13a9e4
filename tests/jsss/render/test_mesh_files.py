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
