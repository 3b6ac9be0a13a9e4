r"""A swatch of every measured material (jsss), with Mitsuba 3 renders of a few exports beside.

    PYTHONPATH=. python scripts/render_swatches.py [--out docs/materials.png] [--size 64]
        [--mitsuba marble,skin1,lowfat_soy_milk,espresso] [--spp 64] [--only NAME,...]

**The scene** (one for every swatch): a sphere 100 mm across at the origin, seen from 300 mm
by a camera with a 22 degree field, in a uniform white environment of radiance 1 (no other
light). jsss renders it from the scene file's form (``[material] name = "..."``, the planner's
choice of method; ``profile = "transport"`` with the tabulated g nearest the material's where
the tables cover it, else the dipole) with ``specular = 0``: the swatch is the light that went
under the surface, the material's colour. The tile's pixel values are linear radiance, shown with the sRGB curve,
the same exposure for every tile (a white diffuser would show 1).

**Beside it, Mitsuba 3** (``scalar_rgb``, ``volpathmis``, no depth limit, Russian roulette
only past depth 10^5): the same sphere
with :func:`measure.export.mitsuba_dict` of the material (a smooth ``dielectric`` of the
material's eta around a ``homogeneous`` medium, Henyey-Greenstein g = the material's mean g,
``sigma_s = sigma_s' / (1 - g)``). Mitsuba's sphere also mirrors the white environment (the
Fresnel reflectance F, 2 % at normal view for eta 1.33, more at the rim); the table the
script prints compares a central patch with F(0) taken off against (1 - F(0)) R_d from the
transport tables (the semi-infinite answer at normal view; a material whose diffusion length
approaches the radius, like the soy milk, returns more: light enters all over the sphere).

Clear liquids (juices, wines, sodas) scatter so little that their swatch is almost black:
jsss models the light that diffuses back out, and these are seen by the light they transmit.
Materials with a channel that does not scatter at all (sigma_s' = 0: coke, pepsi, merlot,
coors_light_beer, grape_juice) get a crossed tile when jsss cannot render them (the reason is
printed).
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
import warnings
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# 100 mm across: many diffusion lengths of most materials, so that the centre is the half space's
RADIUS, DISTANCE, FOV = 50.0, 300.0, 22.0   # mm, mm, degrees (vertical)
MITSUBA = ("marble", "skin1", "lowfat_soy_milk", "espresso")


def profile_model(name: str) -> dict:
    """The transport profile at the tabulated g nearest the material's mean g where the tables
    cover the material (every channel scatters, sigma_a / sigma_s' <= 1000), else the dipole's:
    at low albedo (espresso) the dipole, which knows sigma_s' only, is 2-3 times too bright."""
    from jsss import transport
    from jsss.materials import material, material_entry

    gs = np.asarray(transport.table_info()["gs"], float)
    g = float(gs[np.argmin(np.abs(gs - material_entry(name).g_mean))])
    try:
        transport.check_medium(material(name), g=g)
    except ValueError:
        return {}
    return {"profile": "transport", "g": g}


def scene_dict(name: str, size: int) -> dict:
    """The swatch scene in the TOML layout (jsss.render.parse_scene)."""
    return {"geometry": {"shape": "sphere", "radius": RADIUS, "segments": 64, "rings": 32},
            "material": {"name": name, "specular": 0.0, **profile_model(name)},
            "lights": [{"type": "environment", "color": [1.0, 1.0, 1.0], "intensity": 1.0}],
            "camera": {"position": [0.0, -DISTANCE, 0.0], "look_at": [0.0, 0.0, 0.0], "up": [0.0, 0.0, 1.0],
                       "fov": FOV, "resolution": [size, size]},
            "render": {"texture_size": 256, "accuracy": 0.05}}


def render_jsss(name: str, size: int):
    """Linear radiance (size, size, 3) and the method the planner chose (and the profile)."""
    import jax.numpy as jnp

    from jsss.render import parse_scene, plan_scene, render

    scene = parse_scene(scene_dict(name, size), source=f"{name} swatch")
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # the planner's scale warnings for clear liquids: expected here
        plan = plan_scene(scene)
        radiance = np.asarray(render(scene, plan, dtype=jnp.float32).radiance, float)
    model = scene.material.profile_model + (f" g={scene.material.g:g}" if scene.material.profile_model == "transport" else "")
    return radiance, f"{type(plan.method_config).__name__} ({model})"


def render_mitsuba(name: str, size: int, spp: int):
    """Mitsuba 3's linear radiance (size, size, 3) of the exported material on the same sphere."""
    import mitsuba as mi

    from jsss.materials import material, material_entry
    from measure import export

    mi.set_variant("scalar_rgb")
    exported = export.mitsuba_dict(material(name), g=material_entry(name).g_mean)
    T = mi.ScalarTransform4f
    scene = mi.load_dict({
        "type": "scene",
        # Russian roulette from depth 10^5 only: with Mitsuba's default (depth 5) the sphere of
        # marble came out 19 % dark in red (0.66 against 0.82 at 64 spp, 2026-12-04); benchmarks/exports.py uses 1000
        # hide_emitters: the environment seen directly is black, as jsss draws no background
        "integrator": {"type": "volpathmis", "max_depth": -1, "rr_depth": 100000, "hide_emitters": True},
        "ball": {"type": "sphere", "center": [0.0, 0.0, 0.0], "radius": RADIUS,
                 "bsdf": exported["bsdf"], "interior": exported["interior"]},
        "environment": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}},
        "sensor": {"type": "perspective", "fov": FOV, "fov_axis": "y",
                   "to_world": T().look_at(origin=[0.0, -DISTANCE, 0.0], target=[0.0, 0.0, 0.0], up=[0.0, 0.0, 1.0]),
                   "sampler": {"type": "independent", "sample_count": spp},
                   "film": {"type": "hdrfilm", "width": size, "height": size, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"}},
    })
    return np.array(mi.render(scene, spp=spp), float)[..., :3]


def centre(image: np.ndarray, half: int = 4) -> tuple[np.ndarray, np.ndarray]:
    """Mean of the central (2 half) x (2 half) pixels per channel (normal view of the sphere)
    and its standard error (pixels are independent: a box filter)."""
    c = image.shape[0] // 2
    patch = image[c - half:c + half, c - half:c + half].reshape(-1, 3)
    return patch.mean(0), patch.std(0, ddof=1) / np.sqrt(len(patch))


def truth(name: str) -> tuple[np.ndarray, float]:
    """(1 - F(0)) R_d at normal view (R_d per channel as `jsss materials` gives it) and F(0)."""
    from jsss import transport
    from jsss.materials import material
    from measure.commands.info import material_reflectance

    eta = np.asarray(material(name).eta, float)
    f0 = 1.0 - np.asarray(transport.entry_transmittance(eta), float)
    rd, _, _ = material_reflectance(name)
    return (1.0 - f0) * rd, float(f0[0])


def srgb(linear: np.ndarray) -> np.ndarray:
    x = np.clip(linear, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)


def contact_sheet(tiles: dict, pairs: dict, out: Path, size: int) -> None:
    """All tiles in a grid (name under each), then the jsss | Mitsuba 3 pairs."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    columns = 8
    rows = -(-len(tiles) // columns)
    pair_rows = -(-len(pairs) // (columns // 2)) if pairs else 0
    inch = 1.05
    fig = plt.figure(figsize=(columns * inch, (rows + pair_rows) * inch * 1.18 + (0.35 if pairs else 0)), dpi=100)
    grid = fig.add_gridspec(rows + pair_rows, columns, hspace=0.55, wspace=0.05)
    for i, (name, image) in enumerate(tiles.items()):
        ax = fig.add_subplot(grid[i // columns, i % columns])
        _show(ax, image, name)
    for j, (name, (ours, theirs)) in enumerate(pairs.items()):
        row, col = rows + j // (columns // 2), 2 * (j % (columns // 2))
        _show(fig.add_subplot(grid[row, col]), ours, f"{name} (jsss)")
        _show(fig.add_subplot(grid[row, col + 1]), theirs, f"{name} (Mitsuba 3)")
    fig.savefig(out, bbox_inches="tight", facecolor="white")
    plt.close(fig)


def _show(ax, image, label):
    if image is None:  # not rendered: a crossed grey tile
        ax.imshow(np.full((8, 8, 3), 0.8))
        ax.plot([0, 7], [0, 7], "k-", [0, 7], [7, 0], "k-", lw=0.8)
    else:
        ax.imshow(srgb(image), interpolation="nearest")
    ax.set_axis_off()
    ax.set_title(_wrap(label), fontsize=6, pad=2)


def _wrap(label: str, width: int = 14) -> str:
    """The name on up to two lines, split at a word: tiles are narrow."""
    words, lines = label.replace("_", " ").split(" "), [""]
    for word in words:
        if lines[-1] and len(lines[-1]) + 1 + len(word) > width and len(lines) < 2:
            lines.append(word)
        else:
            lines[-1] = f"{lines[-1]} {word}".strip()
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--out", type=Path, default=ROOT / "docs" / "materials.png", help="the contact sheet (PNG)")
    parser.add_argument("--size", type=int, default=64, help="pixels across each swatch")
    parser.add_argument("--mitsuba", default=",".join(MITSUBA), help="materials also rendered in Mitsuba 3 ('' for none)")
    parser.add_argument("--spp", type=int, default=64, help="Mitsuba samples per pixel")
    parser.add_argument("--only", default="", help="render only these materials (comma-separated)")
    args = parser.parse_args()

    import jax

    jax.config.update("jax_enable_x64", True)
    from jsss.materials import material_names

    names = [n for n in args.only.split(",") if n] or list(material_names())
    tiles, start = {}, time.perf_counter()
    for name in names:
        t0 = time.perf_counter()
        try:
            tiles[name], method = render_jsss(name, args.size)
            print(f"{name:<28} jsss {method:<30} {time.perf_counter() - t0:5.1f} s", flush=True)
        except Exception as error:  # noqa: BLE001 - the sheet shows the gap, the log says why
            tiles[name] = None
            print(f"{name:<28} jsss FAILED: {type(error).__name__}: {str(error).splitlines()[0][:160]}", flush=True)
    pairs, table = {}, []
    for name in [n for n in args.mitsuba.split(",") if n]:
        t0 = time.perf_counter()
        theirs = render_mitsuba(name, args.size, args.spp)
        seconds = time.perf_counter() - t0
        ours = tiles.get(name)
        if ours is None:
            ours, _ = render_jsss(name, args.size)
        pairs[name] = (ours, theirs)
        expected, f0 = truth(name)
        (mean, error), (ours_mean, _) = centre(theirs), centre(ours)
        table.append((name, ours_mean, mean - f0, error, expected, seconds))
        print(f"{name:<28} Mitsuba {args.spp} spp {seconds:5.1f} s", flush=True)
    contact_sheet(tiles, pairs, args.out, args.size)
    print(f"wrote {args.out} ({len(tiles)} swatches, {sum(v is None for v in tiles.values())} not rendered; "
          f"{time.perf_counter() - start:.0f} s) on {datetime.date.today()}")
    if table:
        print("\n| material | jsss, centre (no specular) | Mitsuba 3, centre - F(0) | its standard error |"
              " (1 - F(0)) R_d, transport | Mitsuba time |\n|---|---|---|---|---|---|")
        for name, ours, theirs, error, expected, seconds in table:
            print(f"| {name} | {_rgb(ours)} | {_rgb(theirs)} | {_rgb(error)} | {_rgb(expected)} | {seconds:.0f} s |")


def _rgb(values) -> str:
    return " ".join(f"{v:.3f}" for v in values)


if __name__ == "__main__":
    sys.exit(main())
