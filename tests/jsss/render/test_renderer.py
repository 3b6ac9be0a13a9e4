"""render(): one compiled frame per method configuration and prepared geometry."""

import jax.numpy as jnp
import numpy as np

from jsss.render import frame_program, parse_scene, plan_scene, prepare, render
from tests.jsss.render.scenes import scene_dict


def test_a_frame_of_the_same_scene_and_plan_again_is_not_compiled_again():
    """Prepared again, the geometry equals the first (a digest of its data), so the second frame
    runs the first one's program (a cache hit, one compiled shape) and gives the same bits; another
    texture size is another program."""
    scene = parse_scene(scene_dict(camera={"position": [0.0, -110.0, 30.0], "fov": 28, "resolution": [24, 18]},
                                   render={"texture_size": 32, "accuracy": 0.1}))
    plan = plan_scene(scene, method="texture-space")
    first = render(scene, plan, dtype=jnp.float32)
    hits = frame_program.cache_info().hits
    second = render(scene, plan, dtype=jnp.float32)
    assert frame_program.cache_info().hits == hits + 1
    assert second.prepared is not first.prepared and second.prepared == first.prepared
    program = frame_program(plan.method_config, second.prepared)
    assert program._cache_size() == 1  # one trace and compilation for float32 parameters
    np.testing.assert_array_equal(second.radiance, first.radiance)
    other = plan_scene(parse_scene(scene_dict(camera={"position": [0.0, -110.0, 30.0], "fov": 28,
                                                      "resolution": [24, 18]},
                                              render={"texture_size": 16, "accuracy": 0.1})), method="texture-space")
    assert prepare(scene, other) != first.prepared
