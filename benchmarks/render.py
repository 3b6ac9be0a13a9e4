"""Texture-space diffusion: accuracy against brute-force convolution with the exact dipole, and time.

Tables:
1. Plane (uniform UVs), marble and ketchup under a point light with a straight shadow edge.
   Reference: the irradiance texture convolved with the exact dipole profile integrated over
   each texel (8 x 8 sub-samples), by FFT. Rows: number of Gaussians, texture size, step
   growth; columns: relative RMS error of the exitance, ms per frame (blur + combine), ratio
   to the reference convolution's time.
2. Sphere (stretched UVs): stretch correction on/off against a world-space brute-force sum
   over texel pairs (chord distance).
3. One blur chain at 1024^2 x 3 channels x 6 Gaussians against scipy.ndimage.gaussian_filter.
4. The example scenes' warm texture-space frames, and their blur chains against the memory-
   bandwidth bound: the bytes a chain must move at least (each step's two passes read and
   write the texture and its mask once) over the bandwidth of a large array copy measured in
   the same run.

Run: python benchmarks/render.py [--quick] [--only examples]
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time

import jax

jax.config.update("jax_enable_x64", True)
import jax.numpy as jnp  # noqa: E402
import numpy as np  # noqa: E402
from scipy.ndimage import gaussian_filter  # noqa: E402
from scipy.signal import fftconvolve  # noqa: E402

from jsss import dipole  # noqa: E402
from jsss.render import Pass, TextureSpace, load_scene, parse_scene, plan_scene, prepare, render_params  # noqa: E402
from jsss.render.blur import blur_schedule, hierarchical_blur  # noqa: E402
from jsss.render.profiles import choose_variances, shared_variances, full_profile  # noqa: E402

sys.path.insert(0, ".")
from benchmarks._timing import median_seconds  # noqa: E402


def plane_scene(name, size):
    return parse_scene({
        "geometry": {"shape": "plane", "width": 60.0},
        "material": {"name": name},
        "lights": [{"type": "point", "position": [10.0, -5.0, 30.0], "intensity": 1000.0}],
        "camera": {"position": [0.0, 0.0, 150.0], "up": [0, 1, 0], "resolution": [64, 64]},
        "render": {"texture_size": size, "accuracy": 0.05}})


def with_knobs(plan, *, variances=None, size=None, ratio=None, stretch=None):
    if stretch is not None:
        plan = plan.replace(Pass.STRETCH_CORRECTION, stretch, "benchmark")
    method = TextureSpace(size or plan.texture_size, plan.taps, ratio or plan.max_ratio)
    return dataclasses.replace(plan, variances=plan.variances if variances is None else variances,
                               method_config=method)


def diffused(plan, prep):
    """The texel exitance of ``plan``'s texture-space method as a jitted function of (params, irradiance)."""
    method = plan.method_config
    return jax.jit(lambda p, e: method.texel_exitance(p, prep, method.diffusion(p, prep, e)))


def texel_kernel(medium, texel, half):
    """Exact dipole profile integrated over each texel offset (8 x 8 sub-samples), per channel."""
    sub = (np.arange(8) + 0.5) / 8 - 0.5
    offs = np.arange(-half, half + 1)
    x = (offs[:, None] + sub[None, :]).reshape(-1) * texel
    r = np.sqrt(x[:, None] ** 2 + x[None, :] ** 2)
    R = np.asarray(dipole.profile(medium, jnp.asarray(r.reshape(-1)))).reshape(r.shape + (3,))
    n = len(offs)
    return R.reshape(n, 8, n, 8, 3).mean(axis=(1, 3)) * texel**2


def plane_table(quick):
    print("\n## Plane, point light and a straight shadow edge: error vs brute-force convolution\n")
    print("| material | Gaussians | texture | step growth | rel. RMS error | ms/frame | reference ms | ratio |")
    print("|---|---|---|---|---|---|---|---|")
    sizes = (128, 256) if quick else (128, 256, 512)
    for name in ("marble", "ketchup"):
        for size in sizes:
            scene = plane_scene(name, size)
            base = with_knobs(plan_scene(scene, method="texture-space"), size=size)
            prep = prepare(scene, base)
            params = render_params(scene, base, dtype=jnp.float32)
            x = prep.texels.position[..., 0]
            E = base.method_config.irradiance(params, prep) * (x > -5.0)[..., None]
            E64 = np.asarray(E, float)
            texel = 60.0 / size
            kern = texel_kernel(scene.material.medium, texel, size)
            ref_t = median_seconds(lambda: [fftconvolve(E64[..., c], kern[..., c], mode="same") for c in range(3)],
                                   repeats=3)
            ref = np.stack([fftconvolve(E64[..., c], kern[..., c], mode="same") for c in range(3)], -1)
            inner = (slice(size // 6, -size // 6),) * 2  # away from the plane's border (normalised blur there)
            full = full_profile(scene.material)
            counts = (2, 4, 6, 8) if size == sizes[-1] else (len(base.variances),)
            for n in counts:
                variances = shared_variances(full, n) if n != len(base.variances) else base.variances
                if n != len(base.variances):
                    variances = np.asarray(choose_variances(scene.material, 0.0, max_terms=n)[0].variances)
                for ratio in ((2.0, 4.0) if n == len(base.variances) else (2.0,)):
                    plan = with_knobs(base, variances=variances, ratio=ratio)
                    prep_n = prepare(scene, plan)
                    p = render_params(scene, plan, dtype=jnp.float32)
                    frame = diffused(plan, prep_n)
                    M = np.asarray(frame(p, E), float)
                    t = median_seconds(lambda: jax.block_until_ready(frame(p, E)), repeats=3)
                    err = np.sqrt(((M - ref)[inner] ** 2).mean() / (ref[inner] ** 2).mean())
                    print(f"| {name} | {len(variances)} | {size}^2 | {ratio:g}x | {100 * err:.2f} % | {1000 * t:.0f} | "
                          f"{1000 * ref_t:.0f} | {t / ref_t:.2f} |", flush=True)


def sphere_table():
    print("\n## Sphere (UV stretch varies 124 %): stretch correction against a world-space brute-force sum\n")
    print("| material | stretch correction | rel. RMS error | ms/frame |")
    print("|---|---|---|---|")
    for name in ("marble", "skin1"):
        scene = parse_scene({
            "geometry": {"shape": "sphere", "radius": 15.0}, "material": {"name": name},
            "lights": [{"type": "directional", "direction": [0.3, 1.0, -0.4]}],
            "camera": {"position": [0, -90, 0], "resolution": [64, 64]},
            "render": {"texture_size": 96, "accuracy": 0.05}})
        base = with_knobs(plan_scene(scene, method="texture-space"), size=96)
        prep = prepare(scene, base)
        params = render_params(scene, base, dtype=jnp.float64)
        E = np.asarray(base.method_config.irradiance(params, prep), float)
        m = prep.texels.mask
        pos, area = prep.texels.position[m], prep.texels.area[m]
        src = E[m] * area[:, None]
        ref = np.zeros_like(src)
        for start in range(0, len(pos), 512):  # chunked pair sum with chord distances
            d = np.linalg.norm(pos[start:start + 512, None] - pos[None], axis=-1)
            R = np.asarray(dipole.profile(scene.material.medium, jnp.asarray(d.reshape(-1)))).reshape(d.shape + (3,))
            ref[start:start + 512] = np.einsum("ijc,jc->ic", R, src)
        lat = np.abs(pos[:, 2]) < 0.8 * 15.0  # leave out the poles, where a texel is a sliver
        for stretch in (True, False):
            plan = with_knobs(base, stretch=stretch)
            prep_s = prepare(scene, plan)
            frame = diffused(plan, prep_s)
            M = np.asarray(frame(params, jnp.asarray(E)))[m]
            t = median_seconds(lambda: jax.block_until_ready(frame(params, jnp.asarray(E))), repeats=3)
            err = np.sqrt(((M - ref)[lat] ** 2).mean() / (ref[lat] ** 2).mean())
            print(f"| {name} | {'on' if stretch else 'off'} | {100 * err:.2f} % | {1000 * t:.0f} |", flush=True)


def blur_vs_scipy():
    print("\n## One blur chain, 1024^2 x 3 channels x 6 Gaussians (texel = 1 mm)\n")
    rng = np.random.default_rng(0)
    tex = rng.uniform(size=(1024, 1024, 3)).astype(np.float32)
    variances = np.geomspace(1.0, 400.0, 6)
    mask = np.ones((1024, 1024), np.float32)
    print("| method | step growth | ms | ratio to scipy |")
    print("|---|---|---|---|")
    t_scipy = median_seconds(lambda: [gaussian_filter(tex[..., c], np.sqrt(v), mode="constant")
                                      for v in variances for c in range(3)], repeats=3)
    print(f"| scipy.ndimage.gaussian_filter (6 independent) | - | {1000 * t_scipy:.0f} | 1.00 |")
    for ratio in (4.0, 2.0):
        schedule = blur_schedule(variances, 1.0, max_ratio=ratio)
        fn = jax.jit(lambda t, v: hierarchical_blur(t, mask, (1.0, 1.0), v, schedule))
        args = (jnp.asarray(tex), jnp.asarray(variances, jnp.float32))
        jax.block_until_ready(fn(*args))
        t = median_seconds(lambda: jax.block_until_ready(fn(*args)), repeats=3)
        print(f"| jsss hierarchical 7-tap ({schedule.n_steps} steps) | {ratio:g}x | {1000 * t:.0f} | "
              f"{t / t_scipy:.2f} |", flush=True)


def copy_bandwidth(megabytes: int = 256) -> float:
    """Bytes per second of a large float32 array read and written once (x * 1.0001, jitted)."""
    x = jnp.ones(megabytes * 2**20 // 4, jnp.float32)
    scale = jax.jit(lambda a: a * 1.0001)
    jax.block_until_ready(scale(x))
    return 2 * x.nbytes / median_seconds(lambda: jax.block_until_ready(scale(x)), repeats=7)


def example_frames():
    print("\n## Example scenes: warm texture-space frames (float32) and the blur chain against the bandwidth bound\n")
    bandwidth = copy_bandwidth()
    print(f"Copy bandwidth (256 MB array, read + write): {bandwidth / 1e9:.1f} GB/s\n")
    print("| scene | texture (with margin) | Gaussians | steps | chain moves | bound | chain | x bound | frame |")
    print("|---|---|---|---|---:|---:|---:|---:|---:|")
    for name in ("marble_sphere", "skin_backlit", "ketchup_plane"):
        scene = load_scene(f"examples/{name}.toml")
        plan = plan_scene(scene, method="texture-space")
        prep = prepare(scene, plan)
        params = render_params(scene, plan, dtype=jnp.float32)
        method = plan.method_config
        E = jax.jit(lambda p: method.irradiance(p, prep))(params)
        chain = jax.jit(lambda p, e: method.diffusion(p, prep, e))
        frame = jax.jit(lambda p: method.radiance(p, prep))
        jax.block_until_ready((chain(params, E), frame(params)))
        t_chain = median_seconds(lambda: jax.block_until_ready(chain(params, E)), repeats=5)
        t_frame = median_seconds(lambda: jax.block_until_ready(frame(params)), repeats=5)
        size = plan.texture_size + 2 * prep.open_margin
        texels = size * (plan.texture_size if prep.texels.wrap_u else size)
        moved = prep.schedule.n_steps * 2 * 2 * texels * (3 + 1) * 4  # steps x passes x (read, write) x RGB + mask
        bound = moved / bandwidth
        print(f"| {name} | {size}^2 | {len(plan.variances)} | {prep.schedule.n_steps} | {moved / 1e6:.0f} MB | "
              f"{1000 * bound:.0f} ms | {1000 * t_chain:.0f} ms | {t_chain / bound:.1f} | {1000 * t_frame:.0f} ms |",
              flush=True)


def main():
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="skip the 512^2 rows")
    parser.add_argument("--only", choices=("examples",), help="run one table only")
    args = parser.parse_args()
    load = os.getloadavg()[0]
    print(f"# benchmarks/render.py, {time.strftime('%Y-%m-%d')}, {jax.devices()[0].platform}, "
          f"{os.cpu_count()} cores, load {load:.1f}")
    if args.only != "examples":
        plane_table(args.quick)
        sphere_table()
        blur_vs_scipy()
    example_frames()


if __name__ == "__main__":
    main()
