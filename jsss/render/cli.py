"""``jsss-render``: render a TOML scene to PNG (display) and EXR (linear radiance).

Examples
--------
::

    jsss-render examples/marble_sphere.toml -o marble.png --plan --timings
    jsss-render examples/ketchup_plane.toml --method image-space --samples 64
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path


def _parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="jsss-render", description=__doc__.splitlines()[0])
    p.add_argument("scene", help="TOML scene file (see examples/)")
    p.add_argument("-o", "--output", default=None,
                   help="PNG to write (default: the scene's name .png); the linear EXR goes beside it")
    p.add_argument("--plan", action="store_true", help="print which passes run and why")
    p.add_argument("--timings", action="store_true", help="time each pass (compiles first, median of 3)")
    p.add_argument("--accuracy", type=float, default=None, help="override the scene's accuracy target")
    p.add_argument("--method", default="auto",
                   choices=("auto", "lambert", "normal-filtering", "image-space", "texture-space"),
                   help="how to render subsurface light (default: the planner's choice from its calibration table)")
    p.add_argument("--samples", type=int, default=None, help="image-space samples per pixel")
    p.add_argument("--normal-filter", default="spectral", choices=("spectral", "naive"),
                   help="which Patro filter --method normal-filtering uses")
    p.add_argument("--float64", action="store_true", help="render in float64 (default float32)")
    p.add_argument("--no-exr", action="store_true", help="write only the PNG")
    return p


def main(argv=None) -> int:
    args = _parser().parse_args(argv)
    import jax

    jax.config.update("jax_enable_x64", True)  # planning fits profiles in float64
    import jax.numpy as jnp
    import matplotlib.image

    from ..exr import ExrError, write_exr
    from . import SceneError, load_scene, plan_scene, render
    from .shading import tone_map

    try:
        scene = load_scene(args.scene)
        if args.accuracy is not None and not 0 < args.accuracy < 1:
            raise SceneError(f"--accuracy must lie in (0, 1); got {args.accuracy}.")
        method = {"auto": None, "normal-filtering": "normal filtering"}.get(args.method, args.method)
        plan = plan_scene(scene, accuracy=args.accuracy, method=method, samples=args.samples,
                          normal_filter=args.normal_filter)
        if args.plan:
            print(plan.describe(), flush=True)
        result = render(scene, plan, dtype=jnp.float64 if args.float64 else jnp.float32,
                        time_passes=args.timings)
        output = Path(args.output or Path(args.scene).with_suffix(".png").name)
        image, exposure = tone_map(result.radiance, exposure=scene.exposure)
        output.parent.mkdir(parents=True, exist_ok=True)
        matplotlib.image.imsave(output, image)
        written = [str(output)]
        if not args.no_exr:
            exr = output.with_suffix(".exr")
            write_exr(exr, result.radiance, attributes={"jsss_scene": str(args.scene), "jsss_exposure": exposure})
            written.append(str(exr))
    except (SceneError, ExrError, ValueError, OSError) as error:
        print(f"jsss-render: error: {error}", file=sys.stderr)
        return 2
    if args.timings:
        print("timings (ms):")
        for name, seconds in result.timings.items():
            print(f"  {name:<28} {1000 * seconds:9.1f}")
    print("wrote " + ", ".join(written))
    return 0


if __name__ == "__main__":
    sys.exit(main())
