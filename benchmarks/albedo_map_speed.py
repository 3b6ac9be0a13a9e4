"""What a per-texel albedo-map fit costs: the first and a second ``fit_albedo_map`` in one process.

    PYTHONPATH=. python benchmarks/albedo_map_speed.py [--cases 64x48:64:16 128x96:128:32 320x240:128:32]
        [--markdown docs/benchmarks/albedo_map_speed.md]

The scene is the tests' plane (``tests/fitting/test_albedo_map.py``: a checker colour map,
pre-post texturing, one directional light) at each case's resolution, texture size and map
size (``WxH:texture:map``). Its photo is jsss's own render with the passes the fit models
(``fitting.albedo_map.without_legs``) plus 1 % Gaussian noise, gain 2, the noise given: this
times the solver, and the map's error is a consistency check against the known checker (the
path-traced truth is ``benchmarks/albedo_map_truth.py``). The mean free path starts at the truth.

One fresh process per case. Timed: the first call (tracing and XLA compiles included) and a
second call with the same inputs, which since 12-07 compiles none of the fit's programs (they
are kept per structure, ``fitting.albedo_map._programs``; what it still compiles are a few
small eager operations). The baseline, measured in the same
process right after: the median of 5 warm ``render(scene, plan)`` calls of the same frame, so
that the last column, the second fit in frames' worth, does not depend on the machine's load.
"""

from __future__ import annotations

import argparse
import dataclasses
import datetime
import json
import os
import platform
import subprocess
import sys
import time
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CASES = ("64x48:64:16", "128x96:128:32", "320x240:128:32")


def _measure(case: str) -> dict:
    """Both fits and the frame's time, in this (fresh) process."""
    import jax

    jax.config.update("jax_enable_x64", True)
    import jax.numpy as jnp
    import numpy as np

    from benchmarks._timing import median_seconds
    from fitting.albedo_map import fit_albedo_map, without_legs
    from jsss.render import parse_scene, plan_scene, render
    from jsss.render.surface_maps import SurfaceMaps
    from tests.fitting.test_albedo_map import SCENE, _checker

    size, texture, map_size = case.split(":")
    width, height = (int(v) for v in size.split("x"))
    texture, map_size = int(texture), int(map_size)
    compiled = {"seconds": 0.0, "programs": 0}

    def listen(event, duration, **_):
        if event == "/jax/core/compile/backend_compile_duration":
            compiled["seconds"] += duration
            compiled["programs"] += 1

    jax.monitoring.register_event_duration_secs_listener(listen)
    text = SCENE.replace("resolution = [64, 48]", f"resolution = [{width}, {height}]").replace(
        "texture_size = 64", f"texture_size = {texture}")
    scene = parse_scene(tomllib.loads(text), source="plane.toml")
    truth = _checker(map_size)
    textured = dataclasses.replace(scene, material=dataclasses.replace(scene.material, maps=SurfaceMaps(albedo=truth)))
    plan = without_legs(plan_scene(textured, accuracy=0.001, method="texture-space"))
    clean = np.asarray(render(textured, plan, dtype=jnp.float64).radiance)
    sigma = 0.01 * np.maximum(clean, 0.01 * clean.max())
    photo = 2.0 * (clean + sigma * np.random.default_rng(1).standard_normal(clean.shape))
    medium = scene.material.medium
    mfp = 1.0 / (np.asarray(medium.sigma_a) + np.asarray(medium.sigma_s_prime))
    out = {"case": case, "texture": int(plan.method_config.size), "map": map_size}
    for call in ("first", "second"):
        compiled.update(seconds=0.0, programs=0)
        start = time.perf_counter()
        fit = fit_albedo_map(scene, photo, gain=2.0, sigma=2.0 * sigma, map_size=map_size, init_mean_free_path=mfp,
                             model_error=0)  # jsss's own render: no renderer error to carry
        wall = time.perf_counter() - start
        z = ((fit.albedo - truth) / fit.albedo_err)[fit.seen]
        error = ((fit.albedo - truth) / truth)[fit.seen]
        out[call] = {"wall": wall, "compile": compiled["seconds"], "programs": compiled["programs"],
                     "steps": fit.steps, "cg": fit.cg_steps, "converged": fit.converged,
                     "rms_z": float(np.sqrt(np.mean(z**2))), "rms_error": float(np.sqrt(np.mean(error**2))),
                     "seen": int(fit.seen.sum()), "mfp_z": ((fit.mean_free_path - mfp) / fit.mean_free_path_err).tolist()}
    out["frame"] = median_seconds(lambda: np.asarray(render(textured, plan, dtype=jnp.float64).radiance),
                                  repeats=5)
    return out


def _table(results) -> list[str]:
    lines = [("| photo | texture | map (seen) | call | wall [s] | XLA compile [s] (programs) | Gauss-Newton steps | "
              "CG iterations | map RMS error | RMS z | mfp z (R / G / B) | frame [s] | fit / frame |"),
             "|---|---|---|---|---|---|---|---|---|---|---|---|---|"]
    for r in results:
        for call in ("first", "second"):
            c = r[call]
            z = " / ".join(f"{v:+.1f}" for v in c["mfp_z"])
            lines.append(f"| {r['case'].split(':')[0]} | {r['texture']} | {r['map']}^2 ({c['seen']}) | {call} | "
                         f"{c['wall']:.1f} | {c['compile']:.1f} ({c['programs']}) | {c['steps']} | {c['cg']} | "
                         f"{100 * c['rms_error']:.2f} % | {c['rms_z']:.2f} | {z} | {r['frame']:.3f} | "
                         f"{c['wall'] / r['frame']:.0f} |")
    return lines


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="+", default=list(CASES), help="WxH:texture:map, e.g. 64x48:64:16")
    parser.add_argument("--markdown", type=Path, help="write the table here (docs/benchmarks/albedo_map_speed.md)")
    parser.add_argument("--one", help=argparse.SUPPRESS)  # internal: measure this case here, print JSON
    args = parser.parse_args(argv)
    if args.one:
        print(json.dumps(_measure(args.one)))
        return 0
    results = []
    for case in args.cases:
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        done = subprocess.run([sys.executable, __file__, "--one", case], env=env, check=True, capture_output=True,
                              text=True, cwd=ROOT)
        results.append(json.loads(done.stdout.strip().splitlines()[-1]))
        print(f"{case}: done", file=sys.stderr, flush=True)
    cpu = f"{os.cpu_count()} cores, {platform.machine()}"
    lines = [f"# What a per-texel albedo-map fit costs, {datetime.date.today().isoformat()}", "",
             (f"`PYTHONPATH=. python benchmarks/albedo_map_speed.py` ({cpu}, CPU, float64, a fresh process per "
              "photo). The tests' checker plane; its photo is jsss's own render (the fit's passes) plus 1 % noise, "
              "so the map's error is a consistency check against the known checker, not truth (that is "
              "[albedo_map_truth.md](albedo_map_truth.md), against Mitsuba 3). Default fit options (errors by "
              "probing), the mean free path started at the truth; the scene's `texture_size` caps the plan's "
              "texture. The second call has the same inputs: it compiles none of the fit's programs (they are kept "
              "per structure: map size, the plan's layout, dtypes), only a few small eager operations. Baseline, "
              "measured in the same process: the median of 5 warm `render(scene, plan)` frames; the last column is "
              "the fit in frames' worth."), ""]
    lines += _table(results) + [""]
    for r in results:
        if r["case"].startswith("320x240"):
            wall = r["second"]["wall"]
            lines += [(f"Issue 36's target, a 320 x 240 photo's fit with a per-texel map in under 60 s after "
                       f"compilation: {wall:.0f} s here with a {r['map']}^2 map on a {r['texture']}^2 texture "
                       f"({'met' if wall < 60 else 'not met'}). A larger map or texture costs more: each CG "
                       "iteration is one J v and one J^T w through the blur chain and the camera's lookup."), ""]
    text = "\n".join(lines)
    print(text)
    if args.markdown:
        args.markdown.parent.mkdir(parents=True, exist_ok=True)
        args.markdown.write_text(text)
    return 0


if __name__ == "__main__":
    sys.exit(main())
