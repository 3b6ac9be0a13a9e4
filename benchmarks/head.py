"""The head example's cost: ``jsss-render examples/head.toml`` cold and warm, against ``import jax``.

    python benchmarks/head.py [--repeats 3] [--markdown docs/benchmarks/head.md]

Each run is the command as a user types it, in a fresh process, with its caches in one
temporary folder (``JSSS_CACHE_DIR``): the first run fills it (*cold*: compiling every program,
fitting the layered skin profile, rasterizing the environment's 96 visibility maps), the
following ones read it (*warm*). The baseline is ``python -c "import jax"`` measured in the same
run, so the ratio holds on a noisy shared machine where the seconds do not. Also timed: the
planner's own choice for this frame, Lambert (``--method lambert``), and the passes of one warm
frame (``--timings``, compiled first, median of 3).
"""

from __future__ import annotations

import argparse
import datetime
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
SCENE = ROOT / "examples" / "head.toml"


def _seconds(command, env) -> float:
    start = time.perf_counter()
    subprocess.run(command, env=env, check=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, cwd=ROOT)
    return time.perf_counter() - start


def _render(out, *extra):
    command = Path(sys.executable).with_name("jsss-render")  # the console script, as a user runs it
    return [str(command if command.exists() else shutil.which("jsss-render")), str(SCENE), "-o", str(out), "-q", *extra]


def measure(repeats: int) -> dict:
    with tempfile.TemporaryDirectory() as folder:
        env = dict(os.environ, JSSS_CACHE_DIR=folder)
        env.pop("JAX_COMPILATION_CACHE_DIR", None)
        out = Path(folder) / "head.png"
        baseline = statistics.median(_seconds([sys.executable, "-c", "import jax"], env) for _ in range(repeats))
        cold = _seconds(_render(out), env)
        warm = [_seconds(_render(out), env) for _ in range(repeats)]
        _seconds(_render(out, "--method", "lambert"), env)  # its own programs, once
        lambert = [_seconds(_render(out, "--method", "lambert"), env) for _ in range(repeats)]
        timings = subprocess.run(_render(out, "--timings"), env=env, check=True, capture_output=True, text=True,
                                 cwd=ROOT).stdout
    passes = [line.strip().rsplit(None, 1) for line in timings.splitlines()
              if line.startswith("  ") and line.strip()[-1].isdigit()]
    return {"baseline": baseline, "cold": cold, "warm": statistics.median(warm), "warm_runs": warm,
            "lambert": statistics.median(lambert), "passes": [(name.strip(), float(ms)) for name, ms in passes]}


def markdown(result: dict, repeats: int) -> str:
    b = result["baseline"]
    cpu = f"{os.cpu_count()} cores, {platform.processor() or platform.machine()}"
    lines = [f"Head example, {datetime.date.today().isoformat()} (`python benchmarks/head.py`; {cpu})", "",
             (f"`jsss-render examples/head.toml` in a fresh process, 320 x 400, texture space at 512^2, the layered "
              f"skin, an HDR environment with 96 visibility maps, a key and a rim light with translucent shadow "
              f"maps. Baseline: `python -c \"import jax\"` in the same run, median of {repeats}."), "",
             "| run | seconds | x import jax |", "|---|---:|---:|",
             f"| `import jax` | {b:.2f} | 1.0 |",
             f"| cold (empty cache folder) | {result['cold']:.1f} | {result['cold'] / b:.1f} |",
             (f"| warm, median of {repeats} ({', '.join(f'{t:.1f}' for t in result['warm_runs'])}) "
              f"| {result['warm']:.1f} | {result['warm'] / b:.1f} |"),
             (f"| warm, `--method lambert` (the planner's own choice, 3.1 % predicted) "
              f"| {result['lambert']:.1f} | {result['lambert'] / b:.1f} |"), "",
             "Passes of one warm frame (`--timings`: compiled first, median of 3):", "",
             "| pass | ms |", "|---|---:|"]
    lines += [f"| {name} | {ms:.1f} |" for name, ms in result["passes"]]
    return "\n".join(lines) + "\n"


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--markdown", type=Path, help="write the table here (docs/benchmarks/head.md)")
    args = parser.parse_args(argv)
    text = markdown(measure(args.repeats), args.repeats)
    print(text)
    if args.markdown:
        args.markdown.write_text(text)


if __name__ == "__main__":
    main()
