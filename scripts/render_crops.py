"""Before/after crops of the sample pattern and the silhouettes (docs/silhouettes.png).

    python scripts/render_crops.py render DIR        # frames of the jsss that is imported
    python scripts/render_crops.py compare BEFORE AFTER [--out docs/silhouettes.png]

``render`` writes the linear radiance of two frames to ``DIR`` as .npy: the marble sphere by
image-space integration at 64 samples per pixel (where the pattern shows), and the backlit
skin by its planner's plan (its specular rim and silhouette). Run it once with an older
checkout first on ``PYTHONPATH`` (before) and once with this one (after); ``compare`` crops
both and shows them side by side at one exposure per crop.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
# (scene, method or None for the plan, samples, crop rows, crop columns, what to look at)
FRAMES = (("marble_sphere", "image-space", 64, (60, 140), (90, 190), "image-space 64 spp: the pattern"),
          ("marble_sphere", "image-space", 64, (20, 80), (110, 190), "marble: the silhouette"),
          ("skin_backlit", None, None, (30, 110), (165, 245), "backlit skin: the rim"))


def render_frames(out: Path):
    import jax

    jax.config.update("jax_enable_x64", True)
    import jsss
    from jsss.render import load_scene, plan_scene, render

    out.mkdir(parents=True, exist_ok=True)
    print(f"jsss from {Path(jsss.__file__).parent}", file=sys.stderr)
    for name, method, samples in {(f[0], f[1], f[2]) for f in FRAMES}:
        scene = load_scene(ROOT / "examples" / f"{name}.toml")
        knobs = {} if samples is None else {"samples": samples}
        plan = plan_scene(scene) if method is None else plan_scene(scene, method=method, **knobs)
        np.save(out / f"{name}-{method or 'plan'}.npy", render(scene, plan).radiance)


def compare(before: Path, after: Path, out: Path):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(2, len(FRAMES), figsize=(3.3 * len(FRAMES), 5.6))
    for column, (name, method, _, rows, cols, title) in enumerate(FRAMES):
        crops = [np.load(d / f"{name}-{method or 'plan'}.npy")[slice(*rows), slice(*cols)] for d in (before, after)]
        exposure = np.percentile(crops[1], 99.5)
        for row, (crop, label) in enumerate(zip(crops, ("before", "after"))):
            ax = axes[row, column]
            ax.imshow(np.clip(crop / exposure, 0, 1) ** (1 / 2.2), interpolation="nearest")
            ax.set_title(f"{title}\n{label}" if row == 0 else label, fontsize=8)
            ax.axis("off")
    fig.tight_layout()
    fig.savefig(out, dpi=110)
    print(f"wrote {out}")


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    sub = parser.add_subparsers(dest="command", required=True)
    r = sub.add_parser("render")
    r.add_argument("dir", type=Path)
    c = sub.add_parser("compare")
    c.add_argument("before", type=Path)
    c.add_argument("after", type=Path)
    c.add_argument("--out", type=Path, default=ROOT / "docs" / "silhouettes.png")
    args = parser.parse_args(argv)
    if args.command == "render":
        render_frames(args.dir)
    else:
        compare(args.before, args.after, args.out)


if __name__ == "__main__":
    main()
