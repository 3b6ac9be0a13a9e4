"""``fit-params batch``: many measurements in, one parameter table out.

Jobs come from the naming rule (NAME.ext, NAME_ref.ext, optional NAME_dark.ext) or a manifest
CSV. They are fitted in this process or, with ``--workers N`` or ``--scheduler ADDRESS``, on
Dask worker processes that each keep one compiled fit warm. Every job gives a row: a failure is
recorded with its error, never dropped; the table is written atomically, and ``--resume``
keeps the rows already fitted.
"""

from __future__ import annotations

import argparse
import contextlib
import csv
import glob
import logging
import re
import sys
from pathlib import Path

from .cli import PROG, UsageError, _fit_arguments, _enable_x64, _load_and_fit, _version, _view_angle, \
    _write_atomically

__all__ = ["batch"]

_ROLE = re.compile(r"_(ref|dark)$|_ref_t\d+$|_t\d+$")


def _find_jobs(target, manifest):
    """(measurement, reference, dark, overrides) tuples from a manifest or the naming rule."""
    if manifest:
        manifest = Path(manifest)
        if not manifest.is_file():
            raise UsageError(f"{manifest}: no such manifest")
        jobs = []
        with manifest.open(newline="") as handle:
            reader = csv.DictReader(handle)
            if not reader.fieldnames or not {"measurement", "reference"} <= set(reader.fieldnames):
                raise UsageError(f"{manifest}: needs columns measurement,reference[,dark,pixel_mm,eta,reference_reflectance]")
            for row in reader:
                base = manifest.parent
                overrides = {k: float(row[k]) for k in ("pixel_mm", "eta", "reference_reflectance") if row.get(k)}
                jobs.append((base / row["measurement"], base / row["reference"],
                             (base / row["dark"]) if row.get("dark") else None, overrides))
        return jobs
    path = Path(target)
    if not path.is_dir() and not glob.has_magic(str(target)):
        raise UsageError(f"{target}: no such directory" + ("" if not path.exists() else " (a file: give its directory, "
                                                           "a glob or --manifest)"))
    from .photo import RAW_SUFFIXES

    suffixes = {".exr", ".tif", ".tiff", ".png", *RAW_SUFFIXES}
    candidates = sorted(path.iterdir()) if path.is_dir() else sorted(Path(p) for p in glob.glob(str(target)))
    candidates = [p for p in candidates if p.suffix.lower() in suffixes and not _ROLE.search(p.stem)]
    if not candidates:
        raise UsageError(f"{target}: no measurement images found (NAME.exr, or a raw, TIFF or PNG file, with "
                         "NAME_ref beside it)")
    jobs = []
    for m in candidates:
        dark = m.with_name(f"{m.stem}_dark{m.suffix}")
        jobs.append((m, m.with_name(f"{m.stem}_ref{m.suffix}"), dark if dark.exists() else None, {}))
    return jobs


def _progress(done, total, label, stream=sys.stderr):
    width = 30
    filled = int(width * done / max(total, 1))
    stream.write(f"\r[{'#' * filled}{'.' * (width - filled)}] {done}/{total} {label[:40]:<40}")
    if done == total:
        stream.write("\n")
    stream.flush()


_ROW_KEYS = ("sigma_a", "sigma_s_prime", "sigma_a_err", "sigma_s_prime_err", "total_reflectance", "mean_free_path_mm",
             "rel_residual", "chi2_reduced", "converged", "quality", "field_diffusion_lengths")


def _fit_row(job, options) -> dict:
    """One batch row: the fit of one measurement, or its failure (recorded, never dropped).

    A plain function of picklable arguments, so that it runs the same in this process or on
    a Dask worker (where the compiled fit and the grid stay warm between images)."""
    _enable_x64()
    measurement, reference, dark, overrides = job
    row = {"file": str(measurement), "status": "ok", "error": "", "warnings": ""}
    try:
        result = _load_and_fit(measurement, reference, pixel_mm=overrides.get("pixel_mm", options["pixel_mm"]),
                               eta=overrides.get("eta", options["eta"]), dark=dark,
                               reference_reflectance=overrides.get("reference_reflectance",
                                                                   options["reference_reflectance"]),
                               model=options["model"], g=options["g"], view_angle_deg=options["view_angle_deg"],
                               white_balance=options["white_balance"])
        table = result.table()
        for key in _ROW_KEYS:
            for ch, value in zip(table["channels"], table[key]):
                row[f"{key}_{ch}"] = value
        row["warnings"] = "; ".join(result.warnings)
    except Exception as error:  # recorded in the table, never dropped
        row.update(status="failed", error=f"{type(error).__name__}: {error}")
    return row


# Worker processes keep BLAS/OpenMP to one thread each; XLA keeps its own thread pool. On this
# 2-core machine one process already keeps both cores busy (XLA threads the fit's dense
# transforms): forcing one XLA thread per worker made a fit 2.3x slower, and 2 workers of the
# default threading were 0.78-0.84x one process (benchmarks/batch.py). Workers pay off with
# more cores than one fit can use, and on a cluster.
_WORKER_ENV = {"OMP_NUM_THREADS": "1", "OPENBLAS_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}


def _rows(jobs, args):
    """Fit every job: in this process (one worker), on local Dask worker processes
    (``--workers N``) or on the cluster at ``--scheduler``. Rows come back in job order."""
    options = dict(pixel_mm=args.pixel_mm, eta=args.eta, reference_reflectance=args.reference_reflectance,
                   model=args.model, g=args.g, view_angle_deg=_view_angle(args), white_balance=args.white_balance)
    if not jobs:
        return []
    if args.workers == 1 and not args.scheduler:
        rows = []
        for i, job in enumerate(jobs):
            _progress(i, len(jobs), job[0].name)
            rows.append(_fit_row(job, options))
        _progress(len(jobs), len(jobs), "done")
        return rows
    try:
        from dask.distributed import Client, LocalCluster, as_completed
    except ImportError:
        raise UsageError("--workers/--scheduler need dask.distributed: pip install 'dask[distributed]'") from None
    with contextlib.ExitStack() as stack:
        if args.scheduler:
            try:
                client = stack.enter_context(Client(args.scheduler, timeout="10s"))
            except OSError as error:
                raise UsageError(f"--scheduler {args.scheduler}: cannot connect ({error})") from None
        else:
            cluster = stack.enter_context(LocalCluster(n_workers=args.workers, threads_per_worker=1, processes=True,
                                                       dashboard_address=None, env=_WORKER_ENV,
                                                       silence_logs=logging.ERROR))
            client = stack.enter_context(Client(cluster))
        futures = {client.submit(_fit_row, job, options, pure=False): i for i, job in enumerate(jobs)}
        rows = [None] * len(jobs)
        _progress(0, len(jobs), f"{len(client.scheduler_info()['workers'])} workers")
        for done, future in enumerate(as_completed(futures), start=1):
            i = futures[future]
            try:
                rows[i] = future.result()
            except Exception as error:  # a worker that died: the row still says so
                rows[i] = {"file": str(jobs[i][0]), "status": "failed", "error": f"{type(error).__name__}: {error}"}
            _progress(done, len(jobs), jobs[i][0].name)
    return rows


def _resumed(jobs, out):
    """Rows of ``out`` already fitted (status ok), by file, and the jobs still to run (``--resume``)."""
    out = Path(out)
    if not out.is_file():
        return {}, jobs
    if out.suffix == ".parquet":
        try:
            import pyarrow.parquet as pq
        except ImportError:
            raise UsageError(f"{out}: resuming a .parquet table needs pyarrow") from None
        old = pq.read_table(out).to_pylist()
    else:
        with out.open(newline="") as handle:
            old = list(csv.DictReader(handle))
    done = {row["file"]: row for row in old if row.get("status") == "ok"}
    return {f: row for f, row in done.items() if f in {str(job[0]) for job in jobs}}, \
        [job for job in jobs if str(job[0]) not in done]


def _write_table(rows, out):
    """Write CSV (or Parquet) atomically (temp file beside ``out``, then rename): no partial tables."""
    out = Path(out)
    # Columns in the order the rows hold them (the image's channel order, e.g. R, G, B), not sorted.
    columns = list(dict.fromkeys(["file", "status", "error"] + [k for r in rows for k in r]))

    def write(tmp):
        if out.suffix == ".parquet":
            try:
                import pyarrow as pa
                import pyarrow.parquet as pq
            except ImportError:
                raise UsageError(f"{out}: writing .parquet needs pyarrow; install it or use .csv") from None
            pq.write_table(pa.Table.from_pylist([{c: r.get(c) for c in columns} for r in rows]), tmp)
        else:
            with open(tmp, "w", newline="") as handle:
                writer = csv.DictWriter(handle, fieldnames=columns)
                writer.writeheader()
                writer.writerows(rows)

    _write_atomically(out, write)


def batch(argv) -> int:
    """Run ``fit-params batch ARGV``; returns the exit status (1 if any row failed)."""
    parser = argparse.ArgumentParser(prog=f"{PROG} batch", description=(
        "Fit many measurements. Naming rule: NAME.exr is a measurement, NAME_ref.exr its reference, NAME_dark.exr "
        "its optional dark frame; or list them in a manifest CSV (columns measurement, reference, and optionally dark, "
        "pixel_mm, eta, reference_reflectance; paths relative to the manifest). A file that fails becomes a row with "
        "status 'failed' and its error."))
    parser.add_argument("target", nargs="?", help="directory or glob of measurement EXRs")
    parser.add_argument("--out", required=True, help="output table (.csv, or .parquet with pyarrow)")
    parser.add_argument("--manifest", help="CSV listing the measurements instead of the naming rule")
    _fit_arguments(parser)
    parser.add_argument("--workers", type=int, default=1,
                        help="local Dask worker processes fitting in parallel (default 1: in this process); each "
                             "compiles the fit once and reuses it for its images")
    parser.add_argument("--scheduler", metavar="ADDRESS",
                        help="fit on an existing dask.distributed cluster (e.g. tcp://host:8786) instead")
    parser.add_argument("--resume", action="store_true",
                        help="keep the rows of --out that are already fitted (status ok) and fit only the rest")
    parser.add_argument("--version", action="version", version=_version())
    args = parser.parse_args(argv)
    if not args.target and not args.manifest:
        raise UsageError("batch needs a directory/glob or --manifest")
    if args.workers < 1:
        raise UsageError(f"--workers must be at least 1; got {args.workers}")
    jobs = _find_jobs(args.target, args.manifest)
    kept, todo = _resumed(jobs, args.out) if args.resume else ({}, jobs)
    if kept:
        print(f"resuming: {len(kept)} row(s) of {args.out} already fitted, {len(todo)} to fit", file=sys.stderr)
    _enable_x64()
    new = {row["file"]: row for row in _rows(todo, args)}
    rows = [new.get(str(job[0])) or kept[str(job[0])] for job in jobs]
    _write_table(rows, args.out)
    failed = [r for r in rows if r["status"] != "ok"]
    print(f"{len(rows) - len(failed)} fitted, {len(failed)} failed; table written to {args.out}")
    for r in failed:
        print(f"  failed: {r['file']}: {r['error']}", file=sys.stderr)
    return 1 if failed else 0
