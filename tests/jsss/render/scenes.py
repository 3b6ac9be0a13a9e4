"""Small scenes for the renderer tests (dicts in the TOML layout)."""

import copy


def scene_dict(geometry=None, material=None, lights=None, camera=None, render=None):
    data = {
        "geometry": geometry or {"shape": "sphere", "radius": 20.0, "segments": 48, "rings": 24},
        "material": material or {"name": "marble"},
        "lights": lights or [{"type": "directional", "direction": [0.3, 0.8, -0.5]}],
        "camera": camera or {"position": [0.0, -110.0, 30.0], "fov": 28, "resolution": [48, 36]},
        "render": render or {"texture_size": 64, "accuracy": 0.1},
    }
    return copy.deepcopy(data)


def flat_plane(material, *, width=40.0, texture_size=256):
    """A plane seen straight from above, lit straight from above."""
    return scene_dict(
        geometry={"shape": "plane", "width": width},
        material=material,
        lights=[{"type": "directional", "direction": [0.0, 0.0, -1.0]}],
        camera={"position": [0.0, 0.0, 200.0], "look_at": [0.0, 0.0, 0.0], "up": [0.0, 1.0, 0.0],
                "fov": 12, "resolution": [64, 64]},
        render={"texture_size": texture_size, "accuracy": 0.05},
    )
