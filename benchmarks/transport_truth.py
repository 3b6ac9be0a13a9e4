"""Subsurface light of jsss's renders against a volumetric path tracer (Mitsuba 3): transport truth.

    pip install -e '.[truth]' && python benchmarks/transport_truth.py [--quick] [--spp N]

Mitsuba renders the same mesh, camera and lights with a homogeneous medium (sigma_s =
sigma_s', g = 0: the similarity model the dipole is given in), one grey medium per colour
channel (volpath's chromatic free-path sampling has infinite variance; see `_grey_medium`),
inside a rough dielectric
(Beckmann) of the material's eta. Point and directional lights cannot reach through a
*smooth* dielectric in a path tracer, so each frame is rendered at two roughnesses and
extrapolated to the smooth limit linearly in alpha^2. The subsurface part is the frame with
the medium minus the frame with a purely absorbing interior (albedo 0), rendered with the
same seed so that their surface reflections cancel. Russian roulette starts after 10^5
bounces (albedo 0.999 walks are long). The path tracer's noise comes from independent
chunks (seeds). Before any of that, a white Lambertian object is rendered by both (it must
agree to 1 %), which proves that camera, image orientation and light units are the same.

A plane is open; a medium needs a closed surface, so the plane becomes the top face of a
box 30 mm deep (pixels are compared where jsss sees the plane). A low light also enters the
box's walls, which jsss's plane does not have: ``--black-walls`` hangs black curtains around
them.

Printed per scene, method, profile model (``--profiles dipole transport``: the dipole, and
the scaled Monte Carlo tables of `jsss.transport`, exact to transport) and channel: the ratio
of summed subsurface radiance jsss / Mitsuba and the relative RMS error against it, with the
path tracer's own noise.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import tempfile
import time

import numpy as np

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

import jax.numpy as jnp  # noqa: E402
import trimesh  # noqa: E402

from jsss.render import Method, Pass, load_scene, plan_scene, render  # noqa: E402
from jsss.render.image_space import camera_buffers  # noqa: E402
from jsss.render.reference import white_lambertian_radiance  # noqa: E402

EXAMPLES = os.path.join(os.path.dirname(__file__), "..", "examples")
CALIBRATION_SCENES = os.path.join(os.path.dirname(__file__), "calibration_scenes")  # the planner's other kinds


def _scene_file(name: str) -> str:
    """The TOML of ``name`` in examples/ or benchmarks/calibration_scenes/."""
    for folder in (EXAMPLES, CALIBRATION_SCENES):
        path = os.path.join(folder, f"{name}.toml")
        if os.path.exists(path):
            return path
    raise SystemExit(f"--scenes: no {name}.toml in examples/ or benchmarks/calibration_scenes/")
ROUGHNESS = (0.1, 0.2)


LIBLLVM = "/usr/lib/x86_64-linux-gnu/libLLVM-19.so"  # Debian's libllvm19; 15 and 16 fail to compile kernels


def _mitsuba(variant="auto"):
    """Mitsuba with the LLVM variant where it runs, else scalar (on this 2-core machine they took
    the same time: 0.70 / 0.77 s for 256 spp of the ketchup plane at 40 x 30, one channel)."""
    if variant in ("auto", "llvm_ad_rgb") and "DRJIT_LIBLLVM_PATH" not in os.environ and os.path.exists(LIBLLVM):
        os.environ["DRJIT_LIBLLVM_PATH"] = LIBLLVM
    try:
        import mitsuba as mi
    except ImportError:
        sys.exit("transport_truth.py needs Mitsuba 3: pip install -e '.[truth]'")
    # Older libLLVMs abort the process inside kernel compilation (LLVM 15: "Cannot select
    # fminimum"), which no try can catch, so "auto" tries LLVM only with the library it was tested on.
    llvm_ok = os.environ.get("DRJIT_LIBLLVM_PATH") == LIBLLVM
    for name in ((["llvm_ad_rgb"] if llvm_ok else []) + ["scalar_rgb"] if variant == "auto" else [variant]):
        try:
            mi.set_variant(name)
            mi.render(mi.load_dict(mi.cornell_box()), spp=1)  # a variant can load and still fail to compile
            return mi
        except Exception as error:  # noqa: BLE001 -- any failure of a variant means: try the next one
            print(f"Mitsuba variant {name} does not run here ({type(error).__name__}: {error}); ", file=sys.stderr)
    sys.exit(f"no Mitsuba variant of {variant!r} runs on this machine")


def _with_resolution(scene, width, height):
    import dataclasses

    camera = dataclasses.replace(scene.camera, width=width, height=height)
    return dataclasses.replace(scene, camera=camera)


def _mesh_file(scene, folder):
    """The object's surface as PLY: the scene's mesh, or for a plane a closed box under it."""
    v, f = scene.mesh.vertices, scene.mesh.faces
    extent = np.ptp(v, axis=0)
    if extent[2] < 1e-9:  # a plane: the top face of a 30 mm deep box
        box = trimesh.creation.box(extents=(extent[0], extent[1], 30.0))
        box.apply_translation((v[:, 0].mean(), v[:, 1].mean(), v[:, 2].mean() - 15.0))
        mesh = box
    else:
        mesh = trimesh.Trimesh(v, f, process=True)  # merges seam duplicates: a closed surface
        mesh.fix_normals()
    path = os.path.join(folder, "object.ply")
    mesh.export(path)
    return path


BLACK_WALLS = False  # --black-walls: black curtains keep the light off a plane's box walls


def _wall_curtains(mi, scene):
    """Black curtains 0.05 mm outside the four walls of a plane's box, up to 0.01 mm below its
    top: the light reaches the medium only through the top, as it does jsss's open plane, and
    light leaving through a wall is absorbed. Without them a low light enters the walls (the
    grazing scene's far wall takes 2x the top's irradiance per mm^2) and shows near the edge."""
    v = scene.mesh.vertices
    (x0, y0, top), (x1, y1, _) = v.min(0), v.max(0)
    depth, gap, below = 30.0, 0.05, 0.01
    cz, hz = top - below - (depth - below) / 2, (depth - below) / 2
    black = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [0.0, 0.0, 0.0]}}
    T = mi.ScalarTransform4f
    walls = {}
    for i, x in enumerate((x0 - gap, x1 + gap)):
        walls[f"curtain_x{i}"] = {"type": "rectangle", "bsdf": black, "to_world": T().translate(
            [float(x), float((y0 + y1) / 2), float(cz)]).rotate([0, 1, 0], 90).scale([hz, float((y1 - y0) / 2 + gap), 1])}
    for i, y in enumerate((y0 - gap, y1 + gap)):
        walls[f"curtain_y{i}"] = {"type": "rectangle", "bsdf": black, "to_world": T().translate(
            [float((x0 + x1) / 2), float(y), float(cz)]).rotate([1, 0, 0], 90).scale([float((x1 - x0) / 2 + gap), hz, 1])}
    return walls


def _mitsuba_scene(mi, scene, ply, bsdf, interior=None, extra=None):
    """Mitsuba's scene of ``scene``'s object (``bsdf``, ``interior`` medium), camera and lights;
    ``extra``: more shapes by name (a grey card in the frame)."""
    cam = scene.camera
    lights = {}
    for i, light in enumerate(scene.lights):
        value = (np.asarray(light.color) * light.intensity).tolist()
        if light.kind == "directional":
            lights[f"light{i}"] = {"type": "directional", "direction": list(map(float, light.direction)),
                                   "irradiance": {"type": "rgb", "value": value}}
        else:
            lights[f"light{i}"] = {"type": "point", "position": list(map(float, light.position)),
                                   "intensity": {"type": "rgb", "value": value}}
    shape = {"type": "ply", "filename": ply, "face_normals": True, "bsdf": bsdf}
    if interior is not None:
        shape["interior"] = interior
    return mi.load_dict({
        "type": "scene",
        "integrator": {"type": "volpath", "max_depth": -1, "rr_depth": 100_000},
        "sensor": {"type": "perspective", "fov": cam.fov_degrees, "fov_axis": "y",
                   "to_world": mi.ScalarTransform4f().look_at(origin=list(cam.position), target=list(cam.look_at),
                                                               up=list(cam.up)),
                   "film": {"type": "hdrfilm", "width": cam.width, "height": cam.height,
                            "rfilter": {"type": "box"}, "pixel_format": "rgb"},
                   "sampler": {"type": "independent"}},
        "object": shape, **lights, **(extra or {}),
        **(_wall_curtains(mi, scene) if BLACK_WALLS and np.ptp(scene.mesh.vertices[:, 2]) < 1e-9 else {})})


def _render(mi, mscene, spp, seed):
    return np.array(mi.render(mscene, spp=spp, seed=seed), dtype=float)[..., :3]


def _grey_medium(medium, channel, absorbing=False):
    """One channel's coefficients in all three: a medium that is the same in every channel.

    Mitsuba's ``volpath`` samples free paths with the extinction of one randomly chosen
    channel and weights the others by ``T_c(t) / p_k(t)``. Where a channel's extinction is
    below the sampled one (ketchup: red 0.24/mm against blue 1.48/mm) that weight grows like
    ``exp((sigma_k - sigma_c) t)``: unbiased, but its variance is infinite, so a finite run
    reads the red channel 30-50 % off with an error bar that does not show it (measured on
    the ketchup plane, 40 x 30 px, 8 x 2048 spp: volpath red 22.6 +- 7.9, one medium per
    channel 14.86 +- 0.26, ``volpathmis`` 14.98 +- 0.40). A grey medium has no such weight.
    """
    sigma_a = float((np.asarray(medium.sigma_a, float) * np.ones(3))[channel])
    sigma_s = float((np.asarray(medium.sigma_s_prime, float) * np.ones(3))[channel])
    sigma_t = sigma_a + sigma_s
    albedo = 0.0 if absorbing else sigma_s / sigma_t
    return {"type": "homogeneous", "albedo": {"type": "rgb", "value": [albedo] * 3},
            "sigma_t": {"type": "rgb", "value": [1.0] * 3}, "scale": sigma_t}


def lambert_check(mi, scene, ply, spp):
    """Relative difference of a white Lambertian object, Mitsuba against jsss's own irradiance."""
    ours = white_lambertian_radiance(scene)
    white = {"type": "diffuse", "reflectance": {"type": "rgb", "value": [1.0, 1.0, 1.0]}}
    truth = _render(mi, _mitsuba_scene(mi, scene, ply, white), spp, 0)
    inner = _interior(camera_buffers(scene.mesh, scene.camera).mask)
    return ours[inner].sum(0) / truth[inner].sum(0) - 1, inner


def _interior(mask):
    """Pixels whose 8 neighbours are on the object too (silhouette pixels are partly background)."""
    m = mask.astype(bool)
    out = m.copy()
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            out &= np.roll(np.roll(m, dy, 0), dx, 1)
    return out


def subsurface_truth(mi, scene, ply, spp, chunks):
    """Smooth-limit subsurface radiance (H, W, 3) and each chunk's estimate (for the noise)."""
    eta = float(np.asarray(scene.material.eta).mean())
    at = []  # (roughness, chunk, H, W, 3): each scene is loaded once and rendered with every seed
    for alpha in ROUGHNESS:
        bsdf = {"type": "roughdielectric", "distribution": "beckmann", "alpha": alpha, "int_ior": eta, "ext_ior": 1.0}
        channels = []
        for c in range(3):  # one grey medium per channel (see _grey_medium)
            full = _mitsuba_scene(mi, scene, ply, bsdf, _grey_medium(scene.material.medium, c))
            dark = _mitsuba_scene(mi, scene, ply, bsdf, _grey_medium(scene.material.medium, c, True))
            channels.append([(_render(mi, full, spp, seed) - _render(mi, dark, spp, seed))[..., c]
                             for seed in range(chunks)])
        at.append(np.stack(channels, axis=-1))
    at = np.array(at)
    a2 = np.square(ROUGHNESS)
    per_chunk = at[0] + (at[0] - at[1]) * a2[0] / (a2[1] - a2[0])  # linear in alpha^2, at 0
    return per_chunk.mean(0), per_chunk


def index_matched(scene):
    """``scene`` with its material's index set to 1 (no Fresnel boundary): a volumetric path
    tracer's next-event estimation then reaches the lights from every scattering vertex."""
    material = scene.material
    medium = material.medium
    eta = np.ones(3)
    medium = dataclasses.replace(medium, eta=jnp.asarray(eta, jnp.asarray(medium.sigma_a).dtype))
    return dataclasses.replace(scene, material=dataclasses.replace(material, eta=eta, medium=medium))


def index_matched_truth(mi, scene, ply, spp, chunks, *, progress=True):
    """Subsurface radiance (H, W, 3) of an index-matched object (``eta`` 1: a ``null`` BSDF on
    the boundary) and each chunk's estimate.

    With no interface to refract through, ``volpath`` connects every scattering vertex to
    the lights (next-event estimation), so the noise is that of a plain volumetric path
    tracer: 18 % per pixel at 16 spp on the marble sphere, against 45 % at 1024 spp through
    the rough dielectric of :func:`subsurface_truth`. Nothing reflects at the surface, so
    the whole frame is subsurface light.
    """
    if np.any(np.abs(np.asarray(scene.material.eta) - 1) > 1e-12):
        raise ValueError(f"index_matched_truth needs eta = 1, got {np.asarray(scene.material.eta).tolist()}; "
                         "pass index_matched(scene)")
    per_chunk = np.zeros((chunks, scene.camera.height, scene.camera.width, 3))
    for c in range(3):  # one grey medium per channel (see _grey_medium)
        mscene = _mitsuba_scene(mi, scene, ply, {"type": "null"}, _grey_medium(scene.material.medium, c))
        for seed in range(chunks):
            t0 = time.perf_counter()
            per_chunk[seed, ..., c] = _render(mi, mscene, spp, seed)[..., c]
            if progress:
                print(f"  channel {c}, chunk {seed + 1}/{chunks}: {time.perf_counter() - t0:.0f} s", flush=True)
    return per_chunk.mean(0), per_chunk


CHANDRASEKHAR_CASES = ((1.0, 0.0), (50.0, 0.0), (50.0, 45.0), (20.0, 60.0))  # (view, light) degrees from the normal


def chandrasekhar_check(mi, *, albedo=0.18 / 0.241, spp=4096, chunks=2):
    """Mitsuba's index-matched frames of a large, uniformly lit plane against Chandrasekhar's
    exact reflection of every order (:func:`jsss.diffusion.incidence.index_matched_brdf`): the truth
    pipeline itself checked against a closed form. Rows (view deg, light deg, Mitsuba L/E,
    closed form L/E, noise of Mitsuba's mean, jsss's L/E without the oblique-incidence pass, with
    it, and with it and the exit-angle pass: Lambert frames, single scattering on, transport
    profile)."""
    from jsss.diffusion.incidence import index_matched_brdf
    from jsss.render import parse_scene

    rows = []
    for view_deg, light_deg in CHANDRASEKHAR_CASES:
        view, light = np.radians(view_deg), np.radians(light_deg)
        sigma_t = 0.241
        data = {"geometry": {"shape": "plane", "width": 200.0},
                "material": {"sigma_a": [sigma_t * (1 - albedo)] * 3, "sigma_s_prime": [sigma_t * albedo] * 3,
                             "eta": 1.0, "specular": 0.0},
                "lights": [{"type": "directional", "direction": [np.sin(light), 0.0, -np.cos(light)]}],
                # A narrow view from far away: every pixel sees the plane's middle at one angle.
                "camera": {"position": [0.0, -400 * np.sin(view), 400 * np.cos(view)], "look_at": [0, 0, 0],
                           "fov": 1.0, "resolution": [8, 8]},
                "render": {"texture_size": 64}}
        scene = parse_scene(data)
        with tempfile.TemporaryDirectory() as folder:
            mscene = _mitsuba_scene(mi, scene, _mesh_file(scene, folder), {"type": "null"},
                                    _grey_medium(scene.material.medium, 0))
            means = [_render(mi, mscene, spp, seed)[..., 0].mean() / np.cos(light) for seed in range(chunks)]
        exact = float(index_matched_brdf(albedo, np.cos(light), np.cos(view)))
        scene = dataclasses.replace(scene, material=dataclasses.replace(scene.material, profile_model="transport"))
        ours = []
        for oblique, exit_angle in ((False, False), (True, False), (True, True)):
            plan = plan_scene(scene, method="lambert", accuracy=0.01).replace(Pass.SPECULAR, False, "subsurface only")
            plan = plan.replace(Pass.SINGLE_SCATTERING, True, "check").replace(Pass.OBLIQUE_INCIDENCE, oblique, "check")
            plan = plan.replace(Pass.EXIT_ANGLE, exit_angle, "check")
            frame = np.asarray(render(scene, plan, dtype=jnp.float64).radiance)
            ours.append(float(frame[..., 0].mean()) / np.cos(light))
        rows.append((view_deg, light_deg, float(np.mean(means)), exact, float(np.std(means, ddof=1) / np.sqrt(chunks)),
                     *ours))
    return rows


def _ours(scene, method, samples=128, off=()):
    """jsss's subsurface radiance of ``scene`` with ``method`` (None: the planner's choice at the
    scene's accuracy, as a user gets it), the passes that ran, and the method."""
    image_space = method is not None and Method(method) == Method.IMAGE_SPACE
    plan = plan_scene(scene, method=method, samples=samples if image_space else None)
    plan = plan.replace(Pass.SPECULAR, False, "subsurface only")
    for name in off:
        plan = plan.replace(name, False, "benchmark: without it")
    passes = ", ".join(name for name in (Pass.SINGLE_SCATTERING, Pass.OBLIQUE_INCIDENCE, Pass.EXIT_ANGLE,
                                         Pass.FIRST_LEG, Pass.LAST_LEG, Pass.DEPOSIT_DEPTH) if plan.on(name))
    return render(scene, plan, dtype=jnp.float64).radiance, passes or "none", plan


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="40 x 30 pixels, 2 chunks")
    parser.add_argument("--spp", type=int, default=512, help="path-tracer samples per pixel per chunk")
    parser.add_argument("--scenes", nargs="*", default=["marble_sphere", "ketchup_plane"],
                        help="examples/ or benchmarks/calibration_scenes/ names")
    parser.add_argument("--profiles", nargs="*", default=["dipole", "transport"], choices=["dipole", "transport"],
                        help="jsss profile models to compare (the path tracer runs once for all); the first row "
                             "is always the scene as a user renders it: the planner's method, profile = auto")
    parser.add_argument("--methods", nargs="*", default=[m.value for m in Method])
    parser.add_argument("--variant", default="auto", choices=["auto", "llvm_ad_rgb", "scalar_rgb"],
                        help="Mitsuba variant (auto: LLVM where it runs, else scalar)")
    parser.add_argument("--chunks", type=int, default=None, help="independent seeds (default 8; --quick 2)")
    parser.add_argument("--index-matched", action="store_true",
                        help="eta set to 1 on both sides: no rough-dielectric extrapolation, "
                             "far less path-tracer noise")
    parser.add_argument("--black-walls", action="store_true",
                        help="black curtains around a plane's box walls: light enters only through the top")
    parser.add_argument("--chandrasekhar", action="store_true",
                        help="only check the path tracer against Chandrasekhar's exact plane reflection")
    args = parser.parse_args(argv)
    global BLACK_WALLS
    BLACK_WALLS = args.black_walls
    mi = _mitsuba(args.variant)
    if args.chandrasekhar:
        print(f"Mitsuba {mi.__version__} {mi.variant()}: index-matched plane (albedo 0.747, 200 mm, 30 mm deep) under "
              f"a directional light against Chandrasekhar's H-function reflection, {time.strftime('%Y-%m-%d')}")
        print("| view deg | light deg | Mitsuba L/E [1/sr] | closed form | Mitsuba / closed form - 1 | "
              "jsss / closed form - 1: no angular pass / oblique incidence / and exit angle |")
        print("|---:|---:|---:|---:|---:|---:|")
        for view, light, theirs, exact, noise, *ours in chandrasekhar_check(mi):
            shown = " / ".join(f"{100 * (x / exact - 1):+.1f} %" for x in ours)
            print(f"| {view:g} | {light:g} | {theirs:.5f} +- {noise:.5f} | {exact:.5f} | "
                  f"{100 * (theirs / exact - 1):+.2f} % | {shown} |")
        return
    width, height, chunks = (40, 30, 2) if args.quick else (80, 60, 8)
    chunks = args.chunks or chunks
    boundary = "index-matched (null boundary)" if args.index_matched else f"roughness {ROUGHNESS} -> 0 (in alpha^2)"
    boundary += ", a plane's box walls behind black curtains" if args.black_walls else ""
    print(f"transport truth: Mitsuba {mi.__version__} {mi.variant()} volpath, one grey medium per channel, {width}x{height}, "
          f"{chunks} chunks x {args.spp} spp, {boundary}, {time.strftime('%Y-%m-%d')}")
    with tempfile.TemporaryDirectory() as folder:
        for name in args.scenes:
            scene = _with_resolution(load_scene(_scene_file(name)), width, height)
            if args.index_matched:
                scene = index_matched(scene)
            ply = _mesh_file(scene, folder)
            t0 = time.perf_counter()
            lam, inner = lambert_check(mi, scene, ply, 4 * args.spp)
            print(f"\n## {name}: white Lambertian jsss / Mitsuba - 1 = "
                  + " / ".join(f"{100 * x:+.2f} %" for x in lam))
            if args.index_matched:
                truth, chunk = index_matched_truth(mi, scene, ply, args.spp, chunks, progress=False)
            else:
                truth, chunk = subsurface_truth(mi, scene, ply, args.spp, chunks)
            ratios = np.array([c[inner].sum(0) / truth[inner].sum(0) for c in chunk])
            noise = ratios.std(0, ddof=1) / np.sqrt(chunks)
            print(f"path tracer: {time.perf_counter() - t0:.0f} s; its own noise on the sums "
                  + " / ".join(f"{100 * x:.1f} %" for x in noise))
            print("| method | profile | passes | ratio R | ratio G | ratio B | rel. RMS R | G | B |")
            print("|---|---|---|---:|---:|---:|---:|---:|---:|")
            runs = [(None, "auto", ())] + [(method, profile, ()) for profile in args.profiles for method in args.methods]
            # What the passes for slanted and nearby light and for the exit angle change, on the
            # best configuration.
            runs.append((Method.TEXTURE_SPACE, "transport", (Pass.EXIT_ANGLE,)))
            runs.append((Method.TEXTURE_SPACE, "transport", (Pass.OBLIQUE_INCIDENCE, Pass.EXIT_ANGLE, Pass.DEPOSIT_DEPTH)))
            for method, profile, off in runs:
                material = scene.material if profile == "auto" else dataclasses.replace(
                    scene.material, profile_model=profile, profile=None)  # profile=None: a new request
                ours, passes, plan = _ours(dataclasses.replace(scene, material=material), method, off=off)
                if method is None:  # the defaults: say what the planner chose and what it predicted
                    chosen = next((e for e in plan.estimates if (e.method, e.knob) == (plan.method, plan.knob)), None)
                    knob = f"{plan.knob}, " if plan.knob else ""
                    method = f"default: {plan.method}" + (f" ({knob}predicted {100 * chosen.error:.1f} %)"
                                                          if chosen else "")
                    profile = f"auto: {plan.profile.model}" if plan.profile is not None else "auto"
                ratio = ours[inner].sum(0) / truth[inner].sum(0)
                # The path tracer's own per-pixel variance (from the chunks) is taken out of the
                # mean square, so the RMS measures jsss's error, not Mitsuba's noise.
                noise_var = np.var(np.array(chunk), axis=0, ddof=1)[inner].mean(0) / chunks
                # Where the noise is as large as what it is taken from, the run says so instead.
                mse = ((ours - truth)[inner] ** 2).mean(0) - noise_var
                power = (truth[inner] ** 2).mean(0) - noise_var
                rms = [f"{100 * np.sqrt(m / p):.1f} %" if m > 0 and p > 0 else "below noise"
                       for m, p in zip(mse, power)]
                print(f"| {method} | {profile} | {passes} | " + " | ".join(f"{r:.3f}" for r in ratio)
                      + " | "
                      + " | ".join(rms) + " |")


if __name__ == "__main__":
    main()
