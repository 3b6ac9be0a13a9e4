"""A renderer prepared once for a scene and plan, for loops that change the material or the lights' intensities.

:func:`jsss.render.render` plans (unless given a plan), prepares and runs a frame on every
call; its geometry and compiled programs are kept between calls, so a warm call costs about
its passes. A loop that only changes how bright the lights are, or what the object is made
of, need not even look the geometry up: :func:`prepare_renderer` does the planning and
preparing once and returns a :class:`PreparedRenderer`, whose calls run the compiled frame.
"""

from __future__ import annotations

import dataclasses
import time
import warnings
from dataclasses import dataclass

import equinox as eqx
import jax.numpy as jnp
import numpy as np

from .memory import camera_key, light_key, mesh_key
from .planner import Plan, plan_scene
from .renderer import (
    FrameProgram,
    RenderParams,
    RenderResult,
    frame_program,
    light_radiant,
    render_params,
)
from .scene import Material, Scene

__all__ = ["PreparedRenderer", "prepare_renderer"]


def _geometry(scene: Scene) -> tuple:
    """What a renderer's geometry depends on: the mesh, the camera, the lights' positions
    (directions, maps) and the texture and shadow-map sizes."""
    return (mesh_key(scene.mesh), camera_key(scene.camera), tuple(light_key(light) for light in scene.lights),
            scene.texture_size, scene.shadow_map_size)


@dataclass(frozen=True, eq=False)
class PreparedRenderer:
    """A scene's frame, planned and prepared once: call it with another material or other light
    intensities to render again without planning, rasterizing or compiling.

    Build it with :func:`prepare_renderer`; it is immutable. ``renderer()`` renders the scene
    as it is, ``renderer(material=..., light_intensities=...)`` with either changed, and
    ``renderer.render(scene)`` a scene of the same geometry, camera and light positions (its
    material and lights' colours and intensities may differ), as :func:`jsss.render.render`
    would with the same plan, to float rounding (the same compiled program).

    The plan stays the one made for the scene's own material (its Gaussian variances, its
    passes, its method): another material's profile is fitted on those variances. For a
    material far from it (another order of mean free path), prepare a renderer for it. A
    material left at ``profile_model = "auto"`` chooses its profile model again for its own
    medium; where that is not the plan's model, a call warns (pin the model to keep it).

    Example
    -------
    ::

        import dataclasses
        import jsss.render as jr
        from jsss.medium import Medium

        scene = jr.load_scene("examples/ketchup_plane.toml")
        renderer = jr.prepare_renderer(scene)            # plans, rasterizes, compiles
        for watts in (500.0, 1000.0, 1500.0):
            frame = renderer(light_intensities=[watts])  # (H, W, 3) linear radiance
        m = scene.material.medium
        for scale in (0.8, 1.25):                        # less and more absorbing ketchup
            medium = Medium(m.sigma_a * scale, m.sigma_s_prime, m.eta)
            frame = renderer(material=dataclasses.replace(scene.material, medium=medium))

    Attributes
    ----------
    scene : Scene; plan : Plan; dtype : the frames' float dtype
    params : RenderParams, the scene's own (a frame is ``program(params)``, a pure JAX function)
    prepared : the method's prepared geometry; program : FrameProgram, the compiled frame
    """

    scene: Scene
    plan: Plan
    dtype: object
    params: RenderParams
    prepared: object
    program: FrameProgram

    def __post_init__(self):
        if not isinstance(self.scene, Scene):
            raise TypeError(f"PreparedRenderer(scene=...) must be a jsss.render.Scene; got {type(self.scene).__name__}.")
        if not isinstance(self.plan, Plan):
            raise TypeError(f"PreparedRenderer(plan=...) must be a jsss.render.Plan; got {type(self.plan).__name__}.")
        if not jnp.issubdtype(self.dtype, jnp.floating):
            raise ValueError(f"PreparedRenderer(dtype={self.dtype!r}) must be a float dtype (jnp.float32 or jnp.float64).")

    def __call__(self, *, material: Material | None = None, light_intensities=None) -> np.ndarray:
        """Linear radiance (H, W, 3) of the scene with ``material`` (a :class:`~jsss.render.Material`)
        and ``light_intensities`` (one per light, >= 0; see :class:`~jsss.render.lighting.Light`
        for the units) in place of its own, where given."""
        return self._radiance(self._changed(material, light_intensities))

    def render(self, scene: Scene) -> RenderResult:
        """The frame of ``scene``, which must have this renderer's mesh, camera, light positions
        and sizes (ValueError otherwise, naming what differs); its material and the lights'
        colours and intensities are read."""
        if not isinstance(scene, Scene):
            raise TypeError(f"PreparedRenderer.render(scene=...) must be a jsss.render.Scene; got "
                             f"{type(scene).__name__}.")
        ours, theirs = _geometry(self.scene), _geometry(scene)
        names = ("mesh", "camera", "lights' kinds and positions", "texture_size", "shadow_map_size")
        moved = [name for name, a, b in zip(names, ours, theirs) if a != b]
        if moved:
            raise ValueError(f"PreparedRenderer.render: the scene's {', '.join(moved)} differ from the renderer's; "
                             "prepare a renderer for it (jsss.render.prepare_renderer) or call jsss.render.render.")
        t0 = time.perf_counter()
        radiance = self._radiance(scene)
        return RenderResult(radiance, self.plan, {"frame": time.perf_counter() - t0}, self.prepared)

    def _changed(self, material, light_intensities) -> Scene:
        """The scene with ``material`` and ``light_intensities`` in place (checked)."""
        scene = self.scene
        if material is not None:
            if not isinstance(material, Material):
                raise TypeError(f"material must be a jsss.render.Material; got {type(material).__name__}.")
            scene = dataclasses.replace(scene, material=material)
        if light_intensities is not None:
            values = np.asarray(light_intensities, float)
            if values.shape != (len(scene.lights),) or not np.all(np.isfinite(values)) or np.any(values < 0):
                raise ValueError(f"light_intensities must be {len(scene.lights)} finite numbers >= 0 (one per light); "
                                 f"got {light_intensities!r}.")
            scene = dataclasses.replace(scene, lights=tuple(dataclasses.replace(light, intensity=float(v))
                                                            for light, v in zip(scene.lights, values)))
        return scene

    def _radiance(self, scene: Scene) -> np.ndarray:
        if scene.material is self.scene.material:  # the lights' brightness alone: the same geometry and program
            params = eqx.tree_at(lambda p: p.radiant, self.params, light_radiant(scene.lights, self.dtype))
            return np.asarray(self.program(params))
        _warn_if_other_profile_model(self.plan, scene.material)
        # Another material: its parameters; its geometry is this one (texture space, Lambert) or,
        # where preparing reads the profile or the surface (an image-space disc, filtered normals,
        # roughness), prepared again from the kept rasters; frame_program finds the program.
        method = self.plan.method_config
        params = render_params(scene, self.plan, dtype=self.dtype)
        program = frame_program(method, method.prepare(scene, self.plan, params))
        return np.asarray(program(params))


def _warn_if_other_profile_model(plan: Plan, material: Material) -> None:
    """Warn where ``material`` renders with another profile model than the plan was made for:
    a material left at ``profile = "auto"`` chooses again for its own medium (ketchup's takes the
    transport tables, marble's the dipole), and the plan's Gaussian variances, fitted to the
    other model's profile, may then miss the plan's accuracy target."""
    planned, chosen = plan.profile, getattr(material, "profile", None)
    if planned is None or chosen is None or chosen.model == planned.model:
        return
    warnings.warn(f"PreparedRenderer: the material renders with the {chosen.model} profile ({chosen.why}), but the "
                  f"plan's Gaussians were chosen for the {planned.model} profile, so its frames may miss the plan's "
                  f"accuracy target; prepare a renderer for this material (jsss.render.prepare_renderer), or keep "
                  f"the plan's model: dataclasses.replace(material, profile_model={planned.model!r}, profile=None).",
                  UserWarning, stacklevel=4)


def prepare_renderer(scene: Scene, plan: Plan | None = None, *, dtype=jnp.float32) -> PreparedRenderer:
    """Plan ``scene`` (unless ``plan`` is given), prepare its geometry and compile its frame once:
    a :class:`PreparedRenderer` (its docstring shows the loop)."""
    if not isinstance(scene, Scene):
        raise TypeError(f"prepare_renderer(scene=...) must be a jsss.render.Scene; got {type(scene).__name__}.")
    plan = plan_scene(scene) if plan is None else plan
    method = plan.method_config
    params = render_params(scene, plan, dtype=dtype)
    prepared = method.prepare(scene, plan, params)
    program = frame_program(method, prepared)
    renderer = PreparedRenderer(scene, plan, dtype, params, prepared, program)
    program(params).block_until_ready()  # compile now, not in the loop's first frame
    return renderer
