"""Textured materials against a heterogeneous volumetric path tracer (Mitsuba 3): issue 39's truth.

    pip install -e '.[truth]' && python benchmarks/textured_truth.py [--quick] [--spp N]

Two scenes, generated at run time into a temporary folder (map EXRs written with
``measure.exr.write_exr``, scene TOMLs with tomlkit):

* **checker_plane** -- Mertens et al. 2003's experiment: a 60 x 60 mm plane whose
  ``[material.maps]`` ``sigma_a`` and ``sigma_s_prime`` form a two-material checker (marble and
  Jensen's skin1; one edge along x = 0, the other at y = +7.5 mm, off centre so that a flipped
  ``u``, ``v`` or both changes the frame), a point lamp 30 mm above marble 6 mm from the edge:
  light crosses into skin1. The profile is the image row through the lamp's foot (y = -4 mm),
  crossing the x = 0 edge.
* **gradient_sphere** -- a sphere of radius 20 mm whose coefficients blend smoothly
  (geometrically) from marble to skin1 with t = 0.5 + 0.3 z/r + 0.2 (x + y)/(sqrt(2) r): a
  gradient with latitude (``v``) and with longitude (``u``), so that either flipped shows. The
  profile is the middle image row.

Mitsuba renders the same mesh, camera and lights (`transport_truth.py`'s helpers, imported)
with a ``heterogeneous`` medium inside: ``gridvolume`` s of albedo sigma_s'/(sigma_a + sigma_s')
and extinction sigma_a + sigma_s' (sigma_s = sigma_s', g = 0), built from the *same map files*
read back and looked up with the OBJ convention (UV (0, 0) = the image's bottom-left pixel;
jsss's plane: u = 0..1 along x = -W/2..W/2, v = 0..1 along y = +D/2..-D/2; sphere: u =
longitude / 2 pi from +x toward +y, v = colatitude / pi from +z). The volume is constant with
depth: the plane's grid is texel-aligned (one voxel per texel, nearest filtering: a sharp
edge, 2 voxels through the 30 mm deep box that closes the plane); the sphere's grid (96^3,
trilinear) holds at each voxel the map's value in the voxel's radial direction. One grey
medium per channel (`transport_truth._grey_medium`: volpath's chromatic free-path sampling
has infinite variance). The boundary is index-matched by default (eta = 1 in jsss's scene, a
``null`` BSDF in Mitsuba: next-event estimation reaches the lamp from every scattering
vertex; per-pixel noise of a few % in minutes). ``--interface dielectric`` renders eta = 1.5
through Beckmann rough dielectrics at alpha 0.1 and 0.2 extrapolated to 0 in alpha^2 with the
absorbing-interior frame (same seed) subtracted, as `transport_truth.subsurface_truth`: tens
of % noise per pixel, sums only. A white Lambertian object is rendered by both first (camera,
orientation and light units agree to 1 %). Mitsuba's noise comes from independent chunks
(seeds); each pixel's from the chunks' relative variance pooled over its 3 x 3 neighbours
(`pixel_noise`: keeping the pixels whose own few-chunk estimate is low would keep those whose
noise was underestimated). The whole frame (the sums) gets ``--spp`` samples per chunk; the
profile's row, with the rows above and below it, is rendered again on its own (a cropped
film: the same pixels) with ``--profile-spp``, so that its pixels' noise is well below the
3 % that decides which pixels count, at a fraction of the cost. The frames are cached (``--cache``, default ``$TMPDIR/jsss_textured_truth``), so
``--truth-only`` fills the cache and a later run only renders jsss.

jsss renders the generated scene files through its public API (``load_scene``, ``plan_scene``
with ``Method.TEXTURE_SPACE`` and ``Method.IMAGE_SPACE``, float64, specular off). Printed per
scene, method, profile model and channel: the ratio of the summed subsurface radiance over
the object's interior pixels jsss / Mitsuba, the largest |jsss / Mitsuba - 1| of the pixels
along the profile row whose Mitsuba noise is below 3 % (the checker: within 15 mm of the
edge), and Mitsuba's noise on the sum. A control needs no map support: the checker rendered
as two homogeneous materials (the scene without maps, once marble, once skin1) and composed
pixel by pixel by the checker (no light crosses the edge). ``--homogeneous`` adds each scene
as homogeneous marble and as homogeneous skin1 (no maps) in both renderers: the error each
material has without maps, against which the maps' is read. The table is also written, dated,
to ``docs/benchmarks/textured_truth.md`` (``--no-doc``: not).

Mitsuba needs a working variant: ``scalar_rgb`` everywhere; ``llvm_ad_rgb`` only with
Debian's libLLVM 19 (`transport_truth._mitsuba`). Times on this 2-core machine (shared, load
2-4), scalar_rgb: ``--quick`` about 3 minutes; the default run about 12 minutes.
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))
sys.path.insert(0, str(HERE.parent))

import transport_truth as tt  # noqa: E402 -- also turns float64 on

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import tomlkit  # noqa: E402

from jsss.render import Method, load_scene  # noqa: E402
from jsss.render.image_space import camera_buffers  # noqa: E402
from measure.exr import read_exr, write_exr  # noqa: E402

# Jensen et al. 2001's marble and skin1 [1/mm]: 3-9 mm against 0.7-3.7 mm diffusion lengths.
MATERIAL_A = {"sigma_a": [0.0021, 0.0041, 0.0071], "sigma_s_prime": [2.19, 2.62, 3.00]}  # marble
MATERIAL_B = {"sigma_a": [0.032, 0.17, 0.48], "sigma_s_prime": [0.74, 0.88, 1.01]}  # skin1
MATERIAL_NAMES = {"A": "marble", "B": "skin1"}
PLANE = 60.0  # mm, width = depth
BOX_DEPTH = 30.0  # transport_truth._mesh_file closes a plane with a box this deep
V_EDGE = 0.375  # the checker's second edge: v = 0.375 is y = +7.5 mm
LAMP = (-6.0, -4.0, 30.0)
EDGE_WINDOW = 15.0  # mm either side of the checker's x = 0 edge counted in the profile
RADIUS = 20.0
NOISE_LIMIT = 0.03
TRUTH_VERSION = "1"  # bump when the Mitsuba side changes (cache key)
DOC = HERE.parent / "docs" / "benchmarks" / "textured_truth.md"


# --------------------------------------------------------------------------- maps and scenes


def checker_maps(texels):
    """(sigma_a, sigma_s') images (H, W, 3) in file order (row 0 = the top): marble where
    (u < 0.5) != (v < V_EDGE), skin1 elsewhere."""
    u = (np.arange(texels) + 0.5) / texels
    v = 1.0 - (np.arange(texels) + 0.5) / texels  # file row 0 is the top: v near 1
    is_a = (u[None, :] < 0.5) != (v[:, None] < V_EDGE)
    pick = lambda key: np.where(is_a[..., None], MATERIAL_A[key], MATERIAL_B[key])  # noqa: E731
    return pick("sigma_a"), pick("sigma_s_prime")


def gradient_t(direction):
    """The sphere's blend 0..1 (marble..skin1) in a unit direction (..., 3)."""
    x, y, z = np.moveaxis(direction, -1, 0)
    return 0.5 + 0.3 * z + 0.2 * (x + y) / np.sqrt(2.0)


def blend(t):
    """Coefficients (..., 3) at blend t: geometric between marble and skin1."""
    t = np.asarray(t)[..., None]
    return tuple(np.asarray(MATERIAL_A[k]) ** (1 - t) * np.asarray(MATERIAL_B[k]) ** t
                 for k in ("sigma_a", "sigma_s_prime"))


def gradient_maps(width, height):
    """(sigma_a, sigma_s') images (height, width, 3) in file order of the sphere's gradient."""
    u = (np.arange(width) + 0.5) / width
    v = 1.0 - (np.arange(height) + 0.5) / height
    phi, theta = 2 * np.pi * u[None, :], np.pi * v[:, None]
    direction = np.stack(np.broadcast_arrays(np.sin(theta) * np.cos(phi), np.sin(theta) * np.sin(phi),
                                             np.cos(theta)), -1)
    return blend(gradient_t(direction))


@dataclasses.dataclass(frozen=True)
class Spec:
    name: str
    shape: str
    texels: tuple  # map (width, height)
    width: int
    height: int
    spp: int  # Mitsuba's samples per pixel per chunk: the whole frame
    profile_spp: int  # and the profile's crop


def scene_data(spec, eta, profile, *, maps=True, material=None):
    """The scene TOML's contents; ``material`` (a dict of sigma_a, sigma_s_prime) without maps."""
    base = material or MATERIAL_A
    data = {"geometry": ({"shape": "plane", "width": PLANE, "depth": PLANE} if spec.shape == "plane"
                         else {"shape": "sphere", "radius": RADIUS}),
            "material": {"sigma_a": base["sigma_a"], "sigma_s_prime": base["sigma_s_prime"], "eta": eta,
                         "specular": 0.0, "profile": profile}}
    if maps:
        data["material"]["maps"] = {"sigma_a": f"{spec.name}_sigma_a.exr",
                                    "sigma_s_prime": f"{spec.name}_sigma_s.exr"}
    if spec.shape == "plane":
        data["lights"] = [{"type": "point", "position": list(LAMP), "intensity": 1500.0}]
        data["camera"] = {"position": [0.0, -70.0, 55.0], "look_at": [0.0, 0.0, 0.0], "fov": 40.0,
                          "resolution": [spec.width, spec.height]}
    else:
        data["lights"] = [{"type": "directional", "direction": [0.6, 0.8, -0.5], "intensity": 1.0}]
        data["camera"] = {"position": [0.0, -110.0, 30.0], "look_at": [0.0, 0.0, 0.0], "fov": 28.0,
                          "resolution": [spec.width, spec.height]}
    data["render"] = {"accuracy": 0.02, "texture_size": 512}
    return data


def write_inputs(spec, folder, eta, profiles):
    """Map EXRs and scene TOMLs of ``spec`` in ``folder``: {(kind, profile): path}, kind "maps",
    "A" or "B" (the homogeneous controls)."""
    folder = Path(folder)
    if spec.shape == "plane":
        sigma_a, sigma_s = checker_maps(spec.texels[0])
    else:
        sigma_a, sigma_s = gradient_maps(*spec.texels)
    write_exr(folder / f"{spec.name}_sigma_a.exr", sigma_a)
    write_exr(folder / f"{spec.name}_sigma_s.exr", sigma_s)
    paths = {}
    for profile in profiles:
        for kind, material in (("maps", None), ("A", MATERIAL_A), ("B", MATERIAL_B)):
            path = folder / f"{spec.name}_{kind}_{profile}.toml"
            path.write_text(tomlkit.dumps(scene_data(spec, eta, profile, maps=kind == "maps", material=material)))
            paths[kind, profile] = path
    return paths


# --------------------------------------------------------------------------- the volume


def sample_map(image, u, v, *, nearest, wrap_u=False):
    """``image`` (H, W, C, file order: row 0 on top) at UV (OBJ convention: (0, 0) is the
    bottom-left pixel's corner), nearest or bilinear between texel centres."""
    h, w = image.shape[:2]
    if nearest:
        col = np.floor(u * w).astype(int)
        col = col % w if wrap_u else np.clip(col, 0, w - 1)
        row = np.clip(np.floor(v * h).astype(int), 0, h - 1)  # counted from the bottom
        return image[h - 1 - row, col]
    x, y = u * w - 0.5, v * h - 0.5
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    fx, fy = (x - x0)[..., None], (y - y0)[..., None]

    def at(col, row):
        col = col % w if wrap_u else np.clip(col, 0, w - 1)
        return image[h - 1 - np.clip(row, 0, h - 1), col]

    return ((1 - fx) * (1 - fy) * at(x0, y0) + fx * (1 - fy) * at(x0 + 1, y0)
            + (1 - fx) * fy * at(x0, y0 + 1) + fx * fy * at(x0 + 1, y0 + 1))


def surface_uv(shape, points):
    """UV (jsss's meshes) of the surface point a point (..., 3) belongs to: straight up for the
    plane (constant with depth), radially for the sphere."""
    x, y, z = np.moveaxis(np.asarray(points, float), -1, 0)
    if shape == "plane":
        return x / PLANE + 0.5, 0.5 - y / PLANE
    r = np.sqrt(x * x + y * y + z * z)
    theta = np.arccos(np.clip(z / np.maximum(r, 1e-12), -1, 1))
    return np.mod(np.arctan2(y, x), 2 * np.pi) / (2 * np.pi), theta / np.pi


@dataclasses.dataclass
class Volume:
    sigma_a: np.ndarray  # (Z, Y, X, 3), Mitsuba's grid order
    sigma_s: np.ndarray
    lo: np.ndarray  # world box the grid spans
    hi: np.ndarray
    nearest: bool


def volume_from_maps(spec, folder, sphere_voxels=96):
    """The medium's coefficients on a grid, read back from the map files of ``spec``."""
    maps = [read_exr(Path(folder) / f"{spec.name}_{k}.exr").pixels for k in ("sigma_a", "sigma_s")]
    if spec.shape == "plane":
        w, h = maps[0].shape[1], maps[0].shape[0]
        lo, hi, shape, nearest = (np.array([-PLANE / 2, -PLANE / 2, -BOX_DEPTH]), np.array([PLANE / 2, PLANE / 2, 0.0]),
                                  (2, h, w), True)
    else:
        extent = RADIUS * 1.02
        lo, hi, shape, nearest = -np.full(3, extent), np.full(3, extent), (sphere_voxels,) * 3, False
    axes = [lo[i] + (np.arange(n) + 0.5) / n * (hi[i] - lo[i]) for i, n in zip((2, 1, 0), shape)]
    zz, yy, xx = np.meshgrid(*axes, indexing="ij")
    u, v = surface_uv(spec.shape, np.stack([xx, yy, zz], -1))
    values = [sample_map(m, u, v, nearest=nearest, wrap_u=spec.shape == "sphere") for m in maps]
    return Volume(*values, lo, hi, nearest)


def heterogeneous_medium(mi, volume, channel, absorbing=False):
    """One channel's coefficients in all three (see ``transport_truth._grey_medium``), varying in space."""
    sigma_a, sigma_s = volume.sigma_a[..., channel], volume.sigma_s[..., channel]
    sigma_t = sigma_a + sigma_s
    albedo = np.zeros_like(sigma_t) if absorbing else sigma_s / sigma_t
    to_world = mi.ScalarTransform4f().translate(volume.lo.tolist()).scale((volume.hi - volume.lo).tolist())

    def grid(values):
        data = np.ascontiguousarray(np.repeat(values[..., None], 3, -1), np.float32)
        return {"type": "gridvolume", "grid": mi.VolumeGrid(data), "to_world": to_world,
                "filter_type": "nearest" if volume.nearest else "trilinear"}

    return {"type": "heterogeneous", "albedo": grid(albedo), "sigma_t": grid(sigma_t), "scale": 1.0}


# --------------------------------------------------------------------------- Mitsuba


def crop_sensor(mi, camera, crop):
    """The scene's camera (as `transport_truth._mitsuba_scene` builds it) rendering only ``crop``
    = (first row, rows, first column, columns) of its frame: the same pixels, for more samples."""
    y0, rows, x0, columns = crop
    return mi.load_dict({
        "type": "perspective", "fov": camera.fov_degrees, "fov_axis": "y",
        "to_world": mi.ScalarTransform4f().look_at(origin=list(camera.position), target=list(camera.look_at),
                                                    up=list(camera.up)),
        "film": {"type": "hdrfilm", "width": camera.width, "height": camera.height, "rfilter": {"type": "box"},
                 "pixel_format": "rgb", "crop_offset_x": x0, "crop_offset_y": y0, "crop_width": columns,
                 "crop_height": rows},
        "sampler": {"type": "independent"}})


def mitsuba_truth(mi, scene, medium, ply, spp, chunks, interface, *, sensor=None, first_seed=0, progress=True):
    """Subsurface radiance per chunk (chunks, H, W, 3) with ``medium(channel, absorbing)`` inside:
    index-matched (a ``null`` boundary, the whole frame is subsurface light) or dielectric (rough
    dielectrics extrapolated to smooth in alpha^2, the absorbing interior's frame subtracted with
    the same seed), as `transport_truth` does for a homogeneous medium. ``sensor``: another
    camera (:func:`crop_sensor`)."""
    if interface == "index-matched":
        boundaries = [(None, {"type": "null"})]
    else:
        eta = float(np.asarray(scene.material.eta).mean())
        boundaries = [(alpha, {"type": "roughdielectric", "distribution": "beckmann", "alpha": alpha,
                               "int_ior": eta, "ext_ior": 1.0}) for alpha in tt.ROUGHNESS]

    def frame(mscene, seed):
        return np.array(mi.render(mscene, sensor=sensor or 0, spp=spp, seed=seed), dtype=float)[..., :3]

    at = None
    for b, (alpha, bsdf) in enumerate(boundaries):
        for c in range(3):
            full = tt._mitsuba_scene(mi, scene, ply, bsdf, medium(c, False))
            dark = None if alpha is None else tt._mitsuba_scene(mi, scene, ply, bsdf, medium(c, True))
            for chunk in range(chunks):
                t0 = time.perf_counter()
                seed = first_seed + chunk
                image = frame(full, seed)[..., c]
                if dark is not None:
                    image = image - frame(dark, seed)[..., c]
                if at is None:
                    at = np.zeros((len(boundaries), chunks, *image.shape, 3))
                at[b, chunk, ..., c] = image
                if progress:
                    print(f"    {'' if alpha is None else f'alpha {alpha}, '}channel {c}, chunk {chunk + 1}/{chunks}"
                          f"{'' if sensor is None else ' (profile)'}: {time.perf_counter() - t0:.0f} s", flush=True)
    if interface == "index-matched":
        return at[0]
    a2 = np.square(tt.ROUGHNESS)
    return at[0] + (at[0] - at[1]) * a2[0] / (a2[1] - a2[0])


def cached_truth(spec, folder, scene, args, kind, crop):
    """Mitsuba's frames of ``spec`` from the cache or rendered: (per-chunk frames, per-chunk
    frames of the profile's ``crop`` at ``args.profile_spp``, white-Lambertian check, seconds,
    variant); the heterogeneous medium of the maps (``kind`` "maps"), or ``scene``'s own
    homogeneous medium (``kind`` "A" or "B", `transport_truth._grey_medium`)."""
    digest = hashlib.sha1(TRUTH_VERSION.encode())  # the inputs, so that a changed scene or map renders anew
    digest.update(tomlkit.dumps(scene_data(spec, args.eta, "dipole")).encode())
    for key in ("sigma_a", "sigma_s"):
        digest.update(np.ascontiguousarray(read_exr(Path(folder) / f"{spec.name}_{key}.exr").pixels).tobytes())
    digest.update(repr(crop).encode())
    key = (f"{spec.name}{'' if kind == 'maps' else '_' + kind}_{args.interface}_{spec.width}x{spec.height}_"
           f"{args.chunks}x{spec.spp}_profile{spec.profile_spp}_{args.variant}_{digest.hexdigest()[:10]}")
    path = Path(args.cache) / f"{key}.npz"
    if path.exists():
        data = np.load(path)
        print(f"  Mitsuba frames ({kind}) from the cache ({path})")
        return data["chunks"], data["profile"], data["lambert"], float(data["seconds"]), str(data["variant"])
    mi = tt._mitsuba(args.variant)
    t0 = time.perf_counter()
    ply = tt._mesh_file(scene, folder)
    if kind == "maps":
        lambert, _ = tt.lambert_check(mi, scene, ply, 4 * spec.spp)
        print("  white Lambertian jsss / Mitsuba - 1 = " + " / ".join(f"{100 * x:+.2f} %" for x in lambert),
              flush=True)
        volume = volume_from_maps(spec, folder)
        medium = lambda c, absorbing: heterogeneous_medium(mi, volume, c, absorbing)  # noqa: E731
    else:
        lambert = np.full(3, np.nan)
        medium = lambda c, absorbing: tt._grey_medium(scene.material.medium, c, absorbing)  # noqa: E731
    chunks = mitsuba_truth(mi, scene, medium, ply, spec.spp, args.chunks, args.interface)
    profile = mitsuba_truth(mi, scene, medium, ply, spec.profile_spp, args.chunks, args.interface,
                            sensor=crop_sensor(mi, scene.camera, crop), first_seed=1000)
    seconds = time.perf_counter() - t0
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez(str(path) + ".part.npz", chunks=chunks, profile=profile, lambert=lambert, seconds=seconds,
             variant=mi.variant())
    os.replace(str(path) + ".part.npz", path)  # a killed run leaves no truncated cache entry
    print(f"  Mitsuba {mi.variant()} ({kind}): {seconds:.0f} s, cached in {path}")
    return chunks, profile, lambert, seconds, mi.variant()


# --------------------------------------------------------------------------- comparison


def profile_pixels(spec, scene, inner):
    """(row, columns) of the profile: the checker's row through the lamp's foot within
    EDGE_WINDOW of the x = 0 edge, the sphere's middle row; interior pixels only."""
    buffers = camera_buffers(scene.mesh, scene.camera)
    position = np.asarray(buffers.position)
    if spec.shape == "plane":
        ys = np.array([position[r][inner[r], 1].mean() if inner[r].any() else np.inf for r in range(inner.shape[0])])
        row = int(np.argmin(np.abs(ys - LAMP[1])))
        columns = np.flatnonzero(inner[row] & (np.abs(position[row, :, 0]) <= EDGE_WINDOW))
    else:
        row = scene.camera.height // 2
        columns = np.flatnonzero(inner[row])
    return row, columns, position


def pixel_noise(per_chunk, inner):
    """Each pixel's relative standard error of Mitsuba's mean (H, W, 3).

    A few chunks give each pixel's variance with few degrees of freedom, and keeping the
    pixels whose estimate is below a limit would keep those whose noise was *under*-estimated;
    so the relative variance is pooled over the pixel's 3 x 3 interior neighbours (4 chunks:
    27 degrees of freedom, the standard error known to about 14 %).
    """
    from scipy.ndimage import uniform_filter

    chunks = per_chunk.shape[0]
    mean = per_chunk.mean(0)
    relative = per_chunk.var(0, ddof=1) / chunks / np.maximum(mean * mean, 1e-300)
    weight = inner.astype(float)
    pooled = np.stack([uniform_filter(relative[..., c] * weight, 3, mode="constant") for c in range(3)], -1)
    pooled /= np.maximum(uniform_filter(weight, 3, mode="constant"), 1e-12)[..., None]
    return np.where(inner[..., None], np.sqrt(np.maximum(pooled, 0.0)), np.inf)


@dataclasses.dataclass
class Truth:
    frame: np.ndarray  # (H, W, 3) Mitsuba's mean
    sum_noise: np.ndarray  # (3,) relative standard error of the sums over the interior pixels
    line: np.ndarray  # (n, 3) along the profile, from the crop's frames (more samples)
    line_noise: np.ndarray  # (n, 3) relative standard error per pixel


def truth_of(chunks, profile, inner, crop, row, columns):
    y0, rows, x0, width = crop
    noise = pixel_noise(profile, inner[y0:y0 + rows, x0:x0 + width])
    return Truth(chunks.mean(0), sum_noise(chunks, inner), profile.mean(0)[row - y0, columns - x0],
                 noise[row - y0, columns - x0])


def compare(ours, truth, inner, row, columns):
    """Per channel: sum ratio, max |pixel error| on the profile where noise < 3 %, pixels counted,
    and the per-pixel ratios along the profile."""
    ratio = ours[inner].sum(0) / truth.frame[inner].sum(0)
    line_ratio = ours[row, columns] / truth.line
    good = truth.line_noise < NOISE_LIMIT
    worst = np.where(good, np.abs(line_ratio - 1), -np.inf).max(0)
    return ratio, worst, good.sum(0), line_ratio


def sum_noise(per_chunk, inner):
    truth = per_chunk.mean(0)
    chunk_ratios = np.array([c[inner].sum(0) / truth[inner].sum(0) for c in per_chunk])
    return chunk_ratios.std(0, ddof=1) / np.sqrt(len(per_chunk))


def checker_control(spec, paths, profile, method, position, inner):
    """The checker as two homogeneous materials, composed pixel by pixel (no light crosses the edge)."""
    frames = {kind: tt._ours(load_scene(paths[kind, profile]), method)[0] for kind in ("A", "B")}
    u, v = surface_uv("plane", position)
    is_a = (u < 0.5) != (v < V_EDGE)
    return np.where(is_a[..., None], np.asarray(frames["A"]), np.asarray(frames["B"]))


def method_label(method):
    return f"{method.value} 128 spp" if method == Method.IMAGE_SPACE else method.value


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", 
                        help="48 x 36 and 40 x 30 pixels, 2 chunks x 64 spp: a smoke run")
    parser.add_argument("--spp", type=int, default=None,
                        help="path-tracer samples per pixel per chunk, whole frames (default: plane 256, sphere 128)")
    parser.add_argument("--profile-spp", type=int, default=None,
                        help="the same on the profile's three rows (default: plane 4096, sphere 1024)")
    parser.add_argument("--chunks", type=int, default=None, help="independent seeds (default 4)")
    parser.add_argument("--size", type=int, nargs=2, default=None, metavar=("W", "H"),
                        help="both scenes' pixels (default: the plane 64 x 48, the sphere 48 x 36)")
    parser.add_argument("--scenes", nargs="*", default=["checker_plane", "gradient_sphere"],
                        choices=["checker_plane", "gradient_sphere"])
    parser.add_argument("--profiles", nargs="*", default=["transport", "dipole"], choices=["dipole", "transport"])
    parser.add_argument("--methods", nargs="*", default=[Method.TEXTURE_SPACE.value, Method.IMAGE_SPACE.value])
    parser.add_argument("--interface", default="index-matched", choices=["index-matched", "dielectric"],
                        help="index-matched: eta 1 on both sides (low path-tracer noise); dielectric: eta 1.5, "
                             "rough dielectrics extrapolated to smooth (noisy: sums only)")
    parser.add_argument("--variant", default="auto", choices=["auto", "llvm_ad_rgb", "scalar_rgb"])
    parser.add_argument("--cache", default=os.path.join(tempfile.gettempdir(), "jsss_textured_truth"))
    parser.add_argument("--truth-only", action="store_true", help="path trace (fill the cache) and stop")
    parser.add_argument("--homogeneous", action="store_true",
                        help="also each scene as homogeneous marble and skin1 (no maps), in Mitsuba and jsss: "
                             "the baseline error of each material without maps")
    parser.add_argument("--no-doc", action="store_true", help=f"do not write {DOC.relative_to(HERE.parent)}")
    args = parser.parse_args(argv)
    quick = args.quick
    sizes = {"plane": (48, 36), "sphere": (40, 30)} if quick else {"plane": (64, 48), "sphere": (48, 36)}
    if args.size:
        sizes = {shape: tuple(args.size) for shape in sizes}
    spp = {"plane": 64, "sphere": 64} if quick else {"plane": 256, "sphere": 128}
    profile_spp = {"plane": 256, "sphere": 256} if quick else {"plane": 4096, "sphere": 1024}
    args.chunks = args.chunks or (2 if quick else 4)
    args.eta = 1.0 if args.interface == "index-matched" else 1.5
    methods = [Method(m) for m in args.methods]
    specs = {name: Spec(name, shape, texels, *sizes[shape], args.spp or spp[shape],
                        args.profile_spp or profile_spp[shape])
             for name, shape, texels in (("checker_plane", "plane", (256, 256)),
                                         ("gradient_sphere", "sphere", (256, 128)))}
    header = (f"textured truth: Mitsuba heterogeneous medium (gridvolume from the maps), volpath, one grey medium "
              f"per channel, {args.interface} (eta {args.eta:g}), {args.chunks} chunks; "
              + "; ".join(f"{s.name} {s.width}x{s.height} px, {s.spp} spp (the profile's rows {s.profile_spp} spp)"
                          for s in specs.values() if s.name in args.scenes)
              + f", {time.strftime('%Y-%m-%d')}")
    print(header)
    rows, notes, profiles_md, lines_of = [], [], [], {}
    with tempfile.TemporaryDirectory() as folder:
        for name in args.scenes:
            spec = specs[name]
            paths = write_inputs(spec, folder, args.eta, args.profiles)
            control_scene = load_scene(paths["A", args.profiles[0]])  # geometry, camera, lights: no maps needed
            print(f"\n## {name}")
            inner = tt._interior(camera_buffers(control_scene.mesh, control_scene.camera).mask)
            row, columns, position = profile_pixels(spec, control_scene, inner)
            y0, x0 = max(row - 1, 0), max(columns.min() - 1, 0)
            crop = (y0, min(row + 2, spec.height) - y0, x0, min(columns.max() + 2, spec.width) - x0)
            truths = {}
            for kind in ("maps", "A", "B") if args.homogeneous else ("maps",):
                scene = control_scene if kind == "maps" else load_scene(paths[kind, args.profiles[0]])
                chunks, profile, lambert, seconds, variant = cached_truth(spec, folder, scene, args, kind, crop)
                truths[kind] = truth = truth_of(chunks, profile, inner, crop, row, columns)
                what = "" if kind == "maps" else f" (homogeneous {MATERIAL_NAMES[kind]})"
                notes.append(f"- {name}{what}: Mitsuba {variant} {seconds:.0f} s"
                             + ("; white Lambertian jsss / Mitsuba - 1 = "
                                + " / ".join(f"{100 * x:+.2f} %" for x in lambert) if kind == "maps" else "")
                             + "; noise on the sums " + " / ".join(f"{100 * x:.2f} %" for x in truth.sum_noise)
                             + f"; profile: row {row}, {len(columns)} pixels, {args.chunks} x {spec.profile_spp} spp, "
                             "median noise per pixel " + " / ".join(f"{100 * x:.1f} %"
                                                                  for x in np.median(truth.line_noise, 0))
                             + "; the whole frame's mean over the profile / the crop's: "
                             + " / ".join(f"{x:.3f}" for x in truth.frame[row, columns].sum(0) / truth.line.sum(0)))
                print(notes[-1][2:])
            if args.truth_only:
                continue
            kinds = ["maps"] + (["control"] if spec.shape == "plane" else []) + (["A", "B"] if args.homogeneous else [])
            for kind in kinds:
                truth = truths["maps" if kind == "control" else kind]
                for profile in args.profiles:
                    for method in methods:
                        t0 = time.perf_counter()
                        try:
                            if kind == "control":
                                ours = checker_control(spec, paths, profile, method, position, inner)
                            else:
                                ours = np.asarray(tt._ours(load_scene(paths[kind, profile]), method)[0])
                        except Exception as error:  # noqa: BLE001 -- maps not supported yet: say so, carry on
                            message = f"{type(error).__name__}: {str(error).splitlines()[0][:200]}"
                            print(f"  jsss {method.value} {profile} {kind}: {message}")
                            rows.append((name, method_label(method), profile, kind, None, message))
                            continue
                        ratio, worst, counted, line_ratio = compare(ours, truth, inner, row, columns)
                        print(f"  jsss {method.value} {profile} {kind}: {time.perf_counter() - t0:.0f} s, "
                              "sums / Mitsuba " + " / ".join(f"{x:.3f}" for x in ratio), flush=True)
                        rows.append((name, method_label(method), profile, kind,
                                     (ratio, worst, counted, truth.sum_noise, np.median(truth.line_noise, 0)), None))
                        if method == methods[0] and profile == args.profiles[0]:
                            lines_of[name, kind] = line_ratio
            if (name, "maps") in lines_of:
                truth = truths["maps"]
                profiles_md.append((name, row, position[row, columns], truth.line, truth.line_noise,
                                    lines_of[name, "maps"], lines_of.get((name, "control"))))
    table = ["| scene | method | profile | jsss | channel | sum ratio | max abs pixel error on the profile "
             "(noise < 3 %, pixels) | Mitsuba noise on the sum | Mitsuba noise per pixel on the profile (median) |",
             "|---|---|---|---|---|---:|---:|---:|---:|"]
    for name, method, profile, kind, numbers, failed in rows:
        label = {"maps": "maps", "control": "control: two homogeneous, composed",
                 "A": f"homogeneous {MATERIAL_NAMES['A']} (no maps)",
                 "B": f"homogeneous {MATERIAL_NAMES['B']} (no maps)"}[kind]
        if failed:
            table.append(f"| {name} | {method} | {profile} | {label} | - | - | {failed} | - | - |")
            continue
        ratio, worst, counted, noise, median = numbers
        for c, channel in enumerate("RGB"):
            shown = f"{100 * worst[c]:.1f} % ({counted[c]})" if counted[c] else "no pixel below 3 % noise"
            table.append(f"| {name} | {method} | {profile} | {label} | {channel} | {ratio[c]:.3f} | {shown} | "
                         f"{100 * noise[c]:.2f} % |")
    print("\n" + "\n".join(table))
    lines = []
    for name, row, where, theirs, line_noise, ratio, control in profiles_md:
        lines += [f"\n{name}, pixels along row {row}: x [mm], Mitsuba's radiance and its noise per pixel, jsss / "
                  f"Mitsuba ({methods[0].value}, {args.profiles[0]} profile)"
                  + (", and the control's (two homogeneous frames composed: no light crosses the edge)"
                     if control is not None else "") + ":\n",
                  "| x mm | Mitsuba R | G | B | noise R | G | B | jsss / Mitsuba R | G | B |"
                  + (" control R | G | B |" if control is not None else ""),
                  "|---:|---:|---:|---:|---:|---:|---:|---:|---:|---:|"
                  + ("---:|---:|---:|" if control is not None else "")]
        for i in range(len(where)):
            lines.append(f"| {where[i, 0]:+.1f} | " + " | ".join(f"{x:.4g}" for x in theirs[i]) + " | "
                         + " | ".join(f"{100 * x:.1f} %" for x in line_noise[i]) + " | "
                         + " | ".join(f"{x:.3f}" for x in ratio[i]) + " |"
                         + ("".join(f" {x:.3f} |" for x in control[i]) if control is not None else ""))
    if lines:
        print("\n".join(lines))
    if not args.no_doc and not args.truth_only:
        write_doc(header, notes, table, lines, argv)


def write_doc(header, notes, table, lines, argv):
    command = "python benchmarks/textured_truth.py " + " ".join(argv if argv is not None else sys.argv[1:])
    text = [f"# Textured materials against a heterogeneous path tracer ({time.strftime('%Y-%m-%d')})", "",
            f"`{command.strip()}` (see the script's docstring for the scenes and the method).", "",
            header + ".", "", *notes, "", *table, *lines, ""]
    DOC.parent.mkdir(parents=True, exist_ok=True)
    DOC.write_text("\n".join(text))
    print(f"\nwritten to {DOC}")


if __name__ == "__main__":
    main()
