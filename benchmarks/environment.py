"""Environment light: irradiance tables against brute force, a white furnace, and spheres against Mitsuba 3.

    python benchmarks/environment.py [--quick] [--spp N] [--markdown docs/benchmarks/environment.md]

1. **Irradiance per normal** (truth: brute-force integration over every pixel of the
   256 x 512 map, NumPy, no shared code with the tables but the Fresnel equations):
   jsss's prefiltered map (:mod:`jsss.render.environment`) against Ramamoorthi & Hanrahan's
   9 spherical-harmonic coefficients, on 2000 normals spread over the sphere, at eta 1.3.
   Relative error per normal (RMS and worst), the time to build each from the map, and the
   time per frame of 10^5 points.
2. **Furnace** (truth: conservation): a non-absorbing sphere (eta 1.0 / 1.3 / 1.5, one per
   channel) under a uniform white environment returns radiance 1 at every pixel the sphere
   covers fully, with the specular reflection on. Worst pixel per method and channel, with
   the single-scattering pass off and on.
3. **Spheres against Mitsuba 3** (truth: a volumetric path tracer): marble and skin1
   spheres, index-matched (eta 1: a ``null`` boundary, so ``volpath`` connects every
   scattering vertex to the environment), under the procedural ``sky`` and ``studio`` maps
   given to Mitsuba as the same EXR (``envmap``, turned into jsss's frame by ``to_world``),
   jsss with ``profile = "transport"``; the relative RMS is over the pixels lit above 5 % of
   the frame's 99th percentile, per channel; then the sky's sun alone, as a map and as a directional
   light (which separates the environment's own error from the per-light model's). Per channel: the ratio of summed radiance over the
   pixels both see fully, and the relative RMS per pixel, with the path tracer's own noise.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402

from benchmarks.transport_truth import _grey_medium, _interior, _mitsuba, _render  # noqa: E402
from jsss.materials import jensen2001  # noqa: E402
from jsss.render import Method, Pass, parse_scene, plan_scene, render  # noqa: E402
from jsss.render import environment as env_module  # noqa: E402
from jsss.render.image_space import camera_buffers  # noqa: E402
from measure.exr import write_exr  # noqa: E402

ETA = 1.3
MAPS = ("sky", "studio")


def irradiance_rows(shape=(256, 512), count=2000, points=100_000):
    """(map, method, rms, worst, build s, frame s) for the prefiltered map and SH9."""
    rows = []
    normals = env_module.fibonacci_directions(count)
    eta = jnp.full(3, ETA)
    many = env_module.fibonacci_directions(points)
    for name in MAPS:
        radiance = env_module.procedural_map(name, shape)
        truth = env_module.brute_force_irradiance(radiance, normals, ETA)
        env = env_module.Environment(radiance, source=name)
        start = time.perf_counter()
        shadows = env_module.environment_shadows(env)
        build = time.perf_counter() - start
        g = env_module.environment_geometry(normals, np.ones(count, bool), shadows).astype(jnp.float64)
        ours = np.asarray(env_module.environment_irradiance(g, jnp.ones(3), eta))
        g_many = env_module.environment_geometry(many, np.ones(points, bool), shadows).astype(jnp.float64)
        frame = jax.jit(lambda g, e: env_module.environment_irradiance(g, jnp.ones(3), e))
        frame(g_many, eta).block_until_ready()
        start = time.perf_counter()
        for _ in range(5):
            frame(g_many, eta).block_until_ready()
        per_frame = (time.perf_counter() - start) / 5
        rows.append((name, "prefiltered map", *_errors(ours, truth), build, per_frame))
        start = time.perf_counter()
        sh = env_module.sh9_irradiance(radiance, normals, ETA)
        rows.append((name, "SH, 9 coefficients", *_errors(sh, truth), time.perf_counter() - start, float("nan")))
    return rows


def _errors(estimate, truth):
    relative = estimate / truth - 1
    return float(np.sqrt(np.mean(relative**2))), float(np.max(np.abs(relative)))


def sphere_scene(material, light, resolution=(64, 64), *, texture_size=512, accuracy=0.02):
    """A 20 mm sphere seen from 110 mm under one light (the benchmark's and the tests' scene)."""
    return parse_scene({
        "geometry": {"shape": "sphere", "radius": 20.0},
        "material": material,
        "lights": [light],
        "camera": {"position": [0.0, -110.0, 20.0], "look_at": [0.0, 0.0, 0.0], "fov": 25,
                   "resolution": list(resolution)},
        "render": {"texture_size": texture_size, "accuracy": accuracy},
    }, allow_outside=True)


def _ours(scene, method, *, specular=False, samples=128, single=None):
    plan = plan_scene(scene, method=method, samples=samples if Method(method) == Method.IMAGE_SPACE else None)
    if not specular:
        plan = plan.replace(Pass.SPECULAR, False, "subsurface only")
    if single is not None:
        plan = plan.replace(Pass.SINGLE_SCATTERING, single, "benchmark")
    if plan.method == Method.TEXTURE_SPACE and not plan.on(Pass.DIFFUSION):
        plan = plan.replace(Pass.DIFFUSION, True, "benchmark: blur even below a pixel")
    return np.asarray(render(scene, plan, dtype=jnp.float64).radiance)


def furnace_rows(resolution=(64, 64)):
    """(method, single scattering, worst |L - 1| per channel, mean L - 1) over the pixels the
    sphere covers fully."""
    material = {"sigma_a": 0.0, "sigma_s_prime": [40.0, 60.0, 100.0], "eta": [1.0, 1.3, 1.5]}
    scene = sphere_scene(material, {"type": "environment"}, resolution)
    full = np.asarray(camera_buffers(scene.mesh, scene.camera).coverage) > 0.999
    rows = []
    for single in (False, True):
        for method in Method:
            radiance = _ours(scene, method.value, specular=True, samples=512, single=single)[full]
            rows.append((method.value, single, np.abs(radiance - 1).max(0), float(radiance.mean() - 1)))
    return rows


def _mitsuba_environment(mi, scene, path):
    """The scene's environment as Mitsuba's ``envmap``: jsss's frame (+z up, the map's centre
    toward +x) is Mitsuba's (+y up, centre toward +z... see below) turned by ``to_world``.

    Mitsuba reads direction l (local) at u = atan2(l_x, -l_z) / 2 pi, v = acos(l_y) / pi; jsss
    at u = 1/2 - atan2(w_y, w_x) / 2 pi, v = acos(w_z) / pi. They agree for l = (w_y, w_z, w_x),
    a rotation; ``rotation`` turns it about +z."""
    env = scene.lights[0]
    turn = np.radians(env.rotation)
    rz = np.array([[np.cos(turn), -np.sin(turn), 0, 0], [np.sin(turn), np.cos(turn), 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]])
    local_to_world = np.array([[0, 0, 1, 0], [1, 0, 0, 0], [0, 1, 0, 0], [0, 0, 0, 1]], float)
    return {"type": "envmap", "filename": path, "scale": float(env.intensity),
            "to_world": mi.ScalarTransform4f((rz @ local_to_world).tolist())}


def mitsuba_truth(mi, scene, map_path, ply, spp, chunks, *, emitter=None):
    """Index-matched subsurface radiance (H, W, 3) and each chunk's estimate (``emitter``: a
    Mitsuba emitter in place of the scene's environment)."""
    cam = scene.camera
    per_chunk = np.zeros((chunks, cam.height, cam.width, 3))
    for c in range(3):
        mscene = mi.load_dict({
            "type": "scene",
            "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": 100_000},
            "sensor": {"type": "perspective", "fov": cam.fov_degrees, "fov_axis": "y",
                       "to_world": mi.ScalarTransform4f().look_at(origin=list(cam.position),
                                                                   target=list(cam.look_at), up=list(cam.up)),
                       "film": {"type": "hdrfilm", "width": cam.width, "height": cam.height,
                                "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                       "sampler": {"type": "independent"}},
            "object": {"type": "ply", "filename": ply, "face_normals": True, "bsdf": {"type": "null"},
                       "interior": _grey_medium(scene.material.medium, c)},
            "light": emitter if emitter is not None else _mitsuba_environment(mi, scene, map_path)})
        for seed in range(chunks):
            per_chunk[seed, ..., c] = _render(mi, mscene, spp, seed)[..., c]
    return per_chunk.mean(0), per_chunk


def _cases(folder):
    """(label, light table for jsss, Mitsuba emitter factory) per lighting: the two maps, the sky's
    sun alone as a map, and the same sun as a directional light (Mitsuba's ``directional``)."""
    cases = []
    for name in MAPS:
        radiance = env_module.procedural_map(name)
        cases.append((name, radiance))
    sky = env_module.procedural_map("sky")
    sun = np.where(sky > 5.0, sky, 0.0)
    cases.append(("sky's sun alone", sun))
    out = []
    for label, radiance in cases:
        path = os.path.join(folder, f"{len(out)}.exr")
        write_exr(path, radiance.astype(np.float32))
        out.append((label, {"type": "environment", "map": path}, None))
    directions, solid = env_module.map_directions(sun.shape[:2])
    power = (sun * solid[..., None]).reshape(-1, 3).sum(0)
    centroid = (directions * (sun.mean(-1) * solid)[..., None]).reshape(-1, 3).sum(0)
    centroid /= np.linalg.norm(centroid)
    light = {"type": "directional", "direction": (-centroid).tolist(), "color": (power / power.max()).tolist(),
             "intensity": float(power.max())}
    out.append(("the sun as a directional light", light,
                {"type": "directional", "direction": (-centroid).tolist(),
                 "irradiance": {"type": "rgb", "value": power.tolist()}}))
    return out


def truth_rows(mi, folder, *, resolution, spp, chunks, methods):
    from benchmarks.transport_truth import _mesh_file

    rows = []
    for label, light, emitter in _cases(folder):
        for material in ("marble", "skin1"):
            medium = jensen2001(material)
            scene = sphere_scene({"sigma_a": np.asarray(medium.sigma_a, float).tolist(),
                             "sigma_s_prime": np.asarray(medium.sigma_s_prime, float).tolist(), "eta": 1.0,
                             "profile": "transport", "specular": 0.0}, light, resolution)
            ply = _mesh_file(scene, folder)
            start = time.perf_counter()
            truth, chunk = mitsuba_truth(mi, scene, light.get("map"), ply, spp, chunks, emitter=emitter)
            seconds = time.perf_counter() - start
            inner = _interior(camera_buffers(scene.mesh, scene.camera).mask)
            lit = inner[..., None] & (truth > 0.05 * np.percentile(truth[inner], 99, axis=0))  # per pixel: where lit
            # the path tracer's noise on the sum and per pixel, from its independent chunks
            sums = chunk[:, inner].sum(1)                                   # (chunks, 3)
            sum_noise = sums.std(0, ddof=1) / np.sqrt(chunks) / sums.mean(0)
            pixel_noise = np.array([np.sqrt(np.mean(chunk[:, lit[..., c], c].var(0, ddof=1) / chunks
                                                    / truth[lit[..., c], c] ** 2)) for c in range(3)])
            for method in methods:
                ours = _ours(scene, method)
                ratio = ours[inner].sum(0) / truth[inner].sum(0)
                rms = np.array([np.sqrt(np.mean((ours[lit[..., c], c] / truth[lit[..., c], c] - 1) ** 2))
                                for c in range(3)])
                rows.append((label, material, method, ratio, rms, sum_noise, pixel_noise, seconds))
    return rows


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="32 x 32 pixels, 2 chunks of 16 spp")
    parser.add_argument("--spp", type=int, default=64, help="path-tracer samples per pixel per chunk")
    parser.add_argument("--chunks", type=int, default=4)
    parser.add_argument("--resolution", type=int, nargs=2, default=(64, 64))
    parser.add_argument("--methods", nargs="*", default=["lambert", "texture-space", "image-space"])
    parser.add_argument("--no-mitsuba", action="store_true", help="parts 1 and 2 only")
    parser.add_argument("--only-mitsuba", action="store_true", help="part 3 only")
    parser.add_argument("--markdown", help="write the tables to this file as well")
    args = parser.parse_args(argv)
    if args.quick:
        args.resolution, args.spp, args.chunks = (32, 32), 16, 2
    out = [f"Environment light, {time.strftime('%Y-%m-%d')} (`python benchmarks/environment.py`)", ""]
    out += ["### Irradiance per normal against brute force (256 x 512 map, 2000 normals, eta 1.3)", "",
            "| map | method | RMS error | worst normal | build from the map [s] | frame of 10^5 points [ms] |",
            "|---|---|---:|---:|---:|---:|"]
    for name, method, rms, worst, build, frame in ([] if args.only_mitsuba else irradiance_rows()):
        shown = "-" if np.isnan(frame) else f"{1e3 * frame:.1f}"
        out.append(f"| {name} | {method} | {100 * rms:.2f} % | {100 * worst:.1f} % | {build:.2f} | {shown} |")
    print("\n".join(out), flush=True)
    part = ["", ("### White furnace: non-absorbing sphere (eta 1 / 1.3 / 1.5), uniform environment of radiance 1, "
                 "specular on"), "",
            ("With the single-scattering pass on, the first bounce leaves by its own lobe and the rest by the "
             "diffusion lobe; in a furnace the true multiple scattering makes up the difference angle by angle, "
             "the model does not (how much light leaves is still right: the mean)."), "",
            "| method | single scattering | worst pixel abs(L - 1), R / G / B | mean L - 1 |", "|---|---|---|---:|"]
    for method, single, worst, mean in ([] if args.only_mitsuba else furnace_rows()):
        part.append(f"| {method} | {'on' if single else 'off'} | {' / '.join(f'{x:.1e}' for x in worst)} | "
                    f"{mean:+.1e} |")
    print("\n".join(part), flush=True)
    out += part
    if not args.no_mitsuba:
        mi = _mitsuba()
        part = ["", (f"### Spheres against Mitsuba {mi.__version__} ({mi.variant()}), index-matched, "
                     f"{args.resolution[0]} x {args.resolution[1]}, {args.chunks} x {args.spp} spp"), "",
                ("| map | material | method | sum ratio R / G / B | relative RMS per pixel | path tracer noise: sum, "
                 "per pixel | Mitsuba s |"), "|---|---|---|---|---|---|---:|"]
        with tempfile.TemporaryDirectory() as folder:
            for name, material, method, ratio, rms, sum_noise, pixel_noise, seconds in truth_rows(
                    mi, folder, resolution=args.resolution, spp=args.spp, chunks=args.chunks, methods=args.methods):
                part.append(f"| {name} | {material} | {method} | {' / '.join(f'{x:.3f}' for x in ratio)} | "
                            f"{' / '.join(f'{100 * x:.1f}' for x in rms)} % | "
                            f"{100 * sum_noise.max():.1f} %, {100 * pixel_noise.max():.1f} % | {seconds:.0f} |")
                print(part[-1], flush=True)
        out += part
    if args.markdown:
        with open(args.markdown, "w") as handle:
            handle.write("\n".join(out) + "\n")


if __name__ == "__main__":
    main()
