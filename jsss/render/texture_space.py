"""Texture-space geometry: what surface point each texel stands for (d'Eon 2007 sec. 5).

Rasterizing the mesh in its UV layout gives each texel a world position, a normal and a
valid flag; texels outside every triangle (the gutter between charts) are invalid and are
left out of blurs and lookups by weight, so seams neither darken nor leak. The *stretch*
of a texel is the world length [mm] of one texel step along ``u`` and along ``v``; it
comes from the exact per-triangle Jacobian of the UV map (d'Eon computes the same from
screen-space derivatives) and scales the blur taps so that a Gaussian of variance ``v`` mm^2
is as wide on the surface wherever the UV layout squeezes or stretches it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .mesh import Mesh
from .raster import rasterize, surface_attributes

__all__ = ["TexelGeometry", "bake_texels", "face_stretch", "stretch_variation"]


@dataclass(frozen=True, eq=False)
class TexelGeometry:
    """Per-texel surface data of a mesh at one texture size (NumPy, computed once).

    Attributes
    ----------
    position, normal : ndarray, shape (S, S, 3)
        World position [mm] and unit normal; zeros on invalid texels.
    uv : ndarray, shape (S, S, 2)
    mask : ndarray of bool, shape (S, S)
    stretch : ndarray, shape (S, S, 2)
        World length [mm] of one texel along u (columns) and v (rows).
    area : ndarray, shape (S, S)
        World area [mm^2] a texel covers (0 on invalid texels).
    wrap_u : bool
    """

    position: np.ndarray
    normal: np.ndarray
    uv: np.ndarray
    mask: np.ndarray
    stretch: np.ndarray
    area: np.ndarray
    wrap_u: bool

    @property
    def size(self) -> int:
        return self.mask.shape[0]

    def median_stretch(self) -> float:
        """Median world length of a texel step [mm] over valid texels and both axes."""
        return float(np.median(self.stretch[self.mask]))


def face_stretch(mesh: Mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per face: |dP/du|, |dP/dv| [mm per unit of UV] and the world area of one UV unit square.

    Faces with a degenerate UV triangle get zeros.
    """
    p = mesh.vertices[mesh.faces]
    t = mesh.uvs[mesh.faces]
    dp = np.stack([p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]], -1)  # (F, 3, 2)
    dt = np.stack([t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]], -1)  # (F, 2, 2)
    det = dt[:, 0, 0] * dt[:, 1, 1] - dt[:, 0, 1] * dt[:, 1, 0]
    ok = np.abs(det) > 1e-14
    inv = np.zeros_like(dt)
    safe = np.where(ok, det, 1.0)
    inv[:, 0, 0], inv[:, 0, 1] = dt[:, 1, 1] / safe, -dt[:, 0, 1] / safe
    inv[:, 1, 0], inv[:, 1, 1] = -dt[:, 1, 0] / safe, dt[:, 0, 0] / safe
    jac = np.einsum("fij,fjk->fik", dp, inv)  # columns dP/du, dP/dv
    du = np.linalg.norm(jac[:, :, 0], axis=1)
    dv = np.linalg.norm(jac[:, :, 1], axis=1)
    area = np.linalg.norm(np.cross(jac[:, :, 0], jac[:, :, 1]), axis=1)
    return np.where(ok, du, 0.0), np.where(ok, dv, 0.0), np.where(ok, area, 0.0)


def stretch_variation(mesh: Mesh) -> float:
    """How unevenly the UV map stretches the surface: 0 for a uniform, square map.

    The spread (95th over 5th percentile, weighted by world area, minus 1) of the texel
    lengths along both axes over their common median.
    """
    du, dv, area = face_stretch(mesh)
    p = mesh.vertices[mesh.faces]
    world = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    keep = (area > 0) & (world > 0)
    lengths = np.concatenate([du[keep], dv[keep]])
    weights = np.concatenate([world[keep], world[keep]])
    order = np.argsort(lengths)
    cdf = np.cumsum(weights[order]) / weights.sum()
    lo, hi = np.interp([0.05, 0.95], cdf, lengths[order])
    return float(hi / lo - 1.0)


def bake_texels(mesh: Mesh, size: int) -> TexelGeometry:
    """Rasterize ``mesh`` in UV space at ``size`` x ``size`` texels."""
    if size < 8:
        raise ValueError(f"texture size must be at least 8 texels; got {size}.")
    xy = mesh.uvs * size
    raster = rasterize(xy, np.ones(len(xy)), mesh.faces, (size, size), perspective=False)
    mask = raster.mask
    # One interpolation of all three (each gathers every texel's corners: a third of the time apart).
    attributes = surface_attributes(raster, mesh.faces, np.concatenate([mesh.vertices, mesh.normals, mesh.uvs], 1))
    position, normal, uv = attributes[..., :3], attributes[..., 3:6], attributes[..., 6:]
    normal /= np.where(mask, np.linalg.norm(normal, axis=-1), 1.0)[..., None]
    du, dv, area = face_stretch(mesh)
    face = np.where(mask, raster.face, 0)
    stretch = np.where(mask[..., None], np.stack([du[face], dv[face]], -1) / size, 0.0)
    texel_area = np.where(mask, area[face] / size**2, 0.0)
    mask = mask & (texel_area > 0)
    return TexelGeometry(position, normal, uv, mask, stretch, texel_area, mesh.wrap_u)
