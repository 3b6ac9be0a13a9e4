"""`jsss-render fit` on path-traced photos taken through the real interface, with a grey card in the frame.

    pip install -e '.[truth]' && PYTHONPATH=. python benchmarks/inverse_dielectric.py
        [--size 160 120] [--spp 256] [--chunks 4] [--cache DIR] [--markdown docs/benchmarks/inverse_dielectric.md]

Issue 36's held-out case, as a photographer has it. The "photo" is Mitsuba 3's volumetric
path tracing (``volpath``) of an example scene with nothing taken out: the object's own
rough dielectric (Beckmann, the scene's roughness as alpha and its eta), so the photo holds
the specular highlight and the subsurface light as it crosses a rough boundary both ways,
plus a grey card (a Mitsuba ``diffuse`` of reflectance 0.18) beside the object, in the same
light. Nothing in the photo comes from jsss's profiles, lobes or Fresnel terms. The medium is
one grey medium per colour channel (``sigma_s = sigma_s'``, g = 0; see
``transport_truth._grey_medium``), so each channel is its own render.

A point or directional light is reached through a dielectric only where a path leaves the
surface (next-event estimation at the exit vertex, through the rough lobe), so the photo is
noisy: at 80 x 60 and 64 spp, 60 % per pixel on the marble sphere and 180 % in the ketchup
plane's red (2026-12-07). ``--spp`` is per chunk and channel; a channel noisier than
``--target-noise`` at the first chunk gets more samples (``--max-spp``).

The fit is the command as a user runs it, with default flags and the card as its exposure::

    jsss-render fit start.toml photo.exr --reference-scene card.toml --reference-reflectance 0.18 --json

``start.toml`` is the photo's scene with the material as a user who does not know it writes it:
coefficients, not the example's name, at twice the true absorption and two thirds of the
scattering (``START``). Started at the truth, a fit that stops early would look exact: until
2026-12-08 the fits here started there.

(the noise estimated from the photo, Huber's loss, the highlight handled as ``auto`` decides,
the scene's profile ``auto``), then once more with ``--fit-gain`` in place of the card: the
issue asks that a photo without a reference gives ``converged: false`` and the advice, never a
finite R_d error that misses the truth by more than 3 errors. The truth is the scene's medium:
R_d from the transport tables (exact to transport, g = 0) and the mean free path
1 / sigma_t'. Printed and written (``--markdown``): per scene and channel, the fitted / true
- 1 and its distance in stated errors (z).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import trimesh

sys.path.insert(0, os.path.dirname(__file__))
sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import transport_truth as tt  # also enables float64
from inverse_rendering import true_artist_parameters

from jsss.render import load_scene
from jsss.render.image_space import camera_buffers
from measure.exr import write_exr

ROOT = Path(__file__).resolve().parents[1]
CARD_REFLECTANCE = 0.18
KEPT = "## What it shows"  # the page's hand-kept section, which --markdown keeps
# Where each scene's card stands [mm] and its side: in the frame, clear of the object's
# silhouette, neither shadowing the object nor shadowed by it (checked when the photo is made).
CARDS = {"marble_sphere": ((-29.0, -8.0, -16.0), 8.0), "ketchup_plane": ((-36.0, 0.0, 3.0), 8.0)}


# The interface's Beckmann roughness in the photo (and so in the scene given to the fit).
# Mitsuba's rough dielectric scatters once off the microsurface, so it loses the light that
# real microfacets scatter again: a non-absorbing sphere (eta 1.5) in a white furnace reads
# 0.920 at alpha 0.25, 0.969 at 0.15, 0.987 at 0.1, 0.997 at 0.05 (2026-12-07). A white stone
# with many internal reflections loses that much of R_d, which no physical surface does, so
# marble's photo is taken at 0.1 rather than the example's 0.25. Ketchup keeps its 0.15.
ROUGHNESS = {"marble_sphere": 0.1, "ketchup_plane": 0.15}

# The fit's start: the true sigma_a and sigma_s' times these (tests/fitting/test_render.py's too).
START = (2.0, 1 / 1.5)


def start_text(text: str, scene) -> str:
    """The scene's TOML with the named material replaced by explicit coefficients at ``START``."""
    medium = scene.material.medium
    coefficients = (f"sigma_a = {[float(f'{v:.6g}') for v in START[0] * np.asarray(medium.sigma_a, float)]}\n"
                    f"sigma_s_prime = {[float(f'{v:.6g}') for v in START[1] * np.asarray(medium.sigma_s_prime, float)]}\n"
                    f"eta = {float(np.asarray(medium.eta, float).mean()):.6g}\n")
    text, n = re.subn(r'name\s*=\s*"[^"]*"\n', coefficients, text, count=1)
    assert n == 1, "the example names no material to replace"
    return text


def scene_text(name: str, width: int, height: int) -> str:
    """The example's TOML with the camera's resolution set to ``width`` x ``height`` and the
    surface's roughness to the photo's (``ROUGHNESS``)."""
    text = (ROOT / "examples" / f"{name}.toml").read_text()
    text, n = re.subn(r"resolution\s*=\s*\[[^\]]*\]", f"resolution = [{width}, {height}]", text)
    text, m = re.subn(r"roughness\s*=\s*[0-9.]+", f"roughness = {ROUGHNESS[name]}", text)
    assert n == 1 and m == 1, f"{name}: no single camera resolution or roughness to replace"
    return text


def card_files(name: str, scene, text: str, folder: Path) -> tuple[Path, Path]:
    """Write the card (``card.obj``: a square facing between the light and the camera) and its
    scene ``card.toml`` (the photo's camera and lights, the card as a mesh). Returns both paths."""
    center, side = CARDS[name]
    center = np.asarray(center, float)
    light = scene.lights[0]
    toward_light = (-np.asarray(light.direction, float) if light.kind == "directional"
                    else np.asarray(light.position, float) - center)
    toward_camera = np.asarray(scene.camera.position, float) - center
    normal = toward_light / np.linalg.norm(toward_light) + toward_camera / np.linalg.norm(toward_camera)
    normal /= np.linalg.norm(normal)
    u = np.cross(normal, [0.0, 0.0, 1.0])
    u /= np.linalg.norm(u)
    v = np.cross(normal, u)
    corners = [center + side / 2 * (a * u + b * v) for a, b in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    obj = folder / "card.obj"
    faces = "f 1 2 3\nf 1 3 4\n" if np.dot(np.cross(corners[1] - corners[0], corners[2] - corners[0]), normal) > 0 \
        else "f 1 3 2\nf 1 4 3\n"
    obj.write_text("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in corners) + faces)
    card = re.sub(r"\[geometry\][^\[]*", '[geometry]\nshape = "mesh"\npath = "card.obj"\n\n', text, count=1)
    toml = folder / "card.toml"
    toml.write_text(f"# The grey card beside {name} (reflectance {CARD_REFLECTANCE}), as photographed.\n" + card)
    return toml, obj


def object_files(scene, folder: Path) -> tuple[str, Path | None]:
    """The object as Mitsuba's PLY files: ``(surface, None)``, or for an open plane ``(top, sides)``.

    jsss's plane is the open top of a half-space. Mitsuba needs a closed surface around a
    medium, so the plane is the top face of a box 30 mm deep (`transport_truth._mesh_file`);
    through a dielectric its walls would hold light in by total internal reflection and send it
    back up near the rim, which no open plane does. So only the top is the rough dielectric;
    the walls and the floor are index-matched (``null``), and black curtains outside them
    (`transport_truth._wall_curtains`) take what leaves there.
    """
    box = trimesh.load(tt._mesh_file(scene, str(folder)))
    if np.ptp(scene.mesh.vertices[:, 2]) >= 1e-9:
        return str(folder / "object.ply"), None
    top = box.face_normals[:, 2] > 0.5
    box.submesh([np.flatnonzero(top)], append=True).export(folder / "top.ply")
    box.submesh([np.flatnonzero(~top)], append=True).export(folder / "sides.ply")
    return str(folder / "top.ply"), folder / "sides.ply"


def photo(mi, name, scene, card_obj, folder, *, spp, chunks, max_spp, target_noise, cache):
    """The path-traced photo (H, W, 3) and each pixel's standard error, from ``cache`` or Mitsuba."""
    cam = scene.camera
    (x, y, z), side = CARDS[name]  # in the key: a moved card or another roughness is another photo
    key = Path(cache) / (f"{name}_dielectric_card_{cam.width}x{cam.height}_{chunks}x{spp}-{max_spp}"
                         f"_m{scene.material.roughness:g}_card{x:g},{y:g},{z:g},{side:g}.npz")
    if key.exists():
        data = np.load(key)
        return data["photo"], data["stderr"], float(data["seconds"])
    eta = float(np.asarray(scene.material.eta).mean())
    bsdf = {"type": "roughdielectric", "distribution": "beckmann", "alpha": float(scene.material.roughness),
            "int_ior": eta, "ext_ior": 1.0}
    grey = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [CARD_REFLECTANCE] * 3}}
    card = {"type": "obj", "filename": str(card_obj), "face_normals": True, "bsdf": grey}
    ply, sides = object_files(scene, folder)
    object_pixels = camera_buffers(scene.mesh, cam).mask.astype(bool)

    def relative_noise(frames):  # each frame's noise per pixel, the median over the object
        return np.median(frames.std(0, ddof=1)[object_pixels] / np.maximum(frames.mean(0)[object_pixels], 1e-12))
    tt.BLACK_WALLS = True  # curtains around a plane's walls (nothing else has walls)
    t0 = time.perf_counter()
    mean, stderr = [], []
    for c in range(3):
        medium = tt._grey_medium(scene.material.medium, c)
        extra = {"card": card}
        if sides is not None:  # an open plane: the medium meets the walls and floor index-matched
            extra["sides"] = {"type": "ply", "filename": str(sides), "face_normals": True,
                              "bsdf": {"type": "null"}, "interior": medium}
        mscene = tt._mitsuba_scene(mi, scene, ply, bsdf, medium, extra=extra)
        first = np.array([tt._render(mi, mscene, spp, seed)[..., c] for seed in range(chunks)])
        noise = relative_noise(first)
        scale = int(min(max_spp // spp, max(1, np.ceil((noise / np.sqrt(chunks) / target_noise) ** 2))))
        frames = first if scale == 1 else (first + (scale - 1) * np.array(  # the first pass is kept
            [tt._render(mi, mscene, spp * (scale - 1), chunks + seed)[..., c] for seed in range(chunks)])) / scale
        per_pixel = relative_noise(frames)
        print(f"  {name} channel {'RGB'[c]}: {chunks} x {spp * scale} spp, {100 * per_pixel / np.sqrt(chunks):.0f} % "
              f"noise per pixel (median over the object)", flush=True)
        mean.append(frames.mean(0))
        stderr.append(frames.std(0, ddof=1) / np.sqrt(chunks))
    seconds = time.perf_counter() - t0
    image, error = np.stack(mean, -1), np.stack(stderr, -1)
    os.makedirs(cache, exist_ok=True)
    np.savez(str(key) + ".part.npz", photo=image, stderr=error, seconds=seconds)
    os.replace(str(key) + ".part.npz", key)  # a killed run leaves no truncated cache entry
    return image, error, seconds


def fit(folder: Path, flags: list[str], out: str) -> tuple[dict | None, int, str, float]:
    """Run ``jsss-render fit`` as a user does, writing to ``folder/out``; returns (its JSON or
    None, exit code, stderr, seconds)."""
    t0 = time.perf_counter()
    run = subprocess.run([sys.executable, "-m", "measure.commands.render", "fit", "start.toml", "photo.exr",
                          *flags, "--json", "-o", out], cwd=folder, capture_output=True, text=True,
                         env=os.environ | {"PYTHONPATH": str(ROOT)}, check=False)
    seconds = time.perf_counter() - t0
    try:
        result = json.loads(run.stdout)
    except json.JSONDecodeError:
        result = None
    return result, run.returncode, run.stderr.strip(), seconds


def compare(result, truth_rd, truth_mfp):
    """Per channel: (R_d off, its z, mfp off, its z), relative; z is NaN where the error is infinite."""
    out = []
    for key, truth in (("reflectance", truth_rd), ("mean_free_path_mm", truth_mfp)):
        value = np.asarray(result[key], float)
        error = np.asarray([np.inf if e is None else e for e in result[key.replace("_mm", "") + "_err" +
                                                                     ("_mm" if key.endswith("_mm") else "")]], float)
        off = value / truth - 1
        z = np.where(np.isfinite(error) & (error > 0), (value - truth) / np.where(error > 0, error, 1), np.nan)
        out.append((off, z, error / truth))
    return out


def _row(name, label, result, code, seconds, truth):
    if result is None:
        return f"| {name} | {label} | exit {code}, no JSON | | | | |"
    (rd, rd_z, rd_rel), (mfp, mfp_z, mfp_rel) = compare(result, *truth)

    def cells(off, z, rel):
        return " / ".join(f"{100 * o:+.1f} % ({'inf' if not np.isfinite(r) else f'{100 * r:.1f} %'}, "
                          f"z {'-' if not np.isfinite(zz) else f'{zz:+.1f}'})" for o, zz, r in zip(off, z, rel))
    highlight = result.get("highlight")
    if highlight == "fit":
        highlight = f"fit: m {result['roughness']:.3g} +- {result['roughness_err']:.2g}"
    return (f"| {name} | {label} | {cells(rd, rd_z, rd_rel)} | {cells(mfp, mfp_z, mfp_rel)} | "
            f"{result['converged']} (exit {code}) | {highlight} | {result['profile_model']}, "
            f"chi2/dof {result['chi2_reduced']:.3g} | {seconds:.0f} |")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--size", type=int, nargs=2, default=(160, 120), metavar=("W", "H"))
    parser.add_argument("--spp", type=int, default=256, help="samples per pixel per chunk and channel (first pass)")
    parser.add_argument("--chunks", type=int, default=2, help="independent renders per channel (the noise)")
    parser.add_argument("--target-noise", type=float, default=0.2,
                        help="a channel noisier per pixel than this after the first pass gets more samples")
    parser.add_argument("--max-spp", type=int, default=4096, help="at most this many spp per chunk")
    parser.add_argument("--scenes", nargs="*", default=list(CARDS))
    parser.add_argument("--cache", default=os.path.join(tempfile.gettempdir(), "jsss_inverse_dielectric"))
    parser.add_argument("--variant", default="auto", choices=["auto", "llvm_ad_rgb", "scalar_rgb"])
    parser.add_argument("--markdown", default=None, help="write the table to this page")
    args = parser.parse_args(argv)
    width, height = args.size
    mi = tt._mitsuba(args.variant)
    today = datetime.date.today().isoformat()
    rows, notes = [], []
    for name in args.scenes:
        folder = Path(args.cache) / f"{name}_{width}x{height}"
        folder.mkdir(parents=True, exist_ok=True)
        text = scene_text(name, width, height)
        (folder / "scene.toml").write_text(text)
        scene = load_scene(folder / "scene.toml")
        (folder / "start.toml").write_text(start_text(text, scene))
        card_toml, card_obj = card_files(name, scene, text, folder)
        card_pixels = camera_buffers(load_scene(card_toml).mesh, scene.camera).mask.astype(bool)
        overlap = int((card_pixels & camera_buffers(scene.mesh, scene.camera).mask.astype(bool)).sum())
        assert card_pixels.sum() >= 30 and overlap == 0, f"{name}: card has {card_pixels.sum()} pixels, {overlap} on the object"
        image, stderr, seconds = photo(mi, name, scene, card_obj, folder, spp=args.spp, chunks=args.chunks,
                                       max_spp=args.max_spp, target_noise=args.target_noise, cache=args.cache)
        write_exr(folder / "photo.exr", image.astype(np.float32))
        inside = camera_buffers(scene.mesh, scene.camera).mask.astype(bool)
        noise = np.median(stderr[inside] / np.maximum(np.abs(image[inside]), 1e-12), axis=0)
        notes.append(f"{name}: photo {seconds:.0f} s of path tracing ({mi.variant()}); noise per pixel R / G / B "
                     + " / ".join(f"{100 * n:.0f} %" for n in noise) + f" (median over the object); card {card_pixels.sum()} pixels")
        truth = true_artist_parameters(scene.material)
        for label, out, flags in (("card in the frame", "fitted_card", ["--reference-scene", "card.toml",
                                                                       "--reference-reflectance", str(CARD_REFLECTANCE)]),
                                  ("no reference (`--fit-gain`)", "fitted_gain", ["--fit-gain"])):
            result, code, said, secs = fit(folder, flags, out)
            if result is None:
                print(said[-2000:], file=sys.stderr)
            rows.append(_row(name, label, result, code, secs, truth))
            if result is not None:
                gain_err = "inf" if result["gain_err"] is None else f"{result['gain_err']:.2g}"
                notes.append(f"{name}, {label}: gain {result['gain']:.4g} +- {gain_err}; "
                             f"warnings: {'; '.join(result['warnings']) or 'none'}"
                             + (f"; last line: {said.splitlines()[-1]}" if said else ""))
            print(rows[-1], flush=True)
    header = (f"# `jsss-render fit` through the real interface, a grey card in the frame, {today}\n\n"
              f"`PYTHONPATH=. python benchmarks/inverse_dielectric.py --size {width} {height} --spp {args.spp} "
              f"--chunks {args.chunks}` ({os.cpu_count()} cores, {platform.machine()}, CPU). Truth: the scene's "
              "medium (R_d from the transport tables, g = 0; mean free path 1 / sigma_t'); the photo is Mitsuba 3 "
              "`volpath` through the object's rough dielectric with a grey card (0.18) beside it, nothing jsss "
              "computed. The fit starts at 2x the true sigma_a and 2/3 of its sigma_s' (`start.toml`, the material as coefficients). Each cell: fitted / true - 1 (stated relative error, z = distance in stated errors) for "
              "R / G / B. Issue 36 asks, with the card and default flags, R_d within 3 % and the mean free path "
              "within 15 % wherever the fit calls them constrained, |z| <= 3; without a reference, "
              "`converged: false` and no finite R_d error that misses by more than 3 errors.\n\n"
              "| scene | exposure | R_d R / G / B | mean free path R / G / B | converged | highlight | profile, chi2/dof | s |\n"
              "|---|---|---|---|---|---|---|---:|\n")
    page = header + "\n".join(rows) + "\n\n" + "\n".join(f"- {n}" for n in notes) + "\n"
    print(page)
    if args.markdown:
        kept = Path(args.markdown).read_text() if Path(args.markdown).exists() else ""
        kept = kept[kept.index(KEPT):] if KEPT in kept else ""
        Path(args.markdown).write_text(page + ("\n" + kept if kept else ""))


if __name__ == "__main__":
    main()
