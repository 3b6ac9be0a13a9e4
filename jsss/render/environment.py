r"""Environment light: an HDR latitude-longitude map (or a constant colour) around the scene.

The light entering the surface at a point of normal :math:`n` is

.. math:: E(x) = \int_{4\pi} L(\omega)\,V(x, \omega)\,k(n\cdot\omega)\,d\omega, \qquad
          k(\mu) = \max(\mu, 0)\,F_t(\mu, \eta)\,A(\mu),

with the Fresnel transmittance :math:`F_t` and the medium's oblique-incidence law :math:`A`
(:mod:`jsss.diffusion.incidence`; 1 without it): the kernel a point or directional light is
weighted by, integrated over the sphere.

**Irradiance: a prefiltered map.** Without visibility :math:`E` depends on the normal alone. It
is tabulated on a grid of normals (``NORMAL_GRID``, latitude-longitude) once per frame, from a
table that depends on the map alone: for each grid normal :math:`n_j`, the map's radiance binned
by cosine,

.. math:: H_{jb} = \sum_i L_i\,\Delta\omega_i\,\Lambda_b(n_j\cdot\omega_i), \qquad
          E(n_j) = \sum_b H_{jb}\,k(\mu_b),

with hat functions :math:`\Lambda_b` on ``COSINE_NODES`` cosines :math:`\mu_b` (exact for the
piecewise-linear interpolant of :math:`k`). So the frame's :math:`k` -- which depends on the
material, and is differentiated when a material is fitted -- costs a small matrix product,
and the point's irradiance is a bilinear look-up at its normal. ``benchmarks/environment.py``
measures this against brute-force integration of the full map and against Ramamoorthi &
Hanrahan's 9-coefficient spherical harmonics (:func:`sh9_irradiance`), on the same maps.

**Visibility** (:func:`environment_shadows`): a closed, non-convex mesh shadows itself. Its
points are tested against ``VISIBILITY_DIRECTIONS`` directional shadow maps spread evenly
over the sphere (a Fibonacci lattice), once per mesh; each point's irradiance is scaled by
its visible share of the environment's light, :math:`\sum_d V_d\,w_d / \sum_d w_d` with
:math:`w_d = \bar L_d\,\max(n\cdot d, 0)` (:math:`\bar L_d` the map's radiance around
:math:`d`). Convex and open shapes (sphere, box, plane) see their whole upper hemisphere and
skip the test.

**Single scattering** (Jensen 2001 sec. 2.2, :func:`jsss.render.shading.single_scattering`) sums
the map cut into ``SCATTERING_CELLS`` cells, each a parallel light from its light's centroid:
the first bounce's lobe is broad, and a sun stays a sun.

**Specular reflection** of the map (:func:`environment_specular`): the Fresnel reflectance at
the view angle times the map blurred by the Beckmann lobe's width around the mirror direction,
:math:`F(\cos\theta_o, \eta)\,\tilde L(r)`. With the diffusion exit lobe
:math:`F_t(\cos\theta_o)` it makes a white furnace exact: a non-absorbing object under a
uniform environment of radiance 1 returns radiance 1 at every angle (``tests``).

Convention: world +z is up. The map's top row looks along +z, its bottom row along -z; its
centre column looks along +x and its columns run toward +y leftward (longitude
:math:`\phi = 2\pi(\tfrac12 - u)`, :math:`u` from 0 at the left edge to 1 at the right).
``rotation`` turns the environment about +z by that many degrees (counter-clockwise seen
from above).
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import NamedTuple

import jax.numpy as jnp
import numpy as np

from ..fresnel import fresnel_reflectance, fresnel_transmittance

__all__ = ["Environment", "EnvironmentGeometry", "EnvironmentShadows", "brute_force_irradiance",
           "direction_radiance", "environment_geometry", "environment_irradiance", "environment_shadows", "environment_specular",
           "map_directions", "procedural_map", "sh9_irradiance"]

TABLE_MAP = (64, 256)        # the map is box-filtered to this many rows and columns for the tables
NORMAL_GRID = (64, 256)      # normals the irradiance is tabulated at (rows of latitude; columns: the table map's)
COSINE_NODES = 65            # hat functions over the cosine in [0, 1]
VISIBILITY_DIRECTIONS = 96   # directional shadow maps a non-convex mesh is tested against
VISIBILITY_MAP_SIZE = 256    # texels per side of each
SCATTERING_CELLS = (8, 16)   # the map's cells whose light single scattering sums (rows, columns)


@dataclass(frozen=True, eq=False)
class Environment:
    """Light from every direction: a latitude-longitude map of radiance, or a constant colour.

    Attributes
    ----------
    radiance : (H, W, 3) linear radiance, top row +z (the module's convention); a constant
        environment is a (2, 4, 3) map of one colour
    color : (3,) linear RGB, multiplies ``intensity`` (the map's own units otherwise)
    intensity : float, scales the map
    rotation : float, degrees about +z
    source : str, the map's file, or "constant"
    """

    radiance: np.ndarray
    color: tuple = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    rotation: float = 0.0
    source: str = "constant"

    kind = "environment"

    def __post_init__(self):
        r = np.asarray(self.radiance)
        if r.ndim != 3 or r.shape[-1] != 3 or min(r.shape[:2]) < 1:
            raise ValueError(f"environment radiance must be an (H, W, 3) map; got shape {r.shape}.")
        if not np.all(np.isfinite(r)) or np.any(r < 0):
            raise ValueError(f"{self.source}: environment radiance must be finite and >= 0.")
        if np.any(np.asarray(self.color) < 0) or not self.intensity >= 0:
            raise ValueError(f"environment color and intensity must be non-negative; got {self.color}, {self.intensity}.")

    @classmethod
    def constant(cls, color=(1.0, 1.0, 1.0), intensity: float = 1.0) -> Environment:
        """A uniform environment of radiance ``color * intensity`` (a white furnace at 1)."""
        return cls(np.ones((2, 4, 3)), tuple(float(c) for c in color), float(intensity), 0.0, "constant")

    def incoming_power(self, view) -> tuple[float, float]:
        r"""(from beyond, total): :math:`\int L\,d\omega` over the directions light arrives from
        that lie beyond the object seen along ``view`` (the camera's axis, (3,)), and over all,
        times intensity and mean colour: what lights a small convex object from behind."""
        small = self.table_map.mean(-1)
        directions, solid = map_directions(small.shape, self.rotation)
        power = small * solid * self.intensity * float(np.mean(self.color))
        beyond = directions @ (np.asarray(view, float) / np.linalg.norm(view)) > 0
        return float(power[beyond].sum()), float(power.sum())

    @functools.cached_property
    def table_map(self) -> np.ndarray:
        """The map box-filtered to at most ``TABLE_MAP`` (power kept: each block's mean radiance
        weighted by its rows' solid angles), (h, w, 3); computed once (the tables, the planner
        and the visibility weights all read it)."""
        return downsample(np.asarray(self.radiance, float), TABLE_MAP)


def map_directions(shape, rotation: float = 0.0):
    """Unit directions (H, W, 3) of a latitude-longitude map's pixel centres and their solid
    angles (H, W) [sr], exact per row: :math:`\\Delta\\phi\\,(\\cos\\theta_{top} - \\cos\\theta_{bottom})`."""
    rows, cols = shape
    theta = (np.arange(rows) + 0.5) * np.pi / rows
    u = (np.arange(cols) + 0.5) / cols
    phi = 2 * np.pi * (0.5 - u) + np.radians(rotation)
    sin_t = np.sin(theta)[:, None]
    directions = np.stack(np.broadcast_arrays(sin_t * np.cos(phi), sin_t * np.sin(phi), np.cos(theta)[:, None]), -1)
    return directions, np.broadcast_to(row_solid_angles(rows, cols)[:, None], (rows, cols))


def row_solid_angles(rows: int, cols: int) -> np.ndarray:
    """Solid angle [sr] of one pixel in each row of a latitude-longitude map, (rows,)."""
    edges = np.cos(np.linspace(0.0, np.pi, rows + 1))
    return (2 * np.pi / cols) * (edges[:-1] - edges[1:])


def direction_coordinates(directions, shape, rotation: float = 0.0):
    """Continuous (row, column) of unit ``directions`` (..., 3) on a map of ``shape``, pixel
    centres at integers (the inverse of :func:`map_directions`)."""
    rows, cols = shape
    d = np.asarray(directions, float)
    theta = np.arccos(np.clip(d[..., 2], -1.0, 1.0))
    phi = np.arctan2(d[..., 1], d[..., 0]) - np.radians(rotation)
    u = np.mod(0.5 - phi / (2 * np.pi), 1.0)
    return theta / np.pi * rows - 0.5, u * cols - 0.5


def _bilinear_corners(row, col, shape):
    """Indices (..., 4) into a flattened (rows * cols) grid and weights (..., 4): rows clamped
    at the poles, columns wrapping."""
    rows, cols = shape
    r0 = np.floor(row)
    c0 = np.floor(col)
    fr, fc = row - r0, col - c0
    r0, c0 = r0.astype(np.int64), c0.astype(np.int64)
    r = [np.clip(r0, 0, rows - 1), np.clip(r0 + 1, 0, rows - 1)]
    c = [np.mod(c0, cols), np.mod(c0 + 1, cols)]
    index = np.stack([r[0] * cols + c[0], r[0] * cols + c[1], r[1] * cols + c[0], r[1] * cols + c[1]], -1)
    weight = np.stack([(1 - fr) * (1 - fc), (1 - fr) * fc, fr * (1 - fc), fr * fc], -1)
    return index, weight


def downsample(radiance: np.ndarray, shape) -> np.ndarray:
    """Box-filter a latitude-longitude map to at most ``shape`` (rows, cols), keeping its power.

    A constant map stays constant; a map smaller than ``shape`` is repeated up to it (nearest),
    so the tables always integrate over the same grid."""
    rows, cols = radiance.shape[:2]
    out_rows, out_cols = shape
    if rows < out_rows or cols < out_cols:  # small maps (a constant): nearest-neighbour up
        r = (np.arange(out_rows) * rows) // out_rows
        c = (np.arange(out_cols) * cols) // out_cols
        return radiance[r][:, c]
    solid = np.broadcast_to(row_solid_angles(rows, cols)[:, None], (rows, cols))
    row_of = (np.arange(rows) * out_rows) // rows
    col_of = (np.arange(cols) * out_cols) // cols
    weighted = np.concatenate([radiance * solid[..., None], solid[..., None]], -1)  # power and area
    by_rows = np.zeros((out_rows, cols, 4))
    np.add.at(by_rows, row_of, weighted)
    blocks = np.zeros((out_rows, out_cols, 4))
    np.add.at(blocks.transpose(1, 0, 2), col_of, by_rows.transpose(1, 0, 2))
    power, area = blocks[..., :3], blocks[..., 3]
    return power / area[..., None]


def cosine_nodes(dtype=np.float64) -> np.ndarray:
    """The ``COSINE_NODES`` cosines the kernel is sampled at, 0 to 1."""
    return np.linspace(0.0, 1.0, COSINE_NODES, dtype=dtype)


def irradiance_table(env: Environment) -> np.ndarray:
    """:math:`H_{jb}` (J, B, 3) for the grid normals ``NORMAL_GRID`` (flattened) and the cosine
    hats, per unit ``color * intensity``. Depends on the map alone (NumPy, once per scene).

    The normal grid has the table map's columns, so between a normal row and a map row the
    cosine depends on the column difference alone: each row pair is a circular
    cross-correlation along the columns, done by FFT, one normal row at a time (0.7 s; a dense
    sum over every pair of normal and map pixel took 4-5 times longer at a quarter of the grid;
    measured 2026-12-04)."""
    small = env.table_map
    rows, cols = small.shape[:2]
    normal_rows = NORMAL_GRID[0]
    directions, solid = map_directions((rows, cols))  # the map's own frame: normals are turned at look-up
    spectrum = np.fft.rfft(small * solid[..., None], axis=1)                  # (R, F, 3)
    theta_map = np.arccos(directions[:, 0, 2])
    theta_edges = np.linspace(0.0, np.pi, normal_rows + 1)
    theta_normal = 0.5 * (theta_edges[:-1] + theta_edges[1:])
    shift = 2 * np.pi * np.arange(cols) / cols                                # azimuth between the columns
    table = np.empty((normal_rows, cols, COSINE_NODES, 3))
    for n, theta in enumerate(theta_normal):  # one normal row at a time: (R, cols, B) hats
        cos = (np.sin(theta) * np.sin(theta_map)[:, None] * np.cos(shift)
               + np.cos(theta) * np.cos(theta_map)[:, None])                        # (R, cols)
        t = np.clip(cos, 0.0, 1.0) * (COSINE_NODES - 1)
        lower = np.minimum(np.floor(t), COSINE_NODES - 2).astype(np.int64)[..., None]
        frac = np.where(cos > 0, t - lower[..., 0], 0.0)[..., None]
        lit = (cos > 0)[..., None]
        hats = np.zeros(cos.shape + (COSINE_NODES,))                                       # (R, cols, B)
        np.put_along_axis(hats, lower, lit * (1 - frac), -1)
        np.put_along_axis(hats, lower + 1, lit * frac, -1)  # a different node: no overlap with the line above
        kernel = np.fft.rfft(hats, axis=1)                                                  # (R, F, B)
        # sum over map rows and columns of hats(c_map - c_normal) L(c_map): a cross-correlation
        table[n] = np.fft.irfft(np.einsum("rfb,rfc->fbc", np.conj(kernel), spectrum), n=cols, axis=0)
    return np.ascontiguousarray(table.reshape(normal_rows * cols, COSINE_NODES, 3))


def scattering_cells(small: np.ndarray, rotation: float):
    r"""The table map cut into ``SCATTERING_CELLS``: each cell's direction (K, 3), its light's
    centroid (a sun stays where it is), and its power :math:`\sum L\,\Delta\omega` (K, 3)."""
    rows, cols = small.shape[:2]
    cell_rows, cell_cols = SCATTERING_CELLS
    directions, solid = map_directions((rows, cols), rotation)
    power = small * solid[..., None]
    weight = power.mean(-1) + 1e-12 * solid  # an empty cell keeps its geometric centre

    def cells(a):
        return a.reshape(cell_rows, rows // cell_rows, cell_cols, cols // cell_cols, -1).sum((1, 3)).reshape(
            cell_rows * cell_cols, -1)

    centroid = cells(directions * weight[..., None])
    centroid /= np.linalg.norm(centroid, axis=-1, keepdims=True)
    return centroid, cells(power)


class EnvironmentGeometry(NamedTuple):
    """What a frame's JAX passes read of the environment at its points (texels or pixels).

    Attributes
    ----------
    table : (J, B, 3) :func:`irradiance_table`
    corners : (P..., 4) int, the grid normals around each point's normal
    weights : (P..., 4) their bilinear weights
    visible : (P...) the point's visible share of the environment's light (1 unshadowed)
    radiance : (h, w, 3) the table map (the specular pass blurs it)
    rotation : () degrees about +z
    cell_directions, cell_power : (K, 3) :func:`scattering_cells` (the single-scattering pass)
    """

    table: np.ndarray
    corners: np.ndarray
    weights: np.ndarray
    visible: np.ndarray
    radiance: np.ndarray
    rotation: np.ndarray
    cell_directions: np.ndarray
    cell_power: np.ndarray

    # Read in NumPy by the camera pass (see astype): constants of a compiled frame, not its
    # arguments (jsss.render.programs).
    static_fields = ("radiance", "rotation")

    def astype(self, dtype) -> EnvironmentGeometry:
        """Floats as ``jnp`` arrays of ``dtype``; the corner indices stay integers (and NumPy: the
        camera pass reads the map at the view's mirror direction in NumPy)."""
        return EnvironmentGeometry(jnp.asarray(self.table, dtype), jnp.asarray(self.corners),
                                   jnp.asarray(self.weights, dtype), jnp.asarray(self.visible, dtype),
                                   np.asarray(self.radiance), np.asarray(self.rotation),
                                   jnp.asarray(self.cell_directions, dtype), jnp.asarray(self.cell_power, dtype))


@dataclass(frozen=True, eq=False)
class EnvironmentShadows:
    """What visibility needs: the table, and the directional shadow maps (None: nothing shadows)."""

    table: np.ndarray
    radiance: np.ndarray
    rotation: float
    directions: np.ndarray | None = None
    maps: tuple | None = None


def fibonacci_directions(count: int) -> np.ndarray:
    """``count`` unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    i = np.arange(count) + 0.5
    z = 1 - 2 * i / count
    phi = np.pi * (1 + 5**0.5) * i
    s = np.sqrt(1 - z**2)
    return np.stack([s * np.cos(phi), s * np.sin(phi), z], -1)


def environment_shadows(env: Environment, maps: tuple | None = None) -> EnvironmentShadows:
    """The environment's tables, with the directional shadow maps ``maps`` (one per direction of
    :func:`fibonacci_directions` (``VISIBILITY_DIRECTIONS``), built by
    :func:`jsss.render.lighting.shadow_map`), or None where nothing shadows."""
    directions = None if maps is None else fibonacci_directions(len(maps))
    return EnvironmentShadows(irradiance_table(env), env.table_map, float(env.rotation), directions, maps)


def direction_radiance(shadows: EnvironmentShadows) -> np.ndarray:
    """(K,): the map's mean radiance toward each of ``shadows.directions`` (bilinear in the table
    map): the weight of each visibility map in a point's visible share."""
    luminance = shadows.radiance.mean(-1)
    r, c = direction_coordinates(shadows.directions, luminance.shape, shadows.rotation)
    index, w = _bilinear_corners(r, c, luminance.shape)
    return (luminance.ravel()[index] * w).sum(-1)


def environment_geometry(normals, valid, shadows: EnvironmentShadows, visible=None) -> EnvironmentGeometry:
    r"""The environment at points of normals ``normals`` (P..., 3); ``visible`` (P...): each point's
    visible share of the environment's light, :math:`\sum_k L_k \max(0, n\cdot\omega_k) V_k / \sum_k
    L_k \max(0, n\cdot\omega_k)` over ``shadows.directions`` (:func:`direction_radiance`; tested
    against the shadow maps by :func:`jsss.render.lighting.light_geometry`), None where nothing
    shadows."""
    normals = np.asarray(normals, float)
    valid = np.asarray(valid, bool)
    row, col = direction_coordinates(normals, NORMAL_GRID, shadows.rotation)  # the table is in the map's frame
    corners, weights = _bilinear_corners(row, col, NORMAL_GRID)
    visible = np.where(valid, 1.0 if visible is None else np.asarray(visible, float), 0.0)
    cell_directions, cell_power = scattering_cells(shadows.radiance, shadows.rotation)
    return EnvironmentGeometry(shadows.table, corners, weights, visible, shadows.radiance,
                               np.asarray(shadows.rotation), cell_directions, cell_power)


def environment_irradiance(g: EnvironmentGeometry, radiant, eta, *, law=None):
    """Light transmitted into the surface at each point, (P..., C), for environment colour
    times intensity ``radiant`` (C,): :math:`V(x)\\,E(n(x))` (module docstring)."""
    mu = jnp.asarray(cosine_nodes(), radiant.dtype)
    kernel = mu[:, None] * fresnel_transmittance(mu[:, None], eta)          # (B, C)
    if law is not None:
        kernel = kernel * law(mu)
    table = jnp.einsum("jbc,bc->jc", g.table, kernel)                       # (J, C)
    at_points = (table[g.corners] * g.weights[..., None]).sum(-2)          # (P..., C)
    return radiant * at_points * g.visible[..., None]


def blurred_map(radiance: np.ndarray, rotation: float, directions, roughness: float) -> np.ndarray:
    """The map seen through a lobe of Beckmann roughness ``roughness`` around unit ``directions``
    (..., 3): a von Mises-Fisher average of concentration :math:`1/(2m^2)` (the reflected lobe
    is about twice as wide as the microfacets' slopes), normalised so a uniform map stays uniform."""
    kappa = 1.0 / (2.0 * max(float(roughness), 1e-3) ** 2)
    # The lobe's angular width is about 1 / sqrt(kappa): a map of a quarter of that per row holds
    # all it can see (Beckmann 0.35: 32 rows, a sixteenth of the work of the 128-row table map).
    rows = int(min(radiance.shape[0], 2 ** np.ceil(np.log2(max(32.0, 4 * np.pi * np.sqrt(kappa))))))
    if rows < radiance.shape[0]:
        radiance = downsample(radiance, (rows, rows * radiance.shape[1] // radiance.shape[0]))
    source, solid = map_directions(radiance.shape[:2], rotation)
    d = np.asarray(directions, float).reshape(-1, 3)
    out = np.empty((len(d), 3))
    src = source.reshape(-1, 3)
    w_src = solid.reshape(-1)
    values = radiance.reshape(-1, 3)
    for start in range(0, len(d), 4096):
        cos = d[start:start + 4096] @ src.T
        w = np.exp(kappa * (cos - 1.0)) * w_src
        out[start:start + 4096] = (w @ values) / w.sum(-1, keepdims=True)
    return out.reshape(np.shape(directions)[:-1] + (3,))


SPECULAR_GRID = (32, 64)  # mirror directions the blurred map is tabulated at


def environment_specular(g: EnvironmentGeometry, normals, view_dirs, radiant, eta, *, roughness, weight):
    r"""Reflected environment toward the eye, (P..., C): :math:`w\,F(\cos\theta_o, \eta)\,\tilde L(r)`
    with :math:`r` the mirror direction of the view, :math:`\tilde L` the map blurred by the
    lobe (:func:`blurred_map`, tabulated on ``SPECULAR_GRID`` and read bilinearly) and times the
    point's visible share."""
    n = np.asarray(normals, float)
    v = np.asarray(view_dirs, float)
    cos_o = (n * v).sum(-1, keepdims=True)
    mirror = 2 * cos_o * n - v
    mirror /= np.maximum(np.linalg.norm(mirror, axis=-1, keepdims=True), 1e-12)
    grid, _ = map_directions(SPECULAR_GRID)
    table = blurred_map(np.asarray(g.radiance, float), float(g.rotation), grid, roughness).reshape(-1, 3)
    row, col = direction_coordinates(mirror, SPECULAR_GRID)
    index, w = _bilinear_corners(row, col, SPECULAR_GRID)
    seen = (table[index] * w[..., None]).sum(-2)                              # (P..., 3) NumPy
    cos = jnp.clip(jnp.asarray(cos_o, radiant.dtype), 0.0, 1.0)
    F = fresnel_reflectance(cos, eta)
    return weight * F * radiant * jnp.asarray(seen, radiant.dtype) * g.visible[..., None]


def brute_force_irradiance(radiance: np.ndarray, normals, eta, *, rotation: float = 0.0, law=None) -> np.ndarray:
    """:math:`\\int L\\,k(n\\cdot\\omega)\\,d\\omega` over every pixel of the full map (the truth
    the tables are measured against), (N, 3) for unit ``normals`` (N, 3). NumPy."""
    directions, solid = map_directions(radiance.shape[:2], rotation)
    src = directions.reshape(-1, 3)
    weighted = radiance.reshape(-1, 3) * solid.reshape(-1, 1)
    eta = np.broadcast_to(np.asarray(eta, float), (3,))
    out = np.zeros((len(normals), 3))
    for start in range(0, len(normals), 256):
        cos = np.clip(np.asarray(normals[start:start + 256]) @ src.T, 0.0, None)          # (n, I)
        k = cos[..., None] * np.asarray(fresnel_transmittance(cos[..., None], eta))      # (n, I, 3)
        if law is not None:
            k = k * np.asarray(law(cos))
        out[start:start + 256] = np.einsum("nic,ic->nc", k, weighted)
    return out


def _sh9_basis(d) -> np.ndarray:
    """Real spherical harmonics up to l = 2 at unit directions (..., 3), (..., 9) (Ramamoorthi &
    Hanrahan 2001, eq. 3)."""
    x, y, z = d[..., 0], d[..., 1], d[..., 2]
    return np.stack([0.282095 * np.ones_like(x), 0.488603 * y, 0.488603 * z, 0.488603 * x,
                     1.092548 * x * y, 1.092548 * y * z, 0.315392 * (3 * z**2 - 1), 1.092548 * x * z,
                     0.546274 * (x**2 - y**2)], -1)


def sh9_irradiance(radiance: np.ndarray, normals, eta, *, rotation: float = 0.0) -> np.ndarray:
    r"""The same integral from the map's 9-coefficient spherical-harmonic projection (Ramamoorthi &
    Hanrahan 2001): :math:`E(n) = \sum_{lm} \hat k_l L_{lm} Y_{lm}(n)` with the kernel's zonal
    coefficients :math:`\hat k_l = 2\pi \int_{-1}^1 k(\mu) P_l(\mu)\,d\mu` (for :math:`k = \max(\mu, 0)`
    these are :math:`\pi, 2\pi/3, \pi/4`). (N, 3). NumPy; the benchmark's alternative."""
    directions, solid = map_directions(radiance.shape[:2], rotation)
    Y = _sh9_basis(directions.reshape(-1, 3))                                  # (I, 9)
    L = Y.T @ (radiance.reshape(-1, 3) * solid.reshape(-1, 1))                 # (9, 3)
    mu, w = np.polynomial.legendre.leggauss(256)
    mu, w = 0.5 * (mu + 1), 0.5 * w                                            # [0, 1]
    eta = np.broadcast_to(np.asarray(eta, float), (3,))
    k = mu[:, None] * np.asarray(fresnel_transmittance(mu[:, None], eta))      # (n, 3)
    legendre = [np.ones_like(mu), mu, 0.5 * (3 * mu**2 - 1)]
    k_l = np.stack([2 * np.pi * (w[:, None] * k * p[:, None]).sum(0) for p in legendre])  # (3, 3)
    order = np.array([0, 1, 1, 1, 2, 2, 2, 2, 2])
    return np.einsum("ni,ic->nc", _sh9_basis(np.asarray(normals, float)), L * k_l[order])


def procedural_map(name: str, shape=(256, 512)) -> np.ndarray:
    """Radiance (H, W, 3) of a made-up environment, for examples, tests and benchmarks (no HDR
    photograph ships with jsss).

    ``"sky"``: a blue sky brightening toward the horizon over a grey ground (radiance 0.08),
    and a sun of 3 degrees radius, 45 degrees up, toward -x +y, 2000 times the sky.
    ``"studio"``: a dim room (0.05) with two soft boxes, a large key (radiance 4, 40 x 30
    degrees, front left, 30 degrees up) and a small warm rim light behind (radiance 8).
    Each edge is softened over about a degree, so a renderer's bilinear map look-up and
    these tables see the same light.
    """
    directions, _ = map_directions(shape)
    x, y, z = directions[..., 0], directions[..., 1], directions[..., 2]

    def soft_step(t, width):
        return 0.5 * (1 + np.tanh(t / width))

    if name == "sky":
        up = np.clip(z, 0, None)
        sky = np.stack([0.35 + 0.45 * (1 - up), 0.55 + 0.35 * (1 - up), 1.0 + 0.0 * up], -1)
        ground = np.full(directions.shape, 0.08)
        above = soft_step(z, 0.01)[..., None]
        radiance = above * sky + (1 - above) * ground
        sun = np.array([-0.5, 0.5, np.sqrt(0.5)])
        sun /= np.linalg.norm(sun)
        angle = np.degrees(np.arccos(np.clip(directions @ sun, -1, 1)))
        radiance = radiance + 2000 * soft_step(3.0 - angle, 0.5)[..., None] * np.array([1.0, 0.95, 0.85])
        return radiance
    if name == "studio":
        radiance = np.full(directions.shape, 0.05)
        azimuth = np.degrees(np.arctan2(y, x))
        elevation = np.degrees(np.arcsin(np.clip(z, -1, 1)))

        def box(centre_az, centre_el, width, height):
            d_az = (azimuth - centre_az + 180) % 360 - 180
            return (soft_step(width / 2 - np.abs(d_az), 1.0) * soft_step(height / 2 - np.abs(elevation - centre_el), 1.0))

        radiance = radiance + 4.0 * box(-120, 30, 40, 30)[..., None]
        radiance = radiance + 8.0 * box(90, 15, 10, 40)[..., None] * np.array([1.0, 0.8, 0.6])
        return radiance
    raise ValueError(f"procedural_map: name must be 'sky' or 'studio'; got {name!r}.")
