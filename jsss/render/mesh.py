"""Triangle meshes with UVs: the built-in procedural shapes and OBJ loading.

A :class:`Mesh` is plain NumPy (float64 positions in mm, UVs in [0, 1]^2): geometry is fixed
while materials and lights change, so everything derived from it (texel positions,
rasterized views, shadow maps) is computed once and handed to the JAX passes as arrays.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

__all__ = ["MESH_FILES", "MM_PER_UNIT", "Mesh", "box", "distance_to_rim", "distance_to_surface", "fin", "is_closed",
           "load_mesh", "load_obj", "plane", "uv_sphere", "weld"]


@dataclass(frozen=True, eq=False)
class Mesh:
    """Triangles with per-vertex positions [mm], unit normals and UVs.

    Attributes
    ----------
    vertices : ndarray, shape (V, 3)
    normals : ndarray, shape (V, 3)
    uvs : ndarray, shape (V, 2)
        In [0, 1]; ``u`` runs along texture columns, ``v`` along rows.
    faces : ndarray of int, shape (F, 3)
        Counter-clockwise seen from outside (the normal's side).
    wrap_u : bool
        The texture is periodic in ``u`` (a sphere's longitude): blurs wrap around.
    name : str
    has_uvs : bool
        False for a mesh whose file has no texture coordinates (``uvs`` are then zeros): the
        pixel methods render it; texture space and surface maps need a UV layout.
    """

    vertices: np.ndarray
    normals: np.ndarray
    uvs: np.ndarray
    faces: np.ndarray
    wrap_u: bool = False
    name: str = "mesh"
    has_uvs: bool = True
    _digest: list = field(default_factory=list, repr=False)

    def __post_init__(self):
        v, n, t, f = (np.asarray(a) for a in (self.vertices, self.normals, self.uvs, self.faces))
        if v.ndim != 2 or v.shape[1] != 3 or n.shape != v.shape:
            raise ValueError(f"Mesh {self.name!r}: vertices and normals must both be (V, 3); got {v.shape}, {n.shape}.")
        if t.shape != (len(v), 2):
            raise ValueError(f"Mesh {self.name!r}: uvs must be (V, 2) = ({len(v)}, 2); got {t.shape}.")
        if f.ndim != 2 or f.shape[1] != 3 or len(f) == 0:
            raise ValueError(f"Mesh {self.name!r}: faces must be a non-empty (F, 3) array; got {f.shape}.")
        if f.min() < 0 or f.max() >= len(v):
            raise ValueError(f"Mesh {self.name!r}: face indices must lie in [0, {len(v) - 1}].")
        if not (np.all(np.isfinite(v)) and np.all(np.isfinite(t))):
            raise ValueError(f"Mesh {self.name!r}: vertices and uvs must be finite.")
        norm = np.linalg.norm(n, axis=1, keepdims=True)
        object.__setattr__(self, "vertices", v.astype(np.float64))
        object.__setattr__(self, "normals", (n / np.where(norm > 0, norm, 1)).astype(np.float64))
        object.__setattr__(self, "uvs", t.astype(np.float64))
        object.__setattr__(self, "faces", f.astype(np.int64))

    def digest(self) -> str:
        """A hash of the geometry (for caches keyed by the mesh)."""
        if not self._digest:
            h = hashlib.sha256()
            for a in (self.vertices, self.uvs, self.faces):
                h.update(np.ascontiguousarray(a).tobytes())
            self._digest.append(h.hexdigest()[:16])
        return self._digest[0]

    def transformed(self, *, scale: float = 1.0, translate=(0.0, 0.0, 0.0)) -> Mesh:
        """The mesh scaled about the origin, then moved."""
        return Mesh(self.vertices * scale + np.asarray(translate, float), self.normals, self.uvs,
                    self.faces, self.wrap_u, self.name, self.has_uvs)

    @property
    def bounds(self) -> tuple[np.ndarray, np.ndarray]:
        return self.vertices.min(axis=0), self.vertices.max(axis=0)


def weld(mesh: Mesh, *, tolerance: float = 1e-9):
    """Merge vertices at the same position (UV seams, hard edges): the surface's topology.

    Positions are rounded to a grid of ``tolerance`` times the mesh's extent; welded vertices
    come in the grid's lexicographic order.

    Returns
    -------
    positions : (U, 3); index : (V,) the welded vertex of each mesh vertex; faces : (F, 3) on U

    Notes
    -----
    Kept rather than trimesh's ``merge_vertices`` or ``grouping.unique_rows``: both find the
    same groups on the built-in shapes but number them otherwise (first appearance; hash
    order), which permutes the Laplacian of :mod:`jsss.render.normal_filter`: spectrally
    filtered normals then move by up to 3e-14, Patro's by 1e-15 (uv_sphere, box, fin).
    ``merge_vertices`` also rounds to absolute decimal digits, not to a fraction of the
    mesh's size, leaves unreferenced vertices out of ``index``, and was no faster (23.5 ms
    against 18.7 ms at 100k faces, 0.8 against 0.7 ms for a 64 x 32 sphere; trimesh 5.2).
    """
    scale = max(float(np.ptp(mesh.vertices)), 1e-300)
    keys = np.round(mesh.vertices / (scale * tolerance)).astype(np.int64)
    _, first, index = np.unique(keys, axis=0, return_index=True, return_inverse=True)
    index = index.reshape(-1)
    faces = index[mesh.faces]
    keep = (faces[:, 0] != faces[:, 1]) & (faces[:, 1] != faces[:, 2]) & (faces[:, 0] != faces[:, 2])
    return mesh.vertices[first], index, faces[keep]  # collapsed triangles (at poles) dropped


def _welded_normals(mesh: Mesh) -> np.ndarray:
    """Area-weighted vertex normals of the welded surface, given back to every copy of a vertex
    (an OBJ splits a vertex wherever its texture coordinates jump)."""
    import trimesh

    with np.errstate(all="ignore"):  # a degenerate mesh (no extent) is refused by the scene, with its reason
        positions, index, faces = weld(mesh)
        welded = np.asarray(trimesh.Trimesh(positions, faces, process=False).vertex_normals)
    return welded[index]


def _welded_surface(mesh: Mesh):
    """The welded surface as a ``trimesh.Trimesh`` (``process=False``: kept as welded)."""
    import trimesh

    positions, _, faces = weld(mesh)
    return trimesh.Trimesh(positions, faces, process=False)


def rim_segments(mesh: Mesh) -> np.ndarray:
    """The open surface's boundary: (E, 2, 3) end points of the edges only one triangle uses
    (empty for a closed surface), each from its lower welded vertex index to its higher."""
    from trimesh.grouping import group_rows

    surface = _welded_surface(mesh)
    edges = surface.edges_sorted[group_rows(surface.edges_sorted, require_count=1)]
    return np.asarray(surface.vertices, float)[edges]


def _distance_to_segments(points, start, end, *, chunk: int = 1 << 20) -> np.ndarray:
    """Distance from each of ``points`` (P, 3) to the nearest of the segments ``start``-``end``
    (each (E, 3)): shape (P,). Points go in blocks of about ``chunk`` / E (memory ~ 100 chunk
    bytes, not 100 P E)."""
    flat = np.asarray(points, float).reshape(-1, 1, 3)
    along = end - start
    length2 = np.maximum((along**2).sum(-1), 1e-300)
    step = max(1, chunk // max(len(start), 1))
    out = np.empty(len(flat))
    for i in range(0, len(flat), step):
        block = flat[i:i + step]
        t = np.clip(((block - start) * along).sum(-1) / length2, 0.0, 1.0)
        out[i:i + step] = np.linalg.norm(block - (start + t[..., None] * along), axis=-1).min(-1)
    return out


def distance_to_rim(mesh: Mesh, points) -> np.ndarray:
    """Distance [mm] from each of ``points`` (..., 3) to the nearest rim edge (inf when closed).

    Point-to-segment distances are ours: trimesh has closest points on triangles, not on
    segments.
    """
    points = np.asarray(points, float)
    segments = rim_segments(mesh)
    if len(segments) == 0:
        return np.full(points.shape[:-1], np.inf)
    return _distance_to_segments(points, segments[:, 0], segments[:, 1]).reshape(points.shape[:-1])


def distance_to_surface(mesh: Mesh, point) -> float:
    """Shortest distance [mm] from ``point`` to the mesh's triangles (inside, edges or corners).

    The nearest point of a triangle is the foot of the perpendicular on its plane where that
    falls inside it, else the nearest point of its three edges (so a collapsed triangle, a
    sphere's pole, is its segment). Each triangle is moved to ``point`` and scaled by its
    longest edge first, so that tolerances are relative (unscaled, triangles of 1e-5 mm had
    their closest point off by 1.3e-5 mm in trimesh's absolute ones). NumPy: the planner asks
    this for every point light, and importing trimesh for it was 0.4-1.1 s of a command's start.
    """
    triangles = mesh.vertices[mesh.faces] - np.asarray(point, float)           # (T, 3, 3), the point at 0
    size = np.linalg.norm(triangles - np.roll(triangles, 1, axis=1), axis=-1).max(-1)
    size = np.where(size > 0, size, 1.0)
    a, b, c = np.moveaxis(triangles / size[:, None, None], 1, 0)              # each (T, 3), longest edge 1
    nearest_edge = np.min([_point_segment(u, v) for u, v in ((a, b), (b, c), (c, a))], axis=0)
    normal = np.cross(b - a, c - a)
    area2 = (normal**2).sum(-1)
    flat = area2 > 1e-24                                                      # not collapsed (scaled units)
    n2 = np.where(flat, area2, 1.0)
    height = (a * normal).sum(-1)                                             # signed, times |n|
    foot = normal * (height / n2)[:, None]
    inside = flat.copy()
    for u, v in ((a, b), (b, c), (c, a)):
        inside &= (np.cross(v - u, foot - u) * normal).sum(-1) >= 0
    plane = np.abs(height) / np.sqrt(n2)
    return float(np.min(np.where(inside, np.minimum(plane, nearest_edge), nearest_edge) * size))


def _point_segment(u, v):
    """Distance from the origin to each segment u-v (rows; zero-length segments are points)."""
    along = v - u
    length2 = (along**2).sum(-1)
    t = np.clip(-(u * along).sum(-1) / np.where(length2 > 0, length2, 1.0), 0.0, 1.0)
    return np.linalg.norm(u + t[:, None] * along, axis=-1)


def is_closed(mesh: Mesh) -> bool:
    """True when the welded surface has no boundary: every edge is shared by two triangles
    (the rule of ``trimesh.Trimesh.is_watertight``, counted here in NumPy: the planner asks
    this of every scene, and importing trimesh costs a cold start 0.35 s)."""
    _, _, faces = weld(mesh)
    edges = np.sort(faces[:, [0, 1, 1, 2, 2, 0]].reshape(-1, 2), axis=1)
    _, counts = np.unique(edges, axis=0, return_counts=True)
    return bool(len(faces) > 0 and np.all(counts == 2))


def shadows_itself(mesh: Mesh) -> bool:
    """True when part of the surface can hide the sky from another part: a closed surface whose
    volume falls short of its convex hull's by more than 0.1 %. Convex bodies and open
    surfaces (a plane, lit from above) see their whole upper hemisphere."""
    from scipy.spatial import ConvexHull

    surface = _welded_surface(mesh)
    if not surface.is_watertight:  # open (is_closed, without welding twice)
        return False
    try:
        hull = ConvexHull(np.asarray(surface.vertices, float)).volume
    except Exception:  # a flat or degenerate point set (Qhull refuses it): nothing to hide behind
        return False
    return bool(abs(float(surface.volume)) < (1 - 1e-3) * hull)


def _grid_faces(rows: int, cols: int) -> np.ndarray:
    """Two counter-clockwise triangles per cell of a (rows+1) x (cols+1) vertex grid."""
    i, j = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    a = (i * (cols + 1) + j).ravel()
    b, c, d = a + 1, a + cols + 1, a + cols + 2
    return np.concatenate([np.stack([a, b, d], 1), np.stack([a, d, c], 1)])


def _outward(vertices, normals, faces):
    """Faces re-wound where needed so that each is counter-clockwise seen from its normals' side."""
    p = vertices[faces]
    geometric = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = np.einsum("ij,ij->i", geometric, normals[faces].sum(1)) < 0
    return np.where(flip[:, None], faces[:, [0, 2, 1]], faces)


def uv_sphere(radius: float = 10.0, *, segments: int = 64, rings: int = 32) -> Mesh:
    """A latitude-longitude sphere centred at the origin; ``u`` is longitude (wraps)."""
    if radius <= 0 or segments < 3 or rings < 2:
        raise ValueError(f"uv_sphere needs radius > 0, segments >= 3, rings >= 2; got {radius}, {segments}, {rings}.")
    theta = np.linspace(0, np.pi, rings + 1)  # from the north pole (+z)
    phi = np.linspace(0, 2 * np.pi, segments + 1)
    T, P = np.meshgrid(theta, phi, indexing="ij")
    n = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    uv = np.stack([P / (2 * np.pi), T / np.pi], -1).reshape(-1, 2)
    faces = _outward(radius * n, n, _grid_faces(rings, segments))
    return Mesh(radius * n, n, uv, faces, wrap_u=True, name=f"sphere(r={radius:g})")


def plane(width: float = 40.0, depth: float | None = None, *, segments: int = 1) -> Mesh:
    """A flat rectangle in z = 0 facing +z, centred at the origin; UVs span it once."""
    depth = width if depth is None else depth
    if width <= 0 or depth <= 0 or segments < 1:
        raise ValueError(f"plane needs width, depth > 0 and segments >= 1; got {width}, {depth}, {segments}.")
    s = np.linspace(0, 1, segments + 1)
    V, U = np.meshgrid(s, s, indexing="ij")
    pos = np.stack([(U - 0.5) * width, (0.5 - V) * depth, np.zeros_like(U)], -1).reshape(-1, 3)
    uv = np.stack([U, V], -1).reshape(-1, 2)
    normals = np.tile([0.0, 0.0, 1.0], (len(pos), 1))
    faces = _outward(pos, normals, _grid_faces(segments, segments))
    return Mesh(pos, normals, uv, faces, name=f"plane({width:g}x{depth:g})")


def box(size=(20.0, 20.0, 20.0), *, segments: int = 8) -> Mesh:
    """An axis-aligned box centred at the origin; its six faces tile the texture in a 3 x 2 atlas."""
    size = np.broadcast_to(np.asarray(size, float), (3,))
    if np.any(size <= 0):
        raise ValueError(f"box size must be positive; got {size.tolist()}.")
    s = np.linspace(0, 1, segments + 1)
    V, U = np.meshgrid(s, s, indexing="ij")
    pad = 0.02  # gutter between atlas tiles so that a blur or a lookup does not mix faces
    parts, offset = [], 0
    for tile, (axis, sign) in enumerate([(0, 1), (0, -1), (1, 1), (1, -1), (2, 1), (2, -1)]):
        a, b = [i for i in range(3) if i != axis]
        pos = np.zeros(U.shape + (3,))
        pos[..., a] = (U - 0.5) * size[a]
        pos[..., b] = (0.5 - V) * size[b]
        pos[..., axis] = sign * size[axis] / 2
        n = np.zeros_like(pos)
        n[..., axis] = sign
        col, row = tile % 3, tile // 3
        uv = np.stack([(col + pad + U * (1 - 2 * pad)) / 3, (row + pad + V * (1 - 2 * pad)) / 2], -1)
        parts.append((pos.reshape(-1, 3), n.reshape(-1, 3), uv.reshape(-1, 2),
                      _grid_faces(segments, segments) + offset))
        offset += pos.size // 3
    v, nn, t, f = (np.concatenate(p) for p in zip(*parts))
    return Mesh(v, nn, t, _outward(v, nn, f), name=f"box({size[0]:g}x{size[1]:g}x{size[2]:g})")


def fin(height: float = 30.0, radius: float = 40.0, thickness: float = 2.0, *, arc_degrees: float = 60.0,
        segments: int = 32) -> Mesh:
    """A thin curved shell (a piece of a cylinder wall): light passes through it.

    The outer wall faces +x at the middle; the UV atlas holds the outer wall in the left
    half and the inner wall in the right half (the narrow rims are left out: at
    ``thickness`` << ``height`` they carry almost no light). The surface is open at its
    rims, so it is for showing transmission, not for closed-surface energy checks.
    """
    if min(height, radius, thickness) <= 0 or thickness >= radius:
        raise ValueError(f"fin needs height, radius, thickness > 0 and thickness < radius; "
                         f"got {height}, {radius}, {thickness}.")
    s = np.linspace(0, 1, segments + 1)
    V, U = np.meshgrid(s, s, indexing="ij")
    phi = np.deg2rad(arc_degrees) * (U - 0.5)
    z = (0.5 - V) * height
    pad = 0.02
    parts, offset = [], 0
    for half, (r, sign) in enumerate([(radius, 1.0), (radius - thickness, -1.0)]):
        pos = np.stack([r * np.cos(phi) - radius, r * np.sin(phi), z], -1)
        n = sign * np.stack([np.cos(phi), np.sin(phi), np.zeros_like(phi)], -1)
        uv = np.stack([(half + pad + U * (1 - 2 * pad)) / 2, pad + V * (1 - 2 * pad)], -1)
        faces = _grid_faces(segments, segments) + offset
        parts.append((pos.reshape(-1, 3), n.reshape(-1, 3), uv.reshape(-1, 2), faces))
        offset += pos.size // 3
    v, nn, t, f = (np.concatenate(p) for p in zip(*parts))
    return Mesh(v, nn, t, _outward(v, nn, f), name=f"fin(t={thickness:g})")


MM_PER_UNIT = {"mm": 1.0, "cm": 10.0, "m": 1000.0, "in": 25.4}  # the units a mesh file may be in
MESH_FILES = {".obj": "mm", ".gltf": "m", ".glb": "m"}  # suffix: the file's units unless a scene says (glTF 2.0: metres)


def load_obj(path) -> Mesh:
    """:func:`load_mesh`'s mesh, without its texture (kept for OBJ callers)."""
    return load_mesh(path)[0]


def load_mesh(path) -> tuple[Mesh, np.ndarray | None]:
    """Read a triangle mesh, its texture coordinates and its base-colour texture from a
    Wavefront OBJ (+ MTL) or a glTF 2.0 file (.gltf, .glb), via trimesh.

    Returns the mesh in the file's own units (:data:`MESH_FILES` names them, :data:`MM_PER_UNIT`
    converts) and
    the base-colour texture as linear RGB (H, W, 3) in texel order (the image's bottom row
    first, as :func:`jsss.render.surface_maps.read_map` reads a map), times the material's
    base-colour factor; None where the file has no texture or no UVs. A file without UVs
    gives a mesh marked ``has_uvs = False``.

    Raises
    ------
    ValueError
        The file is missing or not a mesh, a texture it names is missing, or a coordinate is
        not finite; the message names the file.
    """
    import trimesh

    path = Path(path)
    if not path.is_file():
        raise ValueError(f"{path}: no such mesh file.")
    if path.suffix.lower() not in MESH_FILES:
        raise ValueError(f"{path}: a mesh must be {', '.join(MESH_FILES)}; got {path.suffix or 'no suffix'}.")
    named = _check_textures_exist(path)
    try:
        loaded = trimesh.load(path, process=False, force="mesh")
    except Exception as error:  # trimesh raises many types for a bad file
        raise ValueError(f"{path}: not a readable mesh ({type(error).__name__}: {error}).") from None
    if not isinstance(loaded, trimesh.Trimesh) or len(loaded.faces) == 0:
        raise ValueError(f"{path}: holds no triangles.")
    uv = getattr(loaded.visual, "uv", None)
    has_uvs = uv is not None and len(uv) == len(loaded.vertices)
    if has_uvs:  # OBJ's convention for every format (trimesh flips glTF's v on reading): v runs up the
        uv = np.asarray(uv, float).copy()  # image, and maps are read bottom row first (surface_maps.read_map)
    else:  # the pixel methods need none; the planner keeps texture space off (jsss.render.planner)
        uv = np.zeros((len(loaded.vertices), 2))
    vertices = np.asarray(loaded.vertices, float)
    if not np.all(np.isfinite(vertices)):
        raise ValueError(f"{path}: {int(np.size(vertices) - np.isfinite(vertices).sum())} vertex coordinate(s) are "
                         "NaN or infinite.")
    if np.abs(vertices).max(initial=0.0) > 1e30:
        raise ValueError(f"{path}: vertex coordinates must lie within 1e30 (largest {np.abs(vertices).max():.3g}).")
    supplied_normals = "vertex_normals" in loaded._cache  # the file's own (vn, NORMAL): hard edges kept
    with np.errstate(all="ignore"):  # trimesh's normals of a degenerate mesh: checked where it matters
        normals = np.asarray(loaded.vertex_normals)
    mesh = Mesh(vertices, normals, uv, np.asarray(loaded.faces), name=path.stem, has_uvs=has_uvs)
    if not supplied_normals:  # computed: from the welded surface, or each UV seam shades as a crease
        mesh = Mesh(vertices, _welded_normals(mesh), uv, mesh.faces, name=path.stem, has_uvs=has_uvs)
    # An OBJ that names no map_Kd has none: trimesh still offers a 2 x 2 image of its default grey.
    named_texture = path.suffix.lower() != ".obj" or bool(named)
    return mesh, (_base_colour(loaded.visual) if has_uvs and named_texture else None)


def _base_colour(visual) -> np.ndarray | None:
    """The base-colour texture of a trimesh visual (glTF's baseColorTexture times its factor, an
    MTL's map_Kd), linear, in texel order; None without one."""
    from .surface_maps import srgb_to_linear

    material = getattr(visual, "material", None)
    image = getattr(material, "baseColorTexture", None)
    if image is None:
        image = getattr(material, "image", None)
    if image is None:
        return None
    rgb = srgb_to_linear(np.asarray(image.convert("RGB"), float) / 255.0)
    factor = getattr(material, "baseColorFactor", None)
    if factor is not None:  # trimesh keeps it as RGBA bytes
        rgb = rgb * (np.asarray(factor, float)[:3] / 255.0)
    return np.ascontiguousarray(rgb[::-1])


def _check_textures_exist(path: Path) -> list[str]:
    """A texture the file names that is not there is an error naming both (trimesh would load
    the mesh without it, and the object would render white). Returns the names it checked."""
    import json

    names = []
    if path.suffix.lower() == ".obj":
        with open(path, "rb") as handle:
            if b"\x00" in handle.read(1 << 16):
                raise ValueError(f"{path}: a binary file, not a text OBJ.")
        text = path.read_text(errors="replace")
        for library in (line.split(None, 1)[1].strip() for line in text.splitlines()
                        if line.startswith("mtllib ") and len(line.split(None, 1)) > 1):
            mtl = path.parent / library
            if not mtl.is_file():
                raise ValueError(f"{path}: its material library {library} is missing (mtllib).")
            names += [line.split()[-1] for line in mtl.read_text(errors="replace").splitlines()
                      if line.strip().startswith("map_Kd ")]
    elif path.suffix.lower() == ".gltf":
        try:
            document = json.loads(path.read_text())
        except (ValueError, UnicodeDecodeError) as error:
            raise ValueError(f"{path}: not a glTF file (its JSON: {error}).") from None
        names += [item["uri"] for item in document.get("images", []) + document.get("buffers", [])
                  if isinstance(item, dict) and "uri" in item and not str(item["uri"]).startswith("data:")]
    for name in names:
        if not (path.parent / name).is_file():
            raise ValueError(f"{path}: the texture or buffer {name} it names is missing (beside the file).")
    return names
