"""``jsss-render``: render TOML scenes to PNG (display) and EXR (linear radiance).

Examples
--------
::

    jsss-render examples/marble_sphere.toml -o marble.png --plan --timings
    jsss-render examples/ketchup_plane.toml --method image-space --samples 64
    jsss-render examples/*.toml -o renders/
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from .passes import Method

_EPILOG = """\
examples:
  jsss-render examples/marble_sphere.toml -o marble.png --plan --timings
  jsss-render examples/ketchup_plane.toml --method image-space --samples 64
  jsss-render examples/*.toml -o renders/       (several scenes: -o is a directory)
  jsss-render fit scene.toml photo.exr          (fit the material to a photo: jsss-render fit --help)

The scene format (geometry, material, lights, camera, render) is described in the README,
section "Scene files". A scene that fails is reported in one line; the others still render
and the exit status is 2.
"""


def _parser() -> argparse.ArgumentParser:
    from .. import __version__

    p = argparse.ArgumentParser(prog="jsss-render", epilog=_EPILOG, formatter_class=argparse.RawDescriptionHelpFormatter,
                                description="Render TOML scenes of translucent objects to a PNG (display) and an EXR "
                                            "(linear radiance), planning the passes each scene needs.")
    p.add_argument("scenes", nargs="+", metavar="scene", help="TOML scene file(s) (see examples/)")
    p.add_argument("-o", "--output", default=None,
                   help="PNG to write (default: the scene's name .png); with several scenes a directory. The linear "
                        "EXR goes beside each PNG")
    p.add_argument("--plan", action="store_true", help="print which passes run and why")
    p.add_argument("--timings", action="store_true", help="time each pass (compiles first, median of 3)")
    p.add_argument("--accuracy", type=float, default=None, help="override the scene's accuracy target")
    p.add_argument("--method", default="auto",
                   choices=("auto", *(m.option for m in Method)),
                   help="how to render subsurface light (default: the planner's choice from its calibration table)")
    p.add_argument("--samples", type=int, default=None, help="image-space samples per pixel")
    p.add_argument("--normal-filter", default="spectral", choices=("spectral", "naive"),
                   help="which Patro filter --method normal-filtering uses")
    p.add_argument("--float64", action="store_true", help="render in float64 (default float32)")
    p.add_argument("--no-exr", action="store_true", help="write only the PNG")
    p.add_argument("-q", "--quiet", action="store_true",
                   help="no progress lines (they go to stderr, and only when it is a terminal)")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


class _Progress:
    """Progress lines on stderr for the phases that take seconds (compilation above all)."""

    def __init__(self, enabled: bool):
        self.enabled, self.start = enabled, time.perf_counter()

    def __call__(self, message: str):
        if self.enabled:
            print(f"jsss-render: [{time.perf_counter() - self.start:5.1f} s] {message}", file=sys.stderr, flush=True)


def _outputs(args) -> list[Path]:
    """The PNG path of each scene: -o as a file for one scene, as a directory for several."""
    names = [Path(Path(scene).with_suffix(".png").name) for scene in args.scenes]
    if args.output is None:
        return names
    output = Path(args.output)
    if len(args.scenes) == 1 and output.suffix.lower() == ".png":
        return [output]
    if len(args.scenes) == 1 and not output.is_dir() and output.suffix:
        raise ValueError(f"-o {output}: the output is a PNG (name.png) or a directory; got suffix {output.suffix}.")
    return [output / name for name in names]


def _render_one(scene_path, output: Path, args, say) -> list[str]:
    import jax.numpy as jnp
    import matplotlib.image

    from measure.exr import write_exr
    from . import SceneError, load_scene, plan_scene, render
    from .shading import tone_map

    say(f"{scene_path}: loading the scene")
    scene = load_scene(scene_path)
    if args.accuracy is not None and not 0 < args.accuracy < 1:
        raise SceneError(f"--accuracy must lie in (0, 1); got {args.accuracy}.")
    method = None if args.method == "auto" else Method(args.method)
    say(f"{scene_path}: planning (fits the material's profile)")
    plan = plan_scene(scene, accuracy=args.accuracy, method=method, samples=args.samples,
                      normal_filter=args.normal_filter)
    if args.plan:
        print(plan.describe(), flush=True)
    say(f"{scene_path}: rendering with {plan.method} (the first frame compiles: 10-20 s)")
    result = render(scene, plan, dtype=jnp.float64 if args.float64 else jnp.float32, time_passes=args.timings)
    image, exposure = tone_map(result.radiance, exposure=scene.exposure)
    output.parent.mkdir(parents=True, exist_ok=True)
    matplotlib.image.imsave(output, image)
    written = [str(output)]
    if not args.no_exr:
        exr = output.with_suffix(".exr")
        write_exr(exr, result.radiance, attributes={"jsss_scene": str(scene_path), "jsss_exposure": exposure})
        written.append(str(exr))
    if args.timings:
        print(f"timings (ms) of {scene_path}:")
        for name, seconds in result.timings.items():
            print(f"  {name:<28} {1000 * seconds:9.1f}")
    say(f"{scene_path}: done")
    return written


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)  # planning fits profiles in float64
    from fitting.programs import enable_compilation_cache

    enable_compilation_cache()  # a command's compiled programs are kept on disk for the next run
    from .normal_filter import keep_spectra_in
    from fitting.programs import default_cache_dir
    keep_spectra_in(default_cache_dir())

    from measure.exr import ExrError
    from . import SceneError

    say = _Progress(not args.quiet and sys.stderr.isatty())
    try:
        outputs = _outputs(args)
    except ValueError as error:
        print(f"jsss-render: error: {error}", file=sys.stderr)
        return 2
    failed = 0
    for scene_path, output in zip(args.scenes, outputs):
        try:
            written = _render_one(scene_path, output, args, say)
        except (SceneError, ExrError, ValueError, OSError) as error:
            message = str(error).splitlines()[0] if str(error) else type(error).__name__
            print(f"jsss-render: error: {message}", file=sys.stderr)
            failed += 1
            continue
        print("wrote " + ", ".join(written), flush=True)
    return 2 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
