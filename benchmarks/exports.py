r"""The exports rendered by the real renderers: Mitsuba 3 and Blender Cycles, against the truth.

    python benchmarks/exports.py [--seconds-mitsuba 600] [--spp-cycles 4096] [--markdown docs/benchmarks/exports.md]

Mitsuba's estimate of a channel that F(0) dominates is noisy (its dielectric picks reflection
with probability F(0)), and marble's long walks are slow: reaching a standard error near
0.1 % takes many minutes of CPU. On a machine with more cores or a GPU, write the job
(``--write-mitsuba-job job.json``), render it there (``--mitsuba-job job.json
--mitsuba-results rows.json --variant cuda_ad_rgb --seconds-mitsuba 60``: mitsuba and numpy
only) and give the rows back here (``--mitsuba-results rows.json``).

Each material (Jensen et al. 2001's marble, ketchup, skin1; g = 0) is exported
(:mod:`measure.export`) and rendered as a semi-infinite slab: a box 1000 of its largest mean
free paths wide and deep, top face at z = 0, under a uniform white environment (radiance 1),
seen straight down by an orthographic camera over the central 10 mean free paths.

**The truth.** A camera looking along the normal at a smooth half space in a uniform
environment of radiance 1 sees :math:`F(0) + (1 - F(0)) R_d`: the mirror reflection of the
environment, plus the light that entered anywhere from any direction and leaves toward the
camera. By reciprocity the latter equals the light that a beam entering *from* the camera's
direction returns to the whole environment, :math:`(1 - F(0))\,R_d`, with :math:`R_d` the
total diffuse reflectance per unit entering flux of a normally incident beam, internal
Fresnel reflection included: :func:`jsss.transport.total_reflectance` at the medium's eta
(the scaled Monte Carlo tables: within 0.2 % of Chandrasekhar's exact result at eta = 1,
``tests/measure/test_export.py``). Exact, no diffusion approximation, for any eta and g.

**The renders.** Mitsuba 3 (``scalar_rgb``, ``volpathmis``, no depth limit, no Russian
roulette before depth 10^5): the exported ``homogeneous`` medium in its ``dielectric``.
Cycles (bpy 4.5, CPU, in a child process: the exported Python script run on the slab),
Principled BSDF roughness 0, no clamping, 64 bounces of each kind. The value is the mean over
the pixels (box filter: pixels are independent), its standard error their spread / sqrt(n).
"""

from __future__ import annotations

import argparse
import datetime
import json
import platform
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
MATERIALS = ("marble", "ketchup", "skin1")
SLAB_MEAN_FREE_PATHS = 1000.0   # the box's width and depth
VIEW_MEAN_FREE_PATHS = 10.0     # the camera's field, centred
RR_DEPTH = 10000                # Mitsuba's Russian roulette starts here (see mitsuba_scene)


def truth(medium, g=0.0):
    """F(0) + (1 - F(0)) R_d per channel: what the camera sees on the half space (see the module doc)."""
    from jsss import Medium, transport

    medium = Medium(np.asarray(medium.sigma_a, float), np.asarray(medium.sigma_s_prime, float),
                    np.asarray(medium.eta, float))
    rd = np.asarray(transport.total_reflectance(medium, g=g), float)
    f0 = 1.0 - np.asarray(transport.entry_transmittance(medium.eta), float)
    return f0 + (1.0 - f0) * rd


def slab_size(medium) -> float:
    """The largest mean free path [mm]: the slab's and the view's unit."""
    return float(np.max(1.0 / (np.asarray(medium.sigma_a, float) + np.asarray(medium.sigma_s_prime, float))))


def _summary(pixels, seconds):
    pixels = np.asarray(pixels, float).reshape(-1, 3)
    return {"mean": pixels.mean(0).tolist(), "stderr": (pixels.std(0, ddof=1) / np.sqrt(len(pixels))).tolist(),
            "seconds": seconds}


def mitsuba_scene(material: dict, mfp: float, *, spp: int, resolution: int, seed: int = 0):
    """The slab scene around an exported Mitsuba dict (``measure.export.mitsuba_dict``); needs
    only mitsuba, set to its variant (the device run has no jsss)."""
    import mitsuba as mi

    T = mi.ScalarTransform4f
    size, view = SLAB_MEAN_FREE_PATHS * mfp, VIEW_MEAN_FREE_PATHS * mfp
    return mi.load_dict({
        "type": "scene",
        # Russian roulette only from depth 10^4, where a walk carries < 1e-5 of the light: with it
        # from depth 5, volpathmis returned 1.5 % too little at albedo 0.99 (against Chandrasekhar's
        # exact albedo; 0.1 % without it), and from depth 1000, marble's red 0.86 % too little.
        "integrator": {"type": "volpathmis", "max_depth": -1, "rr_depth": RR_DEPTH},
        "slab": {"type": "cube", "to_world": T().translate([0, 0, -size / 2]).scale([size / 2, size / 2, size / 2]),
                 "bsdf": material["bsdf"], "interior": material["interior"]},
        "environment": {"type": "constant", "radiance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}},
        "sensor": {"type": "orthographic", "near_clip": 1e-3 * mfp, "far_clip": 10 * size,
                   "to_world": T().look_at(origin=[0, 0, mfp], target=[0, 0, 0], up=[0, 1, 0]).scale([view / 2, view / 2, 1]),
                   "sampler": {"type": "independent", "sample_count": spp, "seed": seed},
                   "film": {"type": "hdrfilm", "width": resolution, "height": resolution, "rfilter": {"type": "box"},
                            "pixel_format": "rgb"}},
    })


def render_mitsuba_dict(material: dict, mfp: float, *, spp=256, resolution=16, variant="scalar_rgb", seconds=None):
    """Render the slab in passes of ``spp`` (seeds 0, 1, ...) until ``seconds`` are spent (one
    pass without): per-channel mean over every pass's pixels, standard error, seconds, passes."""
    import mitsuba as mi

    mi.set_variant(variant)
    scene = mitsuba_scene(material, mfp, spp=spp, resolution=resolution)
    start, passes = time.perf_counter(), []
    while not passes or (seconds is not None and time.perf_counter() - start < seconds):
        passes.append(np.array(mi.render(scene, spp=spp, seed=len(passes)))[..., :3])
    return {**_summary(np.stack(passes), time.perf_counter() - start), "passes": len(passes), "variant": variant}


def render_mitsuba(medium, *, g=0.0, spp=256, resolution=16, variant="scalar_rgb", seconds=None):
    """The exported Mitsuba dict (:func:`measure.export.mitsuba_dict`) on the slab."""
    from measure import export

    return render_mitsuba_dict(export.mitsuba_dict(medium, g=g), slab_size(medium), spp=spp, resolution=resolution,
                               variant=variant, seconds=seconds)


def _cycles_child(args: dict) -> dict:
    """Runs in the child process: build the slab in bpy, run the exported script on it, render."""
    import tempfile

    import bpy

    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    scene.render.engine = "CYCLES"
    cycles = scene.cycles
    cycles.device, cycles.samples, cycles.seed = "CPU", args["spp"], args["seed"]
    cycles.use_adaptive_sampling = cycles.use_denoising = False
    cycles.sample_clamp_direct = cycles.sample_clamp_indirect = 0.0   # clamping biases
    cycles.max_bounces = cycles.diffuse_bounces = cycles.glossy_bounces = cycles.transmission_bounces = 64
    cycles.blur_glossy = 0.0
    cycles.pixel_filter_type, cycles.filter_width = "BOX", 1.0
    scene.render.threads_mode, scene.render.threads = "FIXED", args["threads"]
    scene.render.resolution_x = scene.render.resolution_y = args["resolution"]
    scene.render.resolution_percentage = 100
    scene.view_settings.view_transform = "Standard"
    world = bpy.data.worlds.new("white")
    scene.world = world
    world.use_nodes = True
    world.node_tree.nodes["Background"].inputs["Color"].default_value = (1.0, 1.0, 1.0, 1.0)
    world.node_tree.nodes["Background"].inputs["Strength"].default_value = 1.0
    size, mfp = args["size"], args["mfp"]
    bpy.ops.mesh.primitive_cube_add(size=1.0, location=(0, 0, -size / 2))
    bpy.context.active_object.scale = (size, size, size)
    bpy.ops.object.transform_apply(scale=True)
    exec(compile(args["script"], "exported_material.py", "exec"), {})  # noqa: S102 - the export under test
    camera = bpy.data.cameras.new("camera")
    camera.type, camera.ortho_scale = "ORTHO", args["view"]
    camera.clip_start, camera.clip_end = 1e-3 * mfp, 10 * size
    scene.camera = bpy.data.objects.new("camera", camera)
    scene.collection.objects.link(scene.camera)
    scene.camera.location = (0, 0, mfp)
    scene.render.image_settings.file_format, scene.render.image_settings.color_depth = "OPEN_EXR", "32"
    with tempfile.TemporaryDirectory() as folder:
        scene.render.filepath = str(Path(folder) / "slab.exr")
        start = time.perf_counter()
        bpy.ops.render.render(write_still=True)
        seconds = time.perf_counter() - start
        image = bpy.data.images.load(scene.render.filepath)
        pixels = np.array(image.pixels[:], float).reshape(args["resolution"], args["resolution"], 4)[..., :3]
    return _summary(pixels, seconds)


def blender_python() -> str:
    """The Python that imports bpy: ``$JSSS_BPY_PYTHON`` (a Python 3.11 of its own: bpy 4.5's
    metadata pins numpy < 2, which jax no longer runs on), else this one."""
    import os

    return os.environ.get("JSSS_BPY_PYTHON") or sys.executable


def render_cycles(medium, *, g=0.0, spp=1024, resolution=16, seed=0, threads=2, own_albedo=False, albedo_map=None):
    """The exported Blender script on the slab, rendered by Cycles in a child process (bpy
    stays out of this one): per-channel mean, standard error, seconds. ``own_albedo``: with
    the colour of the medium's own single-scattering albedo instead (the export until
    2026-12-04, for comparison). ``albedo_map``: a pre-post colour map (rows, columns, 3),
    exported as ``jsss-render fit --albedo-map --export blender`` writes it (the script and
    its colour EXR, side by side in the child's folder)."""
    import tempfile

    from measure import export
    from measure.exr import write_exr

    mfp = slab_size(medium)
    folder = tempfile.TemporaryDirectory()
    if albedo_map is None:
        script = export.blender_python(medium, g=g)
    else:
        write_exr(Path(folder.name) / "colour.exr", export.blender_colour_map(medium, albedo_map, g=g)[::-1]
                  .astype(np.float32))
        script = export.blender_python(medium, g=g, colour_map=str(Path(folder.name) / "colour.exr"))
    if own_albedo:
        _, sigma_s, _ = export.scattering_coefficients(medium, g=g)
        alpha = sigma_s / (np.asarray(medium.sigma_a, float) + sigma_s)
        colour = ", ".join(f"{v:.9g}" for v in export.cycles_colour_from_albedo(alpha, g))
        script = "\n".join(f"node.inputs['Base Color'].default_value = ({colour}, 1.0)"
                           if line.startswith("node.inputs['Base Color']") else line for line in script.splitlines())
    args = {"script": script, "spp": spp, "resolution": resolution, "seed": seed,
            "threads": threads, "size": SLAB_MEAN_FREE_PATHS * mfp, "view": VIEW_MEAN_FREE_PATHS * mfp, "mfp": mfp}
    with folder:  # the script reads its texture from the working folder (run without __file__)
        done = subprocess.run([blender_python(), str(Path(__file__).resolve()), "--cycles-child", json.dumps(args)],
                              capture_output=True, text=True, cwd=folder.name, check=False)
    if done.returncode != 0:
        raise RuntimeError(f"the Cycles child failed ({done.returncode}):\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def mitsuba_job() -> list[dict]:
    """What the Mitsuba renders need, as plain data: each material's export, mean free path and truth."""
    from jsss.materials import jensen2001
    from measure import export

    return [{"material": name, "mitsuba": export.mitsuba_dict(jensen2001(name)), "mfp": slab_size(jensen2001(name)),
             "truth": truth(jensen2001(name)).tolist()} for name in MATERIALS]


def run_mitsuba_job(job, *, spp, resolution, variant, seconds, save=None) -> list[dict]:
    """Render each job entry in Mitsuba (no jsss needed: the device machine runs this)."""
    rows = []
    for entry in job:
        result = render_mitsuba_dict(entry["mitsuba"], entry["mfp"], spp=spp, resolution=resolution, variant=variant,
                                     seconds=entry.get("seconds", seconds))
        rows.append({"material": entry["material"], "renderer": "Mitsuba 3", "truth": entry["truth"], "spp": spp,
                     **result})
        _print_row(rows[-1])
        if save is not None:  # as it goes: a run stopped early keeps what it rendered
            save(rows)
    return rows


def run_cycles(spp, resolution, *, g=0.0, own_albedo=False, label="Cycles") -> list[dict]:
    from jsss.materials import jensen2001

    rows = []
    for name in MATERIALS:
        medium = jensen2001(name)
        rows.append({"material": name, "renderer": label, "truth": truth(medium, g=g).tolist(), "spp": spp,
                     "passes": 1, **render_cycles(medium, g=g, spp=spp, resolution=resolution, own_albedo=own_albedo)})
        _print_row(rows[-1])
    return rows


def _print_row(row):
    print(f"{row['material']:8} {row['renderer']:9} " + "  ".join(
        f"{m:.5f}±{s:.5f} ({m / t - 1:+.2%})" for m, s, t in zip(row["mean"], row["stderr"], row["truth"]))
        + f"  {row['seconds']:.1f} s", flush=True)


def markdown(rows, resolution, mitsuba_machine, extras=()) -> str:
    import mitsuba

    today = datetime.date.today().isoformat()
    variants = sorted({row.get("variant", "") for row in rows if row["renderer"] == "Mitsuba 3"})
    lines = [f"Exports in the real renderers, {today} (`python benchmarks/exports.py`; Mitsuba {mitsuba.__version__} "
             f"`{', '.join(variants)}` on {mitsuba_machine}; Blender {_blender_version()} Cycles CPU on {_machine()})",
             "",
             "Each Jensen et al. 2001 material (g = 0) exported by `measure.export` and rendered as a semi-infinite "
             "slab (a box 1000 of its largest mean free paths wide and deep) under a uniform white environment, "
             f"seen along the normal by an orthographic camera: {resolution} x {resolution} pixels over the central "
             "10 mean free paths; the mean of all pixels of all passes (spp each) and its standard error (box "
             "filter: pixels are independent).", "",
             "**Truth:** F(0) + (1 - F(0)) R_d, with R_d the total diffuse reflectance per unit entering flux "
             "of the transport tables (`jsss.transport.total_reflectance`, internal reflection included) at the "
             "material's eta. By reciprocity this is exactly what a camera along the normal sees on a smooth half "
             "space in a uniform environment of radiance 1: the mirror image of the environment, F(0), plus the "
             "light a beam from the camera's direction would return to the whole environment, (1 - F(0)) R_d.", "",
             "Mitsuba 3: the exported `dielectric` + `homogeneous` medium, `volpathmis`, Russian roulette only "
             f"from depth {RR_DEPTH} (where a walk carries < 1e-5 of the light). With it from depth 1000, marble's "
             "red came out 0.86 % low (30 standard errors; a grey medium of marble's red at eta 1 0.45 % below "
             "Chandrasekhar's exact 1 - H(1) sqrt(1 - alpha), and from depth 5 at albedo 0.99, 1.5 % below: "
             "volpathmis' roulette loses light; without it, 0.01 % and 0.08 %, within the noise). Cycles (pip `bpy`, CPU): the exported Python script, no clamping, 64 bounces "
             "of each kind; its colour is chosen so that Cycles' index-matched, 256-bounce walk returns R_d "
             "(`measure.cycles_walk`), its radius is 4 pi mean free paths.", "",
             "| material | renderer | spp x passes | channel | truth | render ± s.e. | error | error / s.e. | seconds |",
             "|---|---|---:|---|---:|---:|---:|---:|---:|"]
    for row in rows:
        for c, channel in enumerate("RGB"):
            t, m, s = row["truth"][c], row["mean"][c], row["stderr"][c]
            head = (f"| {row['material']} | {row['renderer']} | {row['spp']} x {row.get('passes', 1)} |" if c == 0
                    else "| | | |")
            tail = f" {row['seconds']:.1f} |" if c == 0 else " |"
            lines.append(f"{head} {channel} | {t:.6f} | {m:.6f} ± {s:.6f} | {m / t - 1:+.2%} | {(m - t) / s:+.1f} |"
                         + tail)
    for title, extra in extras:
        lines += ["", title, "", "| material | spp | truth R, G, B | render R, G, B | error R, G, B |",
                  "|---|---:|---|---|---|"]
        for row in extra:
            lines.append(f"| {row['material']} | {row['spp']} | " + ", ".join(f"{t:.4f}" for t in row["truth"]) + " | "
                         + ", ".join(f"{m:.4f}" for m in row["mean"]) + " | "
                         + ", ".join(f"{m / t - 1:+.1%}" for m, t in zip(row["mean"], row["truth"])) + " |")
    return "\n".join(lines) + "\n"


def _blender_version() -> str:
    done = subprocess.run([blender_python(), "-c", "import bpy; print(bpy.app.version_string)"], capture_output=True,
                          text=True, check=False)
    return done.stdout.strip().splitlines()[-1] if done.returncode == 0 else "(not installed)"


def main() -> None:
    if len(sys.argv) == 3 and sys.argv[1] == "--cycles-child":
        print(json.dumps(_cycles_child(json.loads(sys.argv[2]))))
        return
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--spp-mitsuba", type=int, default=256, help="samples per pixel of one Mitsuba pass")
    parser.add_argument("--seconds-mitsuba", type=float, default=None,
                        help="render Mitsuba passes for this long per material (default: one pass)")
    parser.add_argument("--variant", default="scalar_rgb", help="Mitsuba variant (scalar_rgb, cuda_ad_rgb, ...)")
    parser.add_argument("--spp-cycles", type=int, default=4096)
    parser.add_argument("--resolution", type=int, default=16)
    parser.add_argument("--write-mitsuba-job", type=Path, help="only write the Mitsuba job (JSON) for another machine")
    parser.add_argument("--mitsuba-job", type=Path, help="render this job in Mitsuba only (needs no jsss)")
    parser.add_argument("--mitsuba-results", type=Path,
                        help="with --mitsuba-job: write the rows here; else: take the Mitsuba rows from here")
    parser.add_argument("--markdown", type=Path, help="write the table here (e.g. docs/benchmarks/exports.md)")
    args = parser.parse_args()
    if args.write_mitsuba_job:
        args.write_mitsuba_job.write_text(json.dumps(mitsuba_job()))
        return
    if args.mitsuba_job:
        def save(rows):
            if args.mitsuba_results:
                args.mitsuba_results.write_text(json.dumps({"rows": rows, "machine": _machine()}))

        run_mitsuba_job(json.loads(args.mitsuba_job.read_text()), spp=args.spp_mitsuba, resolution=args.resolution,
                        variant=args.variant, seconds=args.seconds_mitsuba, save=save)
        return
    if args.mitsuba_results:
        done = json.loads(args.mitsuba_results.read_text())
        mitsuba_rows, mitsuba_machine = done["rows"], done["machine"]
    else:
        mitsuba_rows = run_mitsuba_job(mitsuba_job(), spp=args.spp_mitsuba, resolution=args.resolution,
                                       variant=args.variant, seconds=args.seconds_mitsuba)
        mitsuba_machine = _machine()
    cycles_rows = run_cycles(args.spp_cycles, args.resolution)
    extras = [("Cycles given the medium's own single-scattering albedo (the export until 2026-12-04, radius fixed): "
               "what the colour choice corrects.", run_cycles(1024, args.resolution, own_albedo=True, label="old")),
              ("Cycles with g = 0.8 (sigma_s = sigma_s' / 0.2; truth: the g = 0.8 tables): the walk model's "
               "g > 0 approximation (the cap's tail from the similar isotropic walk).",
               run_cycles(1024, args.resolution, g=0.8, label="g=0.8"))]
    if args.markdown:
        rows = [row for name in MATERIALS for row in mitsuba_rows + cycles_rows if row["material"] == name]
        args.markdown.write_text(markdown(rows, args.resolution, mitsuba_machine, extras))
        print(f"written to {args.markdown}")


def _machine() -> str:
    import os

    return f"{os.cpu_count()} cores, {platform.machine()}"


if __name__ == "__main__":
    main()
