"""Mesh topology and distances (trimesh-backed where trimesh does the job) against brute force."""

import itertools

import numpy as np
import pytest

from jsss.render.mesh import (
    _distance_to_segments,
    box,
    distance_to_rim,
    distance_to_surface,
    fin,
    is_closed,
    load_obj,
    plane,
    rim_segments,
    uv_sphere,
    weld,
)

_QUAD = ("v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
         "vn 0 0 1\nf 1/1/1 2/2/1 3/3/1\nf 1/1/1 3/3/1 4/4/1\n")


def _small_meshes(tmp_path):
    obj = tmp_path / "quad.obj"
    obj.write_text(_QUAD)
    return {"sphere": uv_sphere(3.0, segments=5, rings=3), "plane": plane(10.0, segments=2), "box": box(4.0, segments=2),
            "fin": fin(10.0, 20.0, 1.0, segments=2), "obj": load_obj(obj),
            "micro box": box((3.0, 50.0, 0.2), segments=5).transformed(scale=1e-3, translate=(1.0, 2.0, 3.0))}


@pytest.fixture
def meshes(tmp_path):
    return _small_meshes(tmp_path)


def _welded_edge_uses(mesh):
    """{(i, j): triangles using the edge} on the welded surface, counted one triangle at a time."""
    _, _, faces = weld(mesh)
    uses = {}
    for face in faces.tolist():
        for a, b in ((face[0], face[1]), (face[1], face[2]), (face[2], face[0])):
            uses[min(a, b), max(a, b)] = uses.get((min(a, b), max(a, b)), 0) + 1
    return uses


def _segment_distance(p, a, b):
    along = b - a
    t = 0.0 if not along.any() else min(max(float(np.dot(p - a, along) / np.dot(along, along)), 0.0), 1.0)
    return float(np.linalg.norm(p - (a + t * along)))


def _triangle_distance(p, a, b, c):
    """Closest point by cases: the plane's foot when it falls inside, else the nearest edge."""
    edges = min(_segment_distance(p, a, b), _segment_distance(p, b, c), _segment_distance(p, c, a))
    normal = np.cross(b - a, c - a)
    if np.dot(normal, normal) <= 1e-30 * max(np.dot(b - a, b - a), np.dot(c - a, c - a)) ** 2:
        return edges  # collapsed: a segment or a point
    foot = p - np.dot(p - a, normal) / np.dot(normal, normal) * normal
    s, t = np.linalg.lstsq(np.stack([b - a, c - a], 1), foot - a, rcond=None)[0]
    return float(np.linalg.norm(p - foot)) if (s >= 0 and t >= 0 and s + t <= 1) else edges


def test_weld_merges_the_coincident_vertices_in_lexicographic_order(meshes):
    """Two mesh vertices share a welded vertex iff they are at the same position up to
    rounding (all pairs compared; the sphere's seam differs by 1e-15 mm); welded vertices come
    in the strictly increasing lexicographic order of their rounded positions (the order the
    normal filter's Laplacian is built in); faces are re-indexed and collapsed ones dropped."""
    for name, mesh in meshes.items():
        positions, index, faces = weld(mesh)
        size = float(np.ptp(mesh.vertices))
        same = np.abs(mesh.vertices[:, None] - mesh.vertices[None]).max(-1) < 1e-12 * size
        assert np.array_equal(same, index[:, None] == index[None]), name
        assert np.abs(positions[index] - mesh.vertices).max() < 1e-12 * size, name
        grid = np.round(positions / (1e-9 * size)).astype(np.int64)  # the default tolerance's grid
        assert np.array_equal(np.lexsort(grid.T[::-1]), np.arange(len(positions))), name
        assert len(np.unique(grid, axis=0)) == len(positions), name
        mapped = index[mesh.faces]
        kept = [f for f in mapped.tolist() if len(set(f)) == 3]
        assert faces.tolist() == kept, name


def test_is_closed_is_every_welded_edge_used_twice(meshes):
    """Closed shapes (sphere, box) are closed, open ones (plane, fin, quad) are not, each as an
    edge count says; a box with one triangle taken out is open."""
    for name, mesh in meshes.items():
        assert is_closed(mesh) == all(n == 2 for n in _welded_edge_uses(mesh).values()), name
    assert is_closed(meshes["sphere"]) and is_closed(meshes["box"]) and not is_closed(meshes["fin"])
    b = meshes["box"]
    holed = type(b)(b.vertices, b.normals, b.uvs, b.faces[1:])
    assert not is_closed(holed)


def test_rim_segments_are_the_edges_one_triangle_uses(meshes):
    """The rim is the set of welded edges used once, each from its lower welded index to its
    higher; empty for closed shapes."""
    for name, mesh in meshes.items():
        positions, _, _ = weld(mesh)
        once = sorted(edge for edge, n in _welded_edge_uses(mesh).items() if n == 1)
        expected = positions[np.array(once, int).reshape(-1, 2)]
        got = rim_segments(mesh)
        assert got.shape == expected.shape, name
        key = lambda s: sorted(map(tuple, s.reshape(len(s), 6).tolist()))
        assert key(got) == key(expected), name
    assert len(rim_segments(meshes["plane"])) == 8 and len(rim_segments(meshes["box"])) == 0


def test_distance_to_rim_is_the_nearest_rim_segment(meshes):
    """Against a loop over the rim's segments, point by point; inf for closed shapes."""
    rng = np.random.default_rng(1)
    for name, mesh in meshes.items():
        lo, hi = mesh.bounds
        points = rng.uniform(lo - 0.2 * (hi - lo), hi + 0.2 * (hi - lo), (4, 5, 3))
        got = distance_to_rim(mesh, points)
        assert got.shape == (4, 5)
        segments = rim_segments(mesh)
        for p, d in zip(points.reshape(-1, 3), got.ravel()):
            expected = min((_segment_distance(p, a, b) for a, b in segments), default=np.inf)
            assert d == pytest.approx(expected, rel=1e-12, abs=1e-12 * float(np.ptp(mesh.vertices))), name


def test_segment_distances_do_not_depend_on_the_block_size():
    """Points go through in blocks to bound memory: any block size gives the same bits."""
    rng = np.random.default_rng(2)
    start, end, points = rng.normal(size=(7, 3)), rng.normal(size=(7, 3)), rng.normal(size=(1000, 3))
    whole = _distance_to_segments(points, start, end, chunk=10**9)
    for chunk in (1, 7, 50, 6999):
        assert np.array_equal(_distance_to_segments(points, start, end, chunk=chunk), whole)


def test_distance_to_surface_is_the_nearest_triangle(meshes):
    """Against closest points found case by case, triangle by triangle, at points around each
    mesh, on its vertices and at its triangles' centres; the sphere's collapsed pole triangles
    and the micrometre box's tiny ones included."""
    rng = np.random.default_rng(3)
    for name, mesh in meshes.items():
        lo, hi = mesh.bounds
        size = float(np.ptp(mesh.vertices))
        triangles = mesh.vertices[mesh.faces]
        points = np.concatenate([rng.uniform(lo - 0.3 * (hi - lo) - 0.1 * size, hi + 0.3 * (hi - lo) + 0.1 * size,
                                             (12, 3)), mesh.vertices[:3], triangles[:3].mean(1)])
        for p in points:
            expected = min(_triangle_distance(p, *t) for t in triangles)
            assert distance_to_surface(mesh, p) == pytest.approx(expected, rel=1e-12, abs=1e-12 * size), name


def test_distance_to_surface_of_a_sphere_is_not_zero_everywhere():
    """The uv-sphere's pole triangles have zero area; a point 30 mm up the axis is 20 mm from
    the pole vertex of a 10 mm sphere, and the centre is about a radius from every facet."""
    sphere = uv_sphere(10.0)
    assert distance_to_surface(sphere, [0.0, 0.0, 30.0]) == pytest.approx(20.0, rel=1e-14)
    assert 9.9 < distance_to_surface(sphere, [0.0, 0.0, 0.0]) < 10.0


@pytest.mark.parametrize("pair", list(itertools.combinations(range(3), 2)))
def test_distance_to_a_collapsed_triangle_is_to_its_segment(pair):
    """A triangle with two corners at one place is a segment, whichever two they are."""
    from jsss.render.mesh import Mesh

    corners = np.array([[0.0, 0.0, 0.0], [4.0, 0.0, 0.0], [0.0, 3.0, 0.0]])
    corners[pair[1]] = corners[pair[0]]
    mesh = Mesh(corners, np.tile([0.0, 0.0, 1.0], (3, 1)), np.zeros((3, 2)), np.array([[0, 1, 2]]))
    p = np.array([1.0, 1.0, 2.0])
    expected = min(_segment_distance(p, corners[i], corners[j]) for i, j in ((0, 1), (1, 2), (2, 0)))
    assert distance_to_surface(mesh, p) == pytest.approx(expected, rel=1e-14)
