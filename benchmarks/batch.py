"""fit-params batch throughput against the number of Dask workers (images per second).

    python benchmarks/batch.py [--images 50] [--size 256] [--workers 1 2 4] [--warm-only] [--platform cpu]
                               [--write docs/benchmarks/batch.md]

Writes ``--images`` synthetic camera images (marble, skin1, apple, ketchup in turn; transport
tables, shot and read noise) to a temporary folder, then times ``fit-params batch`` on them
once per worker count: the whole command as a user runs it (start-up, compilation in every
worker, fits, the table), so the ratio to one worker is what a user gains. One worker is the
in-process path (XLA threads over every core); Dask workers are separate processes. Every run starts with an empty compilation cache of its own (cold, as on a
new machine), then runs once more on the cache it filled (warm). ``--warm-only`` fills one shared
cache with a batch of 4 images first and times only warm runs (for many worker counts on a
machine lent for minutes). ``--platform`` sets ``JAX_PLATFORMS`` for the command (``cpu``, or
``cuda`` for a GPU: there the workers share one device). ``--write`` appends the dated table to a
markdown page.

"cores busy" is the CPU time of the command and all its processes (user + system, from
``getrusage`` of the waited-for children) over its wall time: how much of the machine one
run already uses, and so the most that more workers could add (cores / cores busy).
"""

from __future__ import annotations

import argparse
import os
import resource
import platform
import subprocess
import sys
import tempfile
import time

sys.path.insert(0, os.path.join(os.path.dirname(__file__), ".."))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)

from jsss import hankel  # noqa: E402
from jsss.materials import jensen2001  # noqa: E402
from measure.synth import synthesize, write_measurement  # noqa: E402

MATERIALS = ("marble", "skin1", "apple", "ketchup")
ETA = {"marble": 1.5, "skin1": 1.3, "apple": 1.3, "ketchup": 1.3}


def main(argv=None):
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--images", type=int, default=50)
    parser.add_argument("--size", type=int, default=256)
    parser.add_argument("--workers", type=int, nargs="*", default=[1, 2, 4])
    parser.add_argument("--warm-only", action="store_true")
    parser.add_argument("--platform", help="JAX_PLATFORMS for the command (default: JAX's choice)")
    parser.add_argument("--write", help="append the dated table to this markdown file")
    args = parser.parse_args(argv)
    lines = []

    def say(line):
        print(line, flush=True)
        lines.append(line)

    load = os.getloadavg()[0]
    say(f"\n### {time.strftime('%Y-%m-%d')}: {platform.machine()} x{os.cpu_count()} cores, load {load:.1f}, "
        f"JAX_PLATFORMS={args.platform or '(default)'}; {args.images} images of {args.size}^2, transport model\n")
    with tempfile.TemporaryDirectory() as folder:
        grid = hankel.hankel_grid()
        manifest = ["measurement,reference,dark,eta"]
        for i in range(args.images):
            name = MATERIALS[i % len(MATERIALS)]
            s = synthesize(jensen2001(name), size=args.size, photons_per_unit=1e5, seed=i, grid=grid,
                           model="transport")
            write_measurement(folder, s, name=f"{name}{i}")
            manifest.append(f"{name}{i}.exr,{name}{i}_ref.exr,{name}{i}_dark.exr,{ETA[name]}")
        with open(os.path.join(folder, "manifest.csv"), "w") as handle:
            handle.write("\n".join(manifest) + "\n")
        say("| workers | cache | seconds | images / s | x one worker (same cache state) | cores busy | failed rows |")
        say("|---:|---|---:|---:|---:|---:|---:|")
        base = {}
        platform_env = {"JAX_PLATFORMS": args.platform} if args.platform else {}
        if args.warm_only:
            shared = os.path.join(folder, "xla")
            with open(os.path.join(folder, "manifest.csv")) as handle:
                first = handle.read().splitlines()[:5]
            with open(os.path.join(folder, "warmup.csv"), "w") as handle:
                handle.write("\n".join(first) + "\n")
            for workers in sorted(set(args.workers)):  # every worker count's programs, once
                subprocess.run([sys.executable, "-m", "measure.commands.fit_params", "batch", "--manifest",
                                os.path.join(folder, "warmup.csv"), "--out", os.path.join(folder, f"warm{workers}.csv"),
                                "--workers", str(workers)], capture_output=True, stdin=subprocess.DEVNULL,
                               env={**os.environ, **platform_env, "JAX_COMPILATION_CACHE_DIR": shared})
        for workers in args.workers:
            cache = shared if args.warm_only else os.path.join(folder, f"xla{workers}")
            env = {**os.environ, **platform_env, "JAX_COMPILATION_CACHE_DIR": cache}
            for state in (("warm",) if args.warm_only else ("cold", "warm")):
                out = os.path.join(folder, f"table{workers}{state}.csv")
                before = resource.getrusage(resource.RUSAGE_CHILDREN)
                t0 = time.perf_counter()
                run = subprocess.run([sys.executable, "-m", "measure.commands.fit_params", "batch", "--manifest",
                                      os.path.join(folder, "manifest.csv"), "--out", out, "--workers", str(workers)],
                                     capture_output=True, text=True, stdin=subprocess.DEVNULL, env=env)
                seconds = time.perf_counter() - t0
                after = resource.getrusage(resource.RUSAGE_CHILDREN)
                cpu = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
                failed = sum(1 for line in open(out) if ",failed," in line) if os.path.exists(out) else args.images
                base.setdefault(state, seconds)
                say(f"| {workers} | {state} | {seconds:.1f} | {args.images / seconds:.2f} | "
                    f"{base[state] / seconds:.2f} | {cpu / seconds:.2f} of {os.cpu_count()} | {failed} |")
                if run.returncode not in (0, 1):
                    print(run.stderr[-2000:], file=sys.stderr)
    if args.write:
        with open(args.write, "a") as handle:
            handle.write("\n".join(lines) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
