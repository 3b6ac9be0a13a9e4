"""The test suite runs in float64 (library code never flips this itself)."""

import jax

jax.config.update("jax_enable_x64", True)
