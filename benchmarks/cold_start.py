"""Cold start of the console commands: a new process, the persistent compilation cache filled.

    PYTHONPATH=. python benchmarks/cold_start.py [--repeats 5] [--markdown docs/benchmarks/cold_start.md]
        [--tree DIR]

Each command is a fresh interpreter, ``python -m measure.commands.render`` (what the
``jsss-render`` script runs) and ``python -m measure.commands.fit_params``, in a temporary cache
folder (``JSSS_CACHE_DIR``) that one untimed warm-up run of each command fills: XLA's compiled
programs, the stored executables of the renders and fits, spectra and tables. What a second
start still pays is importing Python modules, loading the executables, and tracing and lowering
whatever is not stored. Python writes its bytecode as a user's does (this machine's environment
sets ``PYTHONDONTWRITEBYTECODE``, which would compile jsss's sources at every start). The
baseline is ``python -c "import jax"``, timed in the same rounds: the commands run interleaved
with it, ``--repeats`` rounds, so that a shared machine's load falls on all alike. The ratio is
the command's median wall time over the baseline's median; issue 35 asks at most 3 for
``jsss-render examples/marble_sphere.toml``.

The import breakdown is ``python -X importtime`` of one more run of each command: the time
spent importing, summed per top-level package (each module's own time, so nothing counts
twice). ``--tree DIR`` runs another copy of the repository (to compare a change with the code
before it: copy the tree, put the old files back, point ``--tree`` at it). ``--markdown``
rewrites the page but keeps its hand-kept section ``## Earlier runs`` (such comparisons).
"""

from __future__ import annotations

import argparse
import collections
import datetime
import os
import platform
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
BASELINE = "python -c \"import jax\""
EARLIER = "## Earlier runs"  # the page's hand-kept section, which --markdown keeps


def commands(out: Path) -> dict[str, list[str]]:
    """Label -> argv (after the interpreter) of each command timed, the baseline first."""
    return {
        BASELINE: ["-c", "import jax"],
        "jsss-render --help": ["-m", "measure.commands.render", "--help"],
        "jsss-render examples/marble_sphere.toml": ["-m", "measure.commands.render", "examples/marble_sphere.toml",
                                                    "-o", str(out / "marble_sphere.png"), "-q"],
        "jsss-render examples/ketchup_plane.toml": ["-m", "measure.commands.render", "examples/ketchup_plane.toml",
                                                    "-o", str(out / "ketchup_plane.png"), "-q"],
        "fit-params --demo": ["-m", "measure.commands.fit_params", "--demo", "-q"],
    }


def _environment(cache: Path) -> dict[str, str]:
    env = {k: v for k, v in os.environ.items()
           if k not in ("JAX_COMPILATION_CACHE_DIR", "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS", "JSSS_CACHE_DIR",
                        "JSSS_COMPILATION_CACHE", "PYTHONPATH", "PYTHONDONTWRITEBYTECODE")}
    return env | {"JSSS_CACHE_DIR": str(cache)}


def _run(argv: list[str], tree: Path, env: dict[str, str], *, extra=()) -> tuple[float, str]:
    """Wall time of one fresh interpreter running ``argv``, and its stderr."""
    t0 = time.perf_counter()
    done = subprocess.run([sys.executable, *extra, *argv], check=False, cwd=tree, env=env, capture_output=True, text=True,
                          stdin=subprocess.DEVNULL, timeout=900)
    seconds = time.perf_counter() - t0
    if done.returncode != 0:
        raise SystemExit(f"{' '.join(argv)} failed ({done.returncode}):\n{done.stderr[-2000:]}")
    return seconds, done.stderr


def import_breakdown(stderr: str) -> tuple[float, dict[str, float]]:
    """(total seconds importing, seconds per top-level package) from ``-X importtime`` output."""
    per_package: dict[str, float] = collections.Counter()
    total = 0.0
    for line in stderr.splitlines():
        if not line.startswith("import time:") or "|" not in line:
            continue
        _, own, cumulative, name = (part.strip() for part in line.replace("import time:", "|", 1).split("|"))
        if not own.isdigit():  # the header line
            continue
        per_package[name.split(".")[0]] += int(own) / 1e6
        if not line.split("|")[2].startswith("  "):  # a top-level import: its cumulative time
            total += int(cumulative) / 1e6
    return total, dict(per_package)


def measure(repeats: int, tree: Path) -> dict:
    with tempfile.TemporaryDirectory(prefix="jsss-cold-start-") as folder:
        folder = Path(folder)
        env = _environment(folder / "cache")
        argvs = commands(folder)
        for label, argv in argvs.items():  # the warm-up: fills the caches
            print(f"warm-up: {label}", file=sys.stderr)
            _run(argv, tree, env)
        times = {label: [] for label in argvs}
        for round_ in range(repeats):
            for label, argv in argvs.items():
                times[label].append(_run(argv, tree, env)[0])
            print(f"round {round_ + 1}/{repeats}: " + ", ".join(f"{t[-1]:.2f}" for t in times.values()),
                  file=sys.stderr)
        imports = {label: import_breakdown(_run(argv, tree, env, extra=("-X", "importtime"))[1])
                   for label, argv in argvs.items() if label != BASELINE}
    return {"times": times, "imports": imports}


def table(result: dict) -> list[str]:
    times, imports = result["times"], result["imports"]
    base = statistics.median(times[BASELINE])
    lines = ["| command | runs | median s | min - max s | x `import jax` |", "|---|---:|---:|---:|---:|"]
    for label, samples in times.items():
        lines.append(f"| `{label}` | {len(samples)} | {statistics.median(samples):.2f} | "
                     f"{min(samples):.2f} - {max(samples):.2f} | {statistics.median(samples) / base:.2f} |")
    packages = sorted({p for _, per in imports.values() for p, s in per.items() if s >= 0.05},
                      key=lambda p: -max(per.get(p, 0.0) for _, per in imports.values()))
    lines += ["", ("Seconds importing (one `-X importtime` run each; each module's own time, summed per top-level "
                   "package, packages under 0.05 s in every command left out):"), "",
              "| command | all imports | " + " | ".join(packages) + " |",
              "|---|---:|" + "---:|" * len(packages)]
    for label, (total, per) in imports.items():
        lines.append(f"| `{label}` | {total:.2f} | " + " | ".join(f"{per.get(p, 0.0):.2f}" for p in packages) + " |")
    return lines


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeats", type=int, default=5, help="timed rounds (default 5)")
    parser.add_argument("--markdown", type=Path, default=None, help="write the dated page here")
    parser.add_argument("--tree", type=Path, default=ROOT, help="the repository copy to run (default: this one)")
    args = parser.parse_args(argv)
    result = measure(args.repeats, args.tree.resolve())
    lines = table(result)
    print("\n".join(lines))
    if args.markdown:
        today = datetime.date.today().isoformat()
        about = (f"`PYTHONPATH=. python benchmarks/cold_start.py --markdown {args.markdown}` ({os.cpu_count()} cores, "
                 f"{platform.machine()}, CPU, Python {platform.python_version()}). Each run is a new process with the "
                 "persistent compilation cache already filled (a fresh cache folder, filled by one untimed run of "
                 f"each command). {args.repeats} rounds, the commands interleaved with the baseline `python -c "
                 "\"import jax\"`; the ratio is the command's median over the baseline's median. Issue 35's target: "
                 "`jsss-render examples/marble_sphere.toml` at most 3x `import jax`. The commands run as "
                 "`python -m measure.commands.render` and `python -m measure.commands.fit_params`, what the "
                 "`jsss-render` and `fit-params` scripts run.")
        head = [f"# Cold start of the commands, {today}", "", about, ""]
        page = args.markdown.read_text() if args.markdown.exists() else ""
        kept = "\n" + page[page.index(EARLIER):] if EARLIER in page else ""  # hand-kept comparisons stay
        args.markdown.write_text("\n".join(head + lines) + "\n" + kept)
        print(f"wrote {args.markdown}", file=sys.stderr)


if __name__ == "__main__":
    main()
