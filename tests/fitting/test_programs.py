"""The store of traced programs and Hankel grids (fitting.programs): off by default, kept in the
folder a caller names, traced once across processes.

Run in subprocesses: the store is process state, which the test process must keep as it is
(library code never turns it on). Where the commands put it is tested with them
(tests/measure/test_commands.py)."""

import subprocess
import sys

PROGRAM_SCRIPT = """
import sys
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

jax.config.update("jax_enable_x64", True)
from fitting import programs as cache
from jsss.layers import hankel

traces = []


@cache.reusable_program(static_argnames=("power",))
@partial(jax.jit, static_argnames=("power",))
def solve(matrix, scale, *, power):
    traces.append(1)  # runs only when JAX traces the Python
    return jnp.linalg.solve(matrix @ matrix.T + jnp.eye(3), scale * matrix[:, 0] ** power)  # a LAPACK call


if sys.argv[2] == "on":
    cache.keep_programs_in(sys.argv[1] + "/jsss/xla")
matrix = jnp.arange(9.0).reshape(3, 3) / 7
value = solve(matrix, 2.0, power=2)
other_static = solve(matrix, 2.0, power=3)
traced = len(traces)
inside_jit = jax.jit(lambda m: solve(m, 2.0, power=2))(matrix)  # a tracer argument: the function itself
grid = cache.stored_hankel_grid(n=64)
fresh = hankel._built_grid.__wrapped__(1e-4, 1e3, 64, 1e-4, 3e5, 64, "float64")
same_grid = all(np.array_equal(getattr(grid, f), getattr(fresh, f)) for f in ("r", "k", "forward_matrix",
                                                                              "inverse_matrix"))
print(traced, np.asarray(value).tobytes().hex(), np.asarray(other_static).tobytes().hex(),
      bool(jnp.allclose(inside_jit, value, rtol=1e-14)), same_grid)
"""


def _run_program_script(tmp_path, mode):
    env = {"PATH": "", "HOME": str(tmp_path)}
    out = subprocess.run([sys.executable, "-c", PROGRAM_SCRIPT, str(tmp_path), mode], capture_output=True, text=True,
                         env=env, timeout=300)
    assert out.returncode == 0, out.stderr
    traced, *rest = out.stdout.split()
    return int(traced), rest


def test_a_reusable_program_is_traced_once_across_processes_and_a_damaged_file_is_traced_again(tmp_path):
    """Off, nothing is written and the function traces as usual; with keep_programs_in, a second
    process traces nothing and gets the same bits; a truncated file is traced again."""
    programs = tmp_path / "jsss" / "xla" / "jsss-programs"
    # Off (the library default): the function itself, traced once per static value; nothing written.
    traced, plain = _run_program_script(tmp_path, "off")
    assert traced == 2 and plain[2:] == ["True", "True"]
    assert not programs.exists()
    # On: the first process traces and stores one program per static value; the next loads them
    # and traces nothing, with the same numbers to the last bit as the plain function.
    assert _run_program_script(tmp_path, "on") == (2, plain)
    stored = sorted(programs.iterdir())
    assert len(stored) == 2
    assert len(list((tmp_path / "jsss" / "xla" / "jsss-grids").iterdir())) == 1
    assert _run_program_script(tmp_path, "on") == (0, plain)
    # A truncated file is traced again and replaced, not an error.
    stored[0].write_bytes(stored[0].read_bytes()[:100])
    assert _run_program_script(tmp_path, "on") == (1, plain)
    assert _run_program_script(tmp_path, "on") == (0, plain)  # replaced whole (XLA's bytes vary run to run)
