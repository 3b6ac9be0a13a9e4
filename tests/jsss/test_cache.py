"""The console scripts' persistent compilation cache: where it goes, and that it can be turned off.

Run in a subprocess: turning the cache on changes JAX's global configuration, which the test
process itself must keep as it is (library code never changes it)."""

import subprocess
import sys

SCRIPT = """
import os, sys, warnings, jax
from jsss.cache import enable_compilation_cache
where = enable_compilation_cache()
print(where, jax.config.jax_compilation_cache_dir)
os.environ["JAX_COMPILATION_CACHE_DIR"] = sys.argv[1] + "/jax"
print(enable_compilation_cache())
os.environ["JSSS_COMPILATION_CACHE"] = "0"
print(enable_compilation_cache())
del os.environ["JSSS_COMPILATION_CACHE"]
os.environ["JAX_COMPILATION_CACHE_DIR"] = sys.argv[1] + "/a_file/xla"
with warnings.catch_warnings(record=True) as caught:
    warnings.simplefilter("always")
    print(enable_compilation_cache(), len(caught), str(caught[0].message).split(":")[0] if caught else "")
"""


def test_cache_directory_follows_the_environment_and_an_unwritable_one_warns(tmp_path):
    (tmp_path / "a_file").write_text("not a directory")
    env = {"PATH": "", "HOME": str(tmp_path), "JSSS_CACHE_DIR": str(tmp_path / "jsss")}
    out = subprocess.run([sys.executable, "-c", SCRIPT, str(tmp_path)], capture_output=True, text=True, env=env,
                         timeout=120)
    assert out.returncode == 0, out.stderr
    lines = out.stdout.splitlines()
    assert lines[0] == f"{tmp_path}/jsss/xla {tmp_path}/jsss/xla"  # JSSS_CACHE_DIR/xla, and JAX uses it
    assert lines[1] == f"{tmp_path}/jax"  # JAX's own variable wins
    assert lines[2] == "None"  # JSSS_COMPILATION_CACHE=0 turns it off
    assert lines[3] == f"None 1 {tmp_path}/a_file/xla"  # unwritable: one warning naming it, no cache
    assert (tmp_path / "jsss" / "xla").is_dir()
