"""What every console command shares: JAX's setup and the caches, progress, exit status 2, the
version string, atomic writes, and subcommands beside a default command.

Library code below the commands prints nothing, changes no global configuration and writes no
file unless asked. A command asks here, before its first computation (:func:`start`):

* float64 (``jax_enable_x64``): fits and the planner's profile fits need it;
* XLA's persistent compilation cache in :func:`compilation_cache_dir`, and in the same folder
  the fits' traced programs and Hankel grids (:func:`fitting.programs.keep_programs_in`), so
  that a second start neither compiles nor traces again;
* for commands that render, the Laplacian spectra of the meshes in ``spectra/`` of
  :func:`cache_dir` (:func:`jsss.render.normal_filter.keep_spectra_in`).

Bad input (a :class:`UsageError`, or any ``ValueError``/``OSError`` of the library, whose
messages name the file, the key or the argument) ends a command with one line on stderr and
exit status 2, never a traceback (:func:`exit_status`).
"""

from __future__ import annotations

import argparse
import functools
import os
import sys
import tempfile
import time
import warnings
from pathlib import Path

__all__ = ["MAP_BUDGET", "Progress", "UsageError", "add_commands", "cache_dir", "compilation_cache_dir", "enable_caches",
           "error_line", "exit_status", "fit_grid", "float64", "memory_maps", "release_compiled_programs", "start",
           "version", "write_atomically", "write_png", "write_text"]


class UsageError(ValueError):
    """A problem with the command line or the input files, reported in one line (exit status 2)."""


def version(prog: str) -> str:
    """``PROG (jsss) VERSION``, from the installed metadata: importing jsss (and JAX) for
    ``--version`` or ``--help`` took 2-6 s."""
    from importlib.metadata import PackageNotFoundError
    from importlib.metadata import version as installed

    try:
        return f"{prog} (jsss) {installed('jsss')}"
    except PackageNotFoundError:  # a source tree that was not installed
        return f"{prog} (jsss) unknown"


# ----------------------------------------------------------------------------- JAX and the caches
def cache_dir() -> Path:
    """``$JSSS_CACHE_DIR``, else ``$XDG_CACHE_HOME/jsss``, else ``~/.cache/jsss``."""
    if os.environ.get("JSSS_CACHE_DIR"):
        return Path(os.environ["JSSS_CACHE_DIR"])
    return Path(os.environ.get("XDG_CACHE_HOME", Path.home() / ".cache")) / "jsss"


def compilation_cache_dir() -> Path | None:
    """Where the commands keep compiled (and traced) programs: ``$JAX_COMPILATION_CACHE_DIR`` if
    set (JAX's own variable), else ``xla/`` in :func:`cache_dir`; None where
    ``JSSS_COMPILATION_CACHE=0`` turns it off."""
    if os.environ.get("JSSS_COMPILATION_CACHE", "1") == "0":
        return None
    if os.environ.get("JAX_COMPILATION_CACHE_DIR"):
        return Path(os.environ["JAX_COMPILATION_CACHE_DIR"])
    return cache_dir() / "xla"


def enable_caches(*, spectra: bool = False) -> Path | None:
    """Turn on JAX's persistent compilation cache and the store of traced programs at
    :func:`compilation_cache_dir`, and with ``spectra`` keep the renderer's Laplacian spectra,
    layered profiles and environment visibility maps in :func:`cache_dir` (importing the renderer costs 0.3 s, so commands that do not render leave
    it off).

    Every program is kept, however quick to compile (unless ``JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS``
    says otherwise): the head example compiles 233 programs of about 25 ms each, 5.7 s of every
    run when only those over half a second were kept. An unwritable folder gives a warning and no
    cache (the command still runs). Returns the folder, or None.
    """
    import jax

    from fitting.programs import keep_programs_in

    if spectra:
        from jsss.render.lighting import keep_visibility_maps_in
        from jsss.render.normal_filter import keep_spectra_in
        from jsss.render.profiles import keep_profiles_in

        keep_spectra_in(cache_dir())
        keep_profiles_in(cache_dir())
        keep_visibility_maps_in(cache_dir())
    path = compilation_cache_dir()
    if path is None:
        return None
    try:
        path.mkdir(parents=True, exist_ok=True)
    except OSError as error:
        warnings.warn(f"{path}: cannot keep compiled programs there ({error}); set JAX_COMPILATION_CACHE_DIR "
                      "or JSSS_CACHE_DIR to a writable directory", stacklevel=2)
        return None
    jax.config.update("jax_compilation_cache_dir", str(path))
    if "JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS" not in os.environ:  # JAX read it already (the tests set 0.1)
        jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    # No size limit (JAX's default). A limit turns on JAX's eviction, which reads an "-atime" file
    # beside every entry on each write: a folder filled without one (an older jsss, or JAX's own
    # default) then failed every write with a warning, and each new program cost a scan of the
    # whole folder (25 ms at 1264 entries). A half-written entry that another process reads fails
    # to decompress, which JAX reports and recompiles.
    keep_programs_in(path)  # JAX's cache reads only its own *-cache files there
    return path


def float64() -> None:
    """Turn on float64 (``jax_enable_x64``) for this process: commands compute in it."""
    import jax

    jax.config.update("jax_enable_x64", True)


def start(*, spectra: bool = False) -> None:
    """A command's JAX: float64 and the caches (:func:`enable_caches`), turned on once per
    process (a batch worker calls it for every image); ``spectra`` also keeps the renderer's
    Laplacian spectra on disk."""
    _start_once()
    if spectra:
        from jsss.render.lighting import keep_visibility_maps_in
        from jsss.render.normal_filter import keep_spectra_in
        from jsss.render.profiles import keep_profiles_in

        keep_spectra_in(cache_dir())
        keep_profiles_in(cache_dir())
        keep_visibility_maps_in(cache_dir())


@functools.lru_cache(maxsize=1)
def _start_once() -> None:
    float64()
    enable_caches()


# Linux gives a process at most vm.max_map_count (65530 by default) memory maps, and each XLA
# CPU executable a process keeps holds about 6-13 of them (its code and data sections); JAX keeps
# every program it compiled. A process past the limit segfaults inside XLA: the test suite's
# long-lived workers did, four times (12-05 to 12-07; one measured at 63100 maps, 7.1 GB).
MAP_BUDGET = 30000


def memory_maps() -> int | None:
    """This process's number of memory maps (Linux), or None where ``/proc`` does not say."""
    try:
        with open("/proc/self/maps", "rb") as maps:
            return sum(1 for _ in maps)
    except OSError:
        return None


def release_compiled_programs(budget: int | None = None) -> bool:
    """In a process that holds more than ``budget`` (default :data:`MAP_BUDGET`) memory maps,
    let go of every compiled program: JAX's (``jax.clear_caches()``) and those loaded through
    :mod:`jsss.stored_programs`. The next call of each compiles it again, or loads it from the
    compilation cache. For long-lived processes that compile many shapes (a batch's images, the
    test suite's workers); returns whether it let go."""
    import gc

    import jax

    from jsss.stored_programs import forget_loaded_programs

    maps = memory_maps()
    if maps is None or maps <= (MAP_BUDGET if budget is None else budget):
        return False
    jax.clear_caches()
    forget_loaded_programs()
    gc.collect()
    return True


@functools.lru_cache(maxsize=None)
def fit_grid():
    """The fits' Hankel grid, once per process, and from the cache after the first start
    (building it is 3 s of Bessel functions; :func:`fitting.programs.stored_hankel_grid`)."""
    from fitting.programs import stored_hankel_grid

    start()  # the grid's dtype, and the folder it is kept in
    return stored_hankel_grid()


# ----------------------------------------------------------------------------- progress
class Progress:
    """A command's progress on stderr: one line per phase that takes seconds (reading,
    compiling), ``PROG: [  1.2 s] message``, and a bar over a batch's jobs (tqdm).

    ``enabled`` None shows them only where stderr is a terminal; ``-q`` passes False.
    """

    def __init__(self, prog: str, *, enabled: bool | None = None):
        self.prog = prog
        self.enabled = sys.stderr.isatty() if enabled is None else bool(enabled)
        self.start = time.perf_counter()

    def __call__(self, message: str) -> None:
        if self.enabled:
            print(f"{self.prog}: [{time.perf_counter() - self.start:5.1f} s] {message}", file=sys.stderr, flush=True)

    def bar(self, total: int, *, desc: str, enabled: bool | None = None):
        """A tqdm bar on stderr (``enabled`` None: as the lines are)."""
        from tqdm import tqdm

        return tqdm(total=total, desc=desc, file=sys.stderr, unit="image", dynamic_ncols=True,
                    disable=not (self.enabled if enabled is None else enabled))


# ----------------------------------------------------------------------------- errors and exit status
class Parser(argparse.ArgumentParser):
    """argparse with a one-line error: ``PROG: error: MESSAGE (see PROG --help)`` and status 2,
    instead of the usage block before it (a bad flag is one line, like any other bad input)."""

    def error(self, message):
        self.exit(2, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def json_safe(value):
    """``value`` with every non-finite float (nested in dicts and lists) as None: JSON has no
    NaN or Infinity, and a reader would refuse the whole output."""
    import math

    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, dict):
        return {k: json_safe(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [json_safe(v) for v in value]
    return value


def error_line(prog: str, error: BaseException) -> str:
    """``PROG: error: `` and the first line of the error's message (its type where it has none)."""
    message = str(error).splitlines()[0] if str(error) else type(error).__name__
    return f"{prog}: error: {message}"


def exit_status(prog: str, command, *args) -> int:
    """Run ``command(*args)`` and return its exit status. Bad input (:class:`UsageError`, and the
    library's ``ValueError`` and ``OSError``: missing or unreadable files, invalid scenes,
    measurements and arguments) is one line on stderr and status 2; an interrupt is 130. The
    library's warnings are one line each too: ``PROG: warning: MESSAGE`` (Python's own format
    adds the warning's source line)."""

    def one_line(message, category, filename, lineno, file=None, line=None):
        print(f"{prog}: warning: {str(message).splitlines()[0] if str(message) else category.__name__}",
              file=sys.stderr)

    warnings.showwarning = one_line
    try:
        return command(*args)
    except BrokenPipeError:  # `jsss | head`: the reader has what it wanted
        os.dup2(os.open(os.devnull, os.O_WRONLY), sys.stdout.fileno())  # no second error as Python flushes stdout
        return 1
    except (ValueError, OSError) as error:
        print(error_line(prog, error), file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130


# ----------------------------------------------------------------------------- files
def _read_umask() -> int:
    """The process's umask. Linux reports it in /proc; elsewhere setting and restoring it is the
    only way, which is process-wide: done once, at import, before any batch starts threads."""
    try:
        with open("/proc/self/status") as status:
            for line in status:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError, IndexError):
        pass
    umask = os.umask(0o022)
    os.umask(umask)
    return umask


_UMASK = _read_umask()  # read once: toggling os.umask per file would race with other threads


def write_atomically(out, write) -> Path:
    """``write(tmp_path)`` to a temporary file beside ``out``, then rename it to ``out``: readers
    see the old file or the whole new one, never a part, and a failure leaves no temporary
    file. The file gets the permissions a plain ``open`` would give it. Returns ``out``."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{out.name}.", dir=out.parent)
    os.close(fd)
    try:
        write(tmp)
        os.chmod(tmp, 0o666 & ~_UMASK)  # mkstemp makes the file private (0600); a table or an image is not
        os.replace(tmp, out)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return out


def write_png(out, image, *, software: str) -> Path:
    """Write ``image`` (H, W, 3), display values in [0, 1], as an 8-bit RGBA PNG at 100 dpi,
    atomically (:func:`write_atomically`), with ``software`` as its Software text.

    The pixels are those ``matplotlib.image.imsave`` wrote: ``(x * 255)`` truncated in the
    image's dtype, NaN pixels black, alpha opaque. Pillow writes them directly: importing
    matplotlib for it was 0.4 s of every ``jsss-render``."""
    import numpy as np
    from PIL import Image, PngImagePlugin

    image = np.asarray(image)
    if image.ndim != 3 or image.shape[2] != 3 or image.dtype.kind != "f":
        raise ValueError(f"{out}: a PNG is written from floating-point RGB (H, W, 3); got {image.dtype} {image.shape}")
    rgba = np.ones(image.shape[:2] + (4,), image.dtype)
    rgba[..., :3] = image
    rgba[np.isnan(image).any(-1)] = 0
    if rgba.max() > 1 or rgba.min() < 0:
        raise ValueError(f"{out}: display values must lie in [0, 1]")
    rgba = np.ascontiguousarray((rgba * 255).astype(np.uint8))
    info = PngImagePlugin.PngInfo()
    info.add_text("Software", software)
    picture = Image.frombuffer("RGBA", (rgba.shape[1], rgba.shape[0]), rgba, "raw", "RGBA", 0, 1)
    return write_atomically(out, lambda tmp: picture.save(tmp, format="png", pnginfo=info, dpi=(100, 100)))


def write_text(out, text: str) -> Path:
    """Write ``text`` to ``out`` atomically (:func:`write_atomically`)."""

    def write(tmp):
        with open(tmp, "w") as handle:
            handle.write(text)

    return write_atomically(out, write)


def write_fit_files(args, stem: str, as_json: dict, scene_text: str, draw, warnings) -> list[Path]:
    """A fit's files beside ``args.output``, each atomically: ``STEM.fit.json`` (``as_json``, JSON-safe
    already), ``STEM.fit.toml`` (``scene_text``) and ``STEM.fit.png`` (``draw(path)``); then its
    ``warnings`` on stderr and, with ``--json``, the JSON on stdout. Returns the paths written."""
    import json
    import sys

    out = Path(args.output)
    files = {out / f"{stem}.fit.json": json.dumps(as_json, indent=2, allow_nan=False) + "\n",
             out / f"{stem}.fit.toml": scene_text}
    for path, text in files.items():
        write_text(path, text)
    figure = write_atomically(out / f"{stem}.fit.png", draw)
    for warning in warnings:
        print(f"{args.prog}: warning: {warning}", file=sys.stderr)
    if args.json:
        print(json.dumps(as_json, allow_nan=False))
    return [*files, figure]


# ----------------------------------------------------------------------------- subcommands
class _CommandOrDefault(argparse._SubParsersAction):
    """Subcommands, and a default command where the first positional names none.

    ``fit-params sample.exr ...`` beside ``fit-params batch DIR ...`` (and ``jsss-render
    scene.toml`` beside ``jsss-render fit ...``): argparse has no default subcommand, and
    looking at ``argv[0]`` before parsing misreads ``fit-params -q batch ...`` and cannot list
    the subcommands in ``--help``. So this is argparse's own subparsers action (the documented
    ``add_subparsers(action=...)`` hook): argparse sorts the words into options, their values
    and positionals as usual and hands this action the first positional with everything after
    it. A subcommand's name runs that subcommand's parser; any other word is the default
    command's first positional, and ``default_parser`` (the same options plus the default
    command's positionals) reads it and the rest into the same namespace, keeping options
    given before it. A file named like a subcommand is given as ``./batch``.
    """

    def __init__(self, option_strings, *, default_parser: argparse.ArgumentParser, **kwargs):
        super().__init__(option_strings, **kwargs)
        self.default_parser = default_parser
        self.choices = None  # any word: a subcommand's name, else the default command's positional

    def __call__(self, parser, namespace, values, option_string=None):
        if values[0] in self._name_parser_map:
            return super().__call__(parser, namespace, values, option_string)
        self.default_parser.parse_args(values, namespace)


def add_commands(parser: argparse.ArgumentParser, *, default: argparse.ArgumentParser | None = None, **kwargs):
    """``parser.add_subparsers(**kwargs)``; with ``default``, a first positional that names no
    subcommand is the default command's, parsed by ``default`` (:class:`_CommandOrDefault`)."""
    if default is None:
        return parser.add_subparsers(**kwargs)
    return parser.add_subparsers(action=_CommandOrDefault, default_parser=default, **kwargs)
