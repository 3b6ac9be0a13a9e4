"""The test suite runs in float64 (library code never flips this itself), and every process of
one run (xdist workers, the notebooks' kernels, the console scripts the tests start) shares
one persistent XLA compilation cache, made empty for the run and removed after it."""

import os
import shutil
import tempfile

import jax

jax.config.update("jax_enable_x64", True)

_CACHE_VARIABLE = "JSSS_TEST_RUN_XLA_CACHE"  # set by the process that made the run's cache
_owned_cache = None


def pytest_configure(config):
    """Many tests compile the same programs (the same fit kernels, frames of the same scenes):
    sharing the compiled programs across processes took the suite from 699 s to 585 s on two
    cores. The first process (the xdist controller, or pytest alone) makes the directory; the
    workers, kernels and subprocesses inherit it through the environment. A fresh directory
    per run, so no program compiled from older code is ever read."""
    global _owned_cache
    if _CACHE_VARIABLE not in os.environ:
        _owned_cache = tempfile.mkdtemp(prefix="jsss-tests-xla-")
        os.environ[_CACHE_VARIABLE] = _owned_cache
    directory = os.environ[_CACHE_VARIABLE]
    os.environ["JAX_COMPILATION_CACHE_DIR"] = directory  # kernels and console scripts read JAX's variables
    os.environ["JAX_PERSISTENT_CACHE_MIN_COMPILE_TIME_SECS"] = "0.1"
    jax.config.update("jax_compilation_cache_dir", directory)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.1)


def pytest_unconfigure(config):
    if _owned_cache is not None:
        shutil.rmtree(_owned_cache, ignore_errors=True)


def pytest_collection_modifyitems(config, items):
    """Run the notebooks and README snippets first: each takes 10-70 s in its own process, and
    collected last (as their files sort) one of them would finish alone while the other
    xdist workers sit idle. The order of everything else is kept."""
    first = ("test_notebooks.py", "test_readme.py")
    items.sort(key=lambda item: item.path.name not in first)


def pytest_runtest_teardown(item, nextitem):
    """A console command run in this process (``main([...])``) turns on the store of traced
    programs for the process; the next test must see the library's default (off), or it would
    read frames and fits through stored programs that its assertions do not expect.

    Between test modules, a worker that holds too many compiled programs lets them go
    (:func:`_release_compiled_programs`)."""
    import sys

    store = sys.modules.get("jsss.stored_programs")
    if store is not None:
        store.keep_programs_in(None)
    if nextitem is None or nextitem.module is not item.module:
        _release_compiled_programs()


def _release_compiled_programs() -> None:
    """A worker keeps every program the suite compiled in it, each holding memory maps, of which
    Linux gives a process 65530: past 30000 they are let go (the next test compiles, or loads
    from the run's compilation cache, what it needs again). Workers had segfaulted inside XLA
    late in four CI runs (12-05 to 12-07), each time in a test that passed alone; one measured
    at 63100 maps and 7.1 GB in the test that had crashed twice."""
    from measure.commands._console import release_compiled_programs

    release_compiled_programs()
