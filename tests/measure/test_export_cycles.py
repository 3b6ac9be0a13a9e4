"""The Blender export rendered by Cycles itself (pip ``bpy``, Blender as a Python module).

bpy is large (800 MB installed), needs Python 3.11 and its metadata pins numpy < 2 (it renders
with numpy 2 all the same: ``pip install --no-deps 'bpy>=4.5,<4.6' zstandard``). It renders in
a child process (``benchmarks/exports.py --cycles-child``), so this process never imports it;
``$JSSS_BPY_PYTHON`` names another Python that has it.
"""

import importlib.util
import os

import numpy as np
import pytest

from jsss.materials import jensen2001

pytestmark = pytest.mark.skipif(importlib.util.find_spec("bpy") is None and not os.environ.get("JSSS_BPY_PYTHON"),
                                reason="bpy (Blender as a Python module) is not installed")


@pytest.mark.parametrize("name", ["marble", "ketchup", "skin1"])
def test_cycles_renders_the_export_with_the_medium_total(name):
    """A 1000-mean-free-path slab of the exported material under a uniform white environment,
    seen along the normal, against F(0) + (1 - F(0)) R_d of the transport tables (exact by
    reciprocity): within 2 %, the statistical error (4 standard errors) allowed on top. Marble
    loses 4 % of its light to Cycles' 256-bounce cap and skin 10-20 % to the missing internal
    reflection, ketchup's green and blue sit below Cycles' albedo floor: each of these fails
    the test unless the export's colour accounts for it."""
    from benchmarks.exports import render_cycles, truth

    medium = jensen2001(name)
    expected = truth(medium)
    result = render_cycles(medium, spp=512, resolution=16)
    mean, stderr = np.asarray(result["mean"]), np.asarray(result["stderr"])
    assert np.all(stderr < 0.004 * expected)  # the check below means something
    assert np.all(np.abs(mean - expected) < 0.02 * expected + 4 * stderr), (mean / expected - 1, stderr / expected)


def test_cycles_renders_an_exported_colour_map_as_c_times_the_total():
    """``jsss-render fit --albedo-map --export blender``'s script and colour EXR on the slab (the
    cube's own UVs): a uniform map c makes every texel's colour the one whose walk returns
    c R_d, so the slab shows F(0) + (1 - F(0)) c R_d, as the plain export shows c = 1. A texture
    that did not load (Blender's magenta), went through a colour transform, or was the medium's
    colour times c misses by far more than the 2 % allowed."""
    from benchmarks.exports import render_cycles
    from jsss import transport

    medium = jensen2001("marble")
    c = np.array([0.5, 0.7, 0.9])
    f0 = 1.0 - np.asarray(transport.entry_transmittance(medium.eta), float)
    expected = f0 + (1 - f0) * c * np.asarray(transport.total_reflectance(medium), float)
    result = render_cycles(medium, spp=512, resolution=16, albedo_map=np.broadcast_to(c, (4, 4, 3)))
    mean, stderr = np.asarray(result["mean"]), np.asarray(result["stderr"])
    assert np.all(stderr < 0.004 * expected)
    assert np.all(np.abs(mean - expected) < 0.02 * expected + 4 * stderr), (mean / expected - 1, stderr / expected)
