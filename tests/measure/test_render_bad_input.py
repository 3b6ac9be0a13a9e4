"""Hostile scenes through ``jsss-render`` as a user runs it (issue 38, parts 1-3).

Each case is the marble sphere example with one thing broken, rendered by the console
script's ``main`` in this process: it must end in exit status 2 with one line on stderr that
names the key or flag -- refused before anything large is allocated -- and write no image.
A scene that still renders must give a finite, non-black frame; one that a bug breaks must
not stop the scenes after it, nor print a traceback.
"""

import copy
import tomllib
from pathlib import Path

import pytest
import tomlkit

from jsss.render import budget
from measure.commands import render as render_command

EXAMPLE = tomllib.loads((Path(__file__).parents[2] / "examples" / "marble_sphere.toml").read_text())
SMALL = {"position": [0.0, -110.0, 30.0], "look_at": [0.0, 0.0, 0.0], "fov": 28, "resolution": [32, 24]}
CUSTOM = {"sigma_a": [0.0021, 0.0041, 0.0071], "sigma_s_prime": [2.19, 2.62, 3.0]}


def _scene(tmp_path, name, edit):
    data = copy.deepcopy(EXAMPLE)
    data["camera"] = dict(SMALL)
    edit(data)
    path = tmp_path / f"{name}.toml"
    path.write_text(tomlkit.dumps(data))
    return path


def _set(section, key, value):
    def edit(data):
        table = data[section][0] if isinstance(data[section], list) else data[section]
        table[key] = value
    return edit


def _material(**keys):
    return lambda data: data.__setitem__("material", {**CUSTOM, **keys})


def _point_obj(data, folder):
    (folder / "point.obj").write_text("v 1 1 1\nv 1 1 1\nv 1 1 1\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
                                      "f 1/1/1 2/2/1 3/3/1\n")
    data["geometry"] = {"shape": "obj", "path": "point.obj"}


CASES = {  # name: (edit, extra flags, words the one line must hold)
    "resolution 20000^2": (_set("camera", "resolution", [20000, 20000]), [], ["[camera] resolution", "GiB"]),
    "resolution 100000^2": (_set("camera", "resolution", [100000, 100000]), [], ["[camera] resolution", "TiB"]),
    "shadow map 100000": (_set("render", "shadow_map_size", 100000), [], ["[render] shadow_map_size", "GiB"]),
    "texture 8192 on little memory": (_set("render", "texture_size", 8192), [], ["[render] texture_size"]),
    "segments 1e6": (_set("geometry", "segments", 1_000_000), [], ["[geometry] segments", "triangles"]),
    "rings 1e7": (_set("geometry", "rings", 10_000_000), [], ["[geometry] rings"]),
    "samples 1e9": (lambda d: None, ["--method", "image-space", "--samples", "1000000000"], ["--samples"]),
    "samples 0": (lambda d: None, ["--method", "image-space", "--samples", "0"], ["--samples"]),
    "eta 1e-9": (_material(eta=1e-9), [], ["[material] eta", "(0.5, 4)"]),
    "eta 10": (_material(eta=10.0), [], ["[material] eta"]),
    "layer eta 0.2": (lambda d: d.__setitem__("material", {"layers": [{**CUSTOM, "eta": 0.2, "thickness": 1.0}]}),
                      [], ["[material.layers[0]] eta"]),
    "intensity 1e308": (_set("lights", "intensity", 1e308), [], ["[lights[0]] intensity", "float32"]),
    "colour 1e300": (_set("lights", "color", [1e300, 1.0, 1.0]), [], ["[lights[0]] intensity"]),
    "up zero": (_set("camera", "up", [0.0, 0.0, 0.0]), [], ["[camera] up", "zero"]),
    "up along the view": (_set("camera", "up", [0.0, 110.0, -30.0]), [], ["[camera] up", "parallel"]),
    "scale 1e300": (_set("geometry", "scale", 1e300), [], ["[geometry] scale", "millimetres"]),
    "scale 1e-300": (_set("geometry", "scale", 1e-300), [], ["[geometry] scale"]),
    "translate 1e300": (_set("geometry", "translate", [1e300, 0.0, 0.0]), [], ["[geometry] translate"]),
    "sigma_s_prime 0": (_material(sigma_s_prime=0.0), [], ["[material] sigma_s_prime", "scatters"]),
    "roughness 1e300": (_set("material", "roughness", 1e300), [], ["[material] roughness", "Beckmann"]),
    "all vertices at one point": (None, [], ["[geometry] path", "point.obj", "one point"]),  # the file, not the key
    # and the rest of the scene, which already answered in one line: kept answering so
    "resolution zero": (_set("camera", "resolution", [0, 240]), [], ["[camera] resolution", "> 0"]),
    "fov 180": (_set("camera", "fov", 180.0), [], ["[camera] fov", "180"]),
    "eta as a string": (_material(eta="1.3"), [], ["[material] eta", "list of 3 numbers"]),
    "no lights": (lambda d: d.__setitem__("lights", []), [], ["lights", "non-empty"]),
    "misspelt section": (lambda d: d.__setitem__("materail", {}), [], ["materail", "material"]),
    "texture 8": (_set("render", "texture_size", 8), [], ["[render] texture_size", "[16, 8192]"]),
    "accuracy 2": (_set("render", "accuracy", 2.0), [], ["[render] accuracy", "(0, 1)"]),
    "--accuracy 0": (lambda d: None, ["--accuracy", "0"], ["--accuracy", "(0, 1)"]),
    "direction zero": (_set("lights", "direction", [0.0, 0.0, 0.0]), [], ["[lights[0]] direction", "zero"]),
    "missing map": (lambda d: d["material"].__setitem__("maps", {"albedo": "nope.png"}), [],
                    ["[material.maps] albedo", "nope.png"]),
    "exposure -1": (_set("render", "exposure", -1.0), [], ["[render] exposure", "> 0"]),
    "negative sigma_a": (_material(sigma_a=[-0.1, 0.01, 0.01]), [], ["[material] sigma_a", ">= 0"]),
    "sigma_a 1e300": (_material(sigma_a=1e300), [], ["[material] sigma_a", "1/mm"]),  # had been numpy's own words
}


@pytest.mark.parametrize("name", list(CASES))
def test_a_hostile_scene_is_one_line_naming_the_key_and_exit_2(tmp_path, capsys, monkeypatch, name):
    edit, flags, words = CASES[name]
    monkeypatch.setenv("JSSS_MEMORY_LIMIT", str(8 << 30))  # the same verdicts on any machine
    if edit is None:
        path = _scene(tmp_path, "case", lambda data: _point_obj(data, tmp_path))
    else:
        path = _scene(tmp_path, "case", edit)
    out = tmp_path / "out.png"
    status = render_command.main([str(path), "-o", str(out), "-q"] + flags)
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert status == 2, err
    assert len(lines) == 1 and "Traceback" not in err, err
    assert all(word in lines[0] for word in words), lines[0]
    assert not out.exists() and not out.with_suffix(".exr").exists()


@pytest.mark.parametrize("content, words", [
    (b"\x80\x81 not text", ["case.toml", "not UTF-8"]), ("[geometry]".encode("utf-16"), ["case.toml", "not UTF-8"]),
])
def test_a_scene_file_that_is_not_text_is_named(tmp_path, capsys, content, words):
    path = tmp_path / "case.toml"
    path.write_bytes(content)
    assert render_command.main([str(path), "-o", str(tmp_path / "out.png"), "-q"]) == 2
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and all(word in lines[0] for word in words), lines


def test_an_obj_with_a_vertex_at_1e300_is_named_without_warnings(tmp_path, capsys):
    (tmp_path / "far.obj").write_text("v 0 0 0\nv 1e300 0 0\nv 0 10 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
                                      "f 1/1/1 2/2/1 3/3/1\n")
    path = _scene(tmp_path, "case", lambda data: data.__setitem__("geometry", {"shape": "obj", "path": "far.obj"}))
    assert render_command.main([str(path), "-o", str(tmp_path / "out.png"), "-q"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "far.obj: vertex coordinates must lie within 1e30" in err and "Warning" not in err


def test_the_memory_limit_follows_what_the_machine_has(monkeypatch):
    monkeypatch.setenv("JSSS_MEMORY_LIMIT", str(2 << 30))
    assert budget.check_size(640 * 480, budget.BYTES_PER_PIXEL, "640 x 480 pixels") is None
    problem = budget.check_size(4000 * 4000, budget.BYTES_PER_PIXEL, "4000 x 4000 pixels")
    assert "30.5 GiB" in problem and "1 GiB" in problem and "524,288" in problem
    monkeypatch.delenv("JSSS_MEMORY_LIMIT")
    assert budget.available_memory() > 0


def test_a_frame_that_is_not_a_picture_is_refused_and_names_the_cause():
    import numpy as np

    from jsss.render import SceneError

    frame = np.ones((4, 4, 3))
    render_command.check_frame(frame, "s.toml")
    frame[1, 2, 0] = np.nan
    with pytest.raises(SceneError, match="1 of 16 pixels that are NaN or infinite"):
        render_command.check_frame(frame, "s.toml")
    with pytest.raises(SceneError, match="black: no lit surface faces the camera"):
        render_command.check_frame(np.zeros((4, 4, 3)), "s.toml")


def test_a_scene_that_breaks_does_not_stop_the_others(tmp_path, capsys, monkeypatch):
    """A bug in one scene is one line (no traceback) and the next scene still renders."""
    good = _scene(tmp_path, "good", lambda data: None)
    bad = _scene(tmp_path, "bad", lambda data: None)
    real = render_command._render_one

    def flaky(scene_path, output, args, say):
        if Path(scene_path).name == "bad.toml":
            raise ZeroDivisionError("float division by zero")
        return real(scene_path, output, args, say)

    monkeypatch.setattr(render_command, "_render_one", flaky)
    status = render_command.main([str(bad), str(good), "-o", str(tmp_path / "frames"), "-q", "--method", "lambert"])
    captured = capsys.readouterr()
    assert status == 2
    assert "Traceback" not in captured.err and len(captured.err.strip().splitlines()) == 1
    assert "bad.toml: ZeroDivisionError" in captured.err and "a bug in jsss" in captured.err
    assert (tmp_path / "frames" / "good.png").exists() and not (tmp_path / "frames" / "bad.png").exists()


def test_the_camera_inside_the_object_is_a_black_frame_named_without_warnings(tmp_path, capsys):
    """From inside the sphere Lambert sees only unlit inner faces: the frame is black, which is
    an error naming the likely cause (it had been written with exit 0). Faces behind the eye
    cover nothing: the rasteriser does no NaN arithmetic (it had printed 16 numpy warnings)."""
    path = _scene(tmp_path, "inside", _set("camera", "position", [0.0, 5.0, 1.0]))
    out = tmp_path / "inside.png"
    status = render_command.main([str(path), "-o", str(out), "-q", "--method", "lambert"])
    err = capsys.readouterr().err
    assert status == 2 and len(err.strip().splitlines()) == 1, err
    assert "black" in err and "camera inside the object" in err and "Warning" not in err
    assert not out.exists()


@pytest.mark.parametrize("where", ["absolute", "parent"])
def test_a_mesh_or_map_outside_the_scenes_folder_is_read_only_when_allowed(tmp_path, capsys, where):
    """A scene from elsewhere must not make jsss read any file it names."""
    folder = tmp_path / "scene"
    folder.mkdir()
    (tmp_path / "outside.obj").write_text("v 0 0 0\nv 10 0 0\nv 0 10 0\nvt 0 0\nvt 1 0\nvt 0 1\nvn 0 0 1\n"
                                          "f 1/1/1 2/2/1 3/3/1\n")
    path = str(tmp_path / "outside.obj") if where == "absolute" else "../outside.obj"
    scene = _scene(folder, "case", lambda data: data.__setitem__("geometry", {"shape": "obj", "path": path}))
    out = tmp_path / "out.png"
    assert render_command.main([str(scene), "-o", str(out), "-q", "--method", "lambert"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "[geometry] path" in err and "outside the scene's folder" in err
    assert "--allow-outside-paths" in err
    render_command.main([str(scene), "-o", str(out), "-q", "--method", "lambert", "--allow-outside-paths"])
    err = capsys.readouterr().err
    assert "outside the scene's folder" not in err  # read; whatever the frame of one triangle gives


def test_an_unconstrained_fit_prints_inf_in_the_table_and_null_in_the_json(tmp_path, capsys):
    """Lambert has no spread, so a fit through it leaves the mean free path unconstrained: infinite errors.
    The table says "+- inf" and the JSON null (it had printed Infinity, invalid JSON; and a
    JSON-safe copy must not reach the table, whose format needs numbers)."""
    import json

    scene = tmp_path / "s.toml"
    scene.write_text('[geometry]\nshape = "sphere"\nradius = 20.0\n[material]\nname = "marble"\n'
                     '[[lights]]\ntype = "environment"\n'
                     '[camera]\nposition = [0.0, -110.0, 30.0]\nfov = 28\nresolution = [32, 24]\n')
    assert render_command.main([str(scene), "-o", str(tmp_path / "photo.png"), "-q"]) == 0
    photo = str(tmp_path / "photo.exr")
    assert render_command.main(["fit", str(scene), photo, "-o", str(tmp_path / "a"), "--no-gain", "-q",
                                "--method", "lambert"]) == 0
    out = capsys.readouterr().out
    assert "mean free path [mm]" in out and "+- inf" in out
    assert render_command.main(["fit", str(scene), photo, "-o", str(tmp_path / "b"), "--no-gain", "-q",
                                "--method", "lambert",
                                "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert None in summary["mean_free_path_err_mm"]
    assert json.loads((tmp_path / "b" / "photo.fit.json").read_text())["mean_free_path_err_mm"] == \
        summary["mean_free_path_err_mm"]
