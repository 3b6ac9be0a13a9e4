"""jsss.stored_programs for programs made at run time (a render's frame) and for outputs that are
jsss's own pytrees (a GaussianSum), whose structure the stored executable does not hold.

Run in subprocesses: the store is process state, which the test process must keep as it is
(library code never turns it on). The fits' use of it is tested in tests/fitting/test_programs.py.
"""

import subprocess
import sys

SCRIPT = """
import sys

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)
from jsss import Medium, stored_programs
from jsss.gaussians import GaussianSum, empirical_dipole_fit

traces = []


def make(scale):
    def closure(x):
        traces.append(scale)  # runs only when JAX traces the Python
        return GaussianSum(jnp.stack([x, scale * x], axis=-1), jnp.exp(x))
    # the identity names what the closure holds: another scale is another program
    return stored_programs.stored_program(jax.jit(closure), name="closure", identity=repr(scale))


if sys.argv[3:]:  # XLA's persistent cache in this folder, every program written to it
    jax.config.update("jax_compilation_cache_dir", sys.argv[3])
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0)
    jax.config.update("jax_persistent_cache_min_entry_size_bytes", 0)
if sys.argv[2] == "on":
    stored_programs.keep_programs_in(sys.argv[1])
x = jnp.linspace(0.1, 1.0, 4)
two, three = make(2.0)(x), make(3.0)(x)
fit = empirical_dipole_fit(Medium(jnp.array([0.002, 0.004]), jnp.array([2.2, 2.6]), 1.3))
inside = jax.jit(lambda y: make(2.0)(y).weights)(x)  # a tracer: the closure itself
out = [type(two).__name__, type(fit).__name__] + [np.asarray(a).tobytes().hex() for a in
                                                  (two.weights, two.variances, three.weights, fit.weights, fit.variances)]
print(len(traces), bool(jnp.array_equal(inside, two.weights)), *out)
"""


def _run(tmp_path, mode, *xla_cache):
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path), mode, *map(str, xla_cache)], capture_output=True,
                         text=True, check=False,
                         env={"PATH": "", "HOME": str(tmp_path)}, timeout=300)
    assert out.returncode == 0, out.stderr
    traced, *rest = out.stdout.split()
    return int(traced), rest


def test_a_stored_closure_and_a_pytree_output_come_back_equal_without_tracing(tmp_path):
    """Off: nothing written. On: the first process traces and stores each closure once (two
    identities, two files, plus the dipole fit); the next traces only the call under jit and
    returns the same bits and the same output types; a damaged file is traced again."""
    store = tmp_path / "jsss-programs"
    traced, plain = _run(tmp_path, "off")
    assert traced == 3 and plain[:3] == ["True", "GaussianSum", "GaussianSum"]  # 2.0, 3.0 and 2.0 under jit
    assert not store.exists()
    assert _run(tmp_path, "on") == (3, plain)
    files = sorted(p.name.split("-")[0] for p in store.iterdir())
    assert files == ["closure", "closure", "empirical_dipole_fit"]
    assert _run(tmp_path, "on") == (1, plain)  # only the call with a tracer traces
    damaged = next(p for p in store.iterdir() if p.name.startswith("closure"))
    damaged.write_bytes(damaged.read_bytes()[:50])
    assert _run(tmp_path, "on") == (2, plain)
    assert len(list(store.iterdir())) == 3


def test_programs_compiled_from_a_filled_compilation_cache_are_stored_whole(tmp_path):
    """XLA's CPU executables lose functions when serialized again after a load from XLA's
    persistent cache ("Function ... not found" when run). A store filled in a process whose
    compiles that cache serves (it was filled by a store elsewhere: a deleted or moved store
    folder) must still give, in the next process, the same bits without tracing."""
    xla = tmp_path / "xla"
    _, plain = _run(tmp_path / "plain", "off")
    assert _run(tmp_path / "first", "on", xla) == (3, plain)  # compiles the store's programs into XLA's cache
    assert any(xla.iterdir())
    store = tmp_path / "second"
    assert _run(store, "on", xla) == (3, plain)  # XLA's cache serves these compiles; the store is filled
    assert len(list((store / "jsss-programs").iterdir())) == 3
    assert _run(store, "on", xla) == (1, plain)  # loaded and run: only the call under jit traces


FORGET = """
import sys
from pathlib import Path

import jax
import jax.numpy as jnp

jax.config.update("jax_enable_x64", True)
from jsss import stored_programs

traces = []


def double(x):
    traces.append(1)
    return 2 * x


program = stored_programs.stored_program(jax.jit(double), name="double", identity="double")
stored_programs.keep_programs_in(sys.argv[1])
x = jnp.arange(3.0)
first = program(x)
stored_programs.forget_loaded_programs()
jax.clear_caches()  # JAX's own trace of double too: a call that reaches it traces again
again = program(x)  # from the file, not traced
for path in (Path(sys.argv[1]) / "jsss-programs").iterdir():
    path.unlink()
kept = program(x)  # nothing forgotten since: from memory, not traced
stored_programs.forget_loaded_programs()
jax.clear_caches()
last = program(x)  # neither in memory nor on disk: traced
print(len(traces), *(bool(jnp.array_equal(first, y)) for y in (again, kept, last)))
"""


def test_forgotten_programs_are_loaded_again_from_their_files(tmp_path):
    """The test suite's workers let go of loaded programs (each executable holds memory maps of
    its own); the next call loads the file again without tracing, and traces only where the file
    is gone too."""
    out = subprocess.run([sys.executable, "-c", FORGET, str(tmp_path)], capture_output=True, text=True, check=False,
                         env={"PATH": "", "HOME": str(tmp_path)}, timeout=300)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["2", "True", "True", "True"]
