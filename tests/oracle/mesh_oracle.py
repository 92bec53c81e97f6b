"""Embree oracle of the mesh-scene tests (run in the .venv oracle environment).

Usage: mesh_oracle.py DIR

Writes, for each case, CASE.obj and CASE.glb (exported by trimesh), CASE_rays.npy (N, 8)
float64 rows `ox oy oz tmin dx dy dz tmax`, CASE_t.npy (N,) float64: Embree's first-hit
distance of each ray against the case's triangles (inf on a miss), computed with embreex
in robust mode, and CASE_t_exact.npy: the same by brute force in float64 with NumPy, the
referee where hytrace and Embree disagree (Embree's float32 test still misses a few
head-on rays at vertices and reports a few crossings no triangle has), and CASE_ill.npy
(N,) float64: 1 where the ray is ill-conditioned at the tests' tolerance
(`ill_conditioned`), else 0.

Cases:
  icosphere   a 3-times subdivided icosphere of radius 10 about (1, 2, 3)
  boxes       a 4 x 4 x 3 block of touching unit boxes: one box mesh placed by 48 scene
              nodes (the .glb shares the mesh between nodes; the .obj has them baked)
  far         an icosphere of radius 5 translated 1e5 away from the origin
  heightfield an open 40 x 40 random heightfield (rays from above, below and the sides)
  lumpy       a 4-times subdivided icosphere of radius 10 displaced radially by smooth
              lumps (up to 20%), so no two triangles are alike
  torus       a torus of radii 10 and 3 (64 x 32 sections)
  boxes5m     the block of boxes of `boxes` 5000 from the origin (5 m in mm), placed by
              nodes (the .glb's translations are 5000 out, the .obj's vertices)

Rays come from outside each case's bounds, aimed at random points of the bounds from random
directions, and head-on at vertices and edge midpoints (rays grazing a vertex or edge
tangentially are ill-posed: within rounding they may hit or miss, so none is aimed so).
The accuracy cases (lumpy, torus, boxes5m, and icosphere and far again as icosphere_acc and
far_acc) get rays that stress the f32 triangle test instead (`stress_rays`): incoherent
rays from outside and from inside the bounds, rays at vertices and edges from every
direction (not only head-on), and grazing rays meeting a random point of a triangle at 1 to
6 degrees from its plane. Origins and directions are rounded to float32 before both
Embree (which traces in float32) and the written rays see them, directions to float32 unit
vectors that hytrace's normalization leaves unchanged (`own_unit_f32`), so Embree and both
of hytrace's precisions trace the same rays.

The float64 reference is Moller-Trumbore over the float32 vertices; a ray whose nearest
candidate crossings lie within 1e-9 (in barycentric terms) of a triangle's edge, or whose
triangle is nearly edge-on, is decided again exactly in rational arithmetic (`exact_hit`:
signs of the ray's Plucker products with the edges, the crossing as a fraction), so ties at
shared edges and vertices and near misses at silhouettes have an exact answer.
"""

import os
import sys
from fractions import Fraction

import numpy as np
import trimesh
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

RNG = np.random.default_rng(20261122)
# The accuracy cases' own generator, so the older cases keep their rays.
RNG_ACC = np.random.default_rng(20261127)

# Accuracy cases and the mesh each is made of (an older case's name, or their own).
ACCURACY = {
    "lumpy": "lumpy",
    "torus": "torus",
    "boxes5m": "boxes5m",
    "icosphere_acc": "icosphere",
    "far_acc": "far",
}


def boxes_scene(offset=(0.0, 0.0, 0.0)):
    scene = trimesh.Scene()
    box = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    for i in range(4):
        for j in range(4):
            for k in range(3):
                scene.add_geometry(
                    box,
                    geom_name="box",
                    node_name=f"box_{i}_{j}_{k}",
                    transform=trimesh.transformations.translation_matrix(
                        [i + offset[0], j + offset[1], k + offset[2]]
                    ),
                )
    return scene


def heightfield(n=40):
    xs, ys = np.meshgrid(np.arange(n + 1, dtype=float), np.arange(n + 1, dtype=float), indexing="ij")
    zs = RNG.uniform(0.0, 3.0, size=xs.shape)
    vertices = np.stack([xs.ravel(), ys.ravel(), zs.ravel()], axis=1)
    idx = lambda i, j: i * (n + 1) + j
    faces = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = idx(i, j), idx(i + 1, j), idx(i + 1, j + 1), idx(i, j + 1)
            faces += [[a, b, c], [a, c, d]]
    return trimesh.Trimesh(vertices, np.array(faces), process=False)


def lumpy_sphere():
    """An icosphere of radius 10 about (-2, 1, 4) with smooth radial lumps."""
    m = trimesh.creation.icosphere(subdivisions=4, radius=1.0)
    x, y, z = m.vertices.T
    r = 10.0 * (1.0 + 0.12 * np.sin(3.0 * x + 1.0) * np.cos(2.0 * y) + 0.08 * np.sin(5.0 * z - x))
    return trimesh.Trimesh(m.vertices * r[:, None] + [-2.0, 1.0, 4.0], m.faces, process=False)


def cases():
    """The test geometry, vertices rounded to float32 (what Embree and the Foundry hold)
    so the OBJ text, the GLB and Embree all carry the same vertices."""
    ico = trimesh.creation.icosphere(subdivisions=3, radius=10.0)
    ico.apply_translation([1.0, 2.0, 3.0])
    far = trimesh.creation.icosphere(subdivisions=3, radius=5.0)
    far.apply_translation([1e5, -2e4, 3e4])
    out = {
        "icosphere": ico,
        "boxes": boxes_scene(),
        "far": far,
        "heightfield": heightfield(),
        "lumpy": lumpy_sphere(),
        "torus": trimesh.creation.torus(
            major_radius=10.0, minor_radius=3.0, major_sections=64, minor_sections=32
        ),
        "boxes5m": boxes_scene(offset=(5000.0, 1200.0, -800.0)),
    }
    for g in out.values():
        for m in g.geometry.values() if isinstance(g, trimesh.Scene) else [g]:
            m.vertices = m.vertices.astype(np.float32).astype(np.float64)
    return out


def unit(v):
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def vertex_normals(mesh):
    """Unit sums of the normals of the faces around each vertex, weighted by the faces'
    angles there (a box corner's normal is its diagonal however its faces are split)."""
    sums = np.zeros_like(mesh.vertices)
    angles = mesh.face_angles
    for k in range(3):
        np.add.at(sums, mesh.faces[:, k], mesh.face_normals * angles[:, k : k + 1])
    return unit(sums)


def rays_for(mesh, two_sided, n_random=8000, n_aimed=2000):
    """Rays from outside the bounds: at random points of the bounds from random
    directions, and head-on (within 22 degrees of the outward vertex normal; either side
    of an open mesh) at vertices and edge midpoints, up to `n_aimed` of each."""
    lo, hi = mesh.bounds
    size = float(np.max(hi - lo))
    v = RNG.permutation(len(mesh.vertices))[:n_aimed]
    e = mesh.edges_unique[RNG.permutation(len(mesh.edges_unique))[:n_aimed]]
    aims = np.concatenate([mesh.vertices[v], mesh.vertices[e].mean(axis=1)])
    vn = vertex_normals(mesh)
    normals = unit(np.concatenate([vn[v], vn[e].sum(axis=1)]))
    if two_sided:
        # Not at the open boundary, where a head-on ray may pass just beside the sheet.
        keep = np.all((aims[:, :2] > lo[:2]) & (aims[:, :2] < hi[:2]), axis=1)
        aims, normals = aims[keep], normals[keep]
        normals *= RNG.choice([-1.0, 1.0], size=(len(normals), 1))
    targets = np.concatenate([RNG.uniform(lo, hi, size=(n_random, 3)), aims])
    aimed = -unit(normals + 0.4 * unit(RNG.normal(size=normals.shape)))
    dirs = np.concatenate([unit(RNG.normal(size=(n_random, 3))), aimed])
    origins = targets - dirs * size * RNG.uniform(1.5, 3.0, size=(len(targets), 1))
    # The same float32 rays for Embree and for the written file.
    origins = origins.astype(np.float32)
    return origins, own_unit_f32(targets - origins)


def own_unit_f32(dirs):
    """Float32 directions, each its own float32 unit vector: normalized in float64 and
    rounded to float32 it comes back unchanged. hytrace normalizes a scan's directions in
    float64 and its f32 tracer rounds them, so on these directions Embree, hytrace's f32
    and f64 tracers and the float64 reference all trace the same ray. Most rounded unit
    vectors are their own; the others are nudged by about 1e-7 (as much as the rounding
    moves them) until they are."""
    want = unit(np.asarray(dirs, dtype=np.float64))
    d = want.astype(np.float32)
    rng = np.random.default_rng(7)
    while True:
        stuck = np.any(unit(d.astype(np.float64)).astype(np.float32) != d, axis=1)
        if not stuck.any():
            return d
        nudged = want[stuck] * (1.0 + 1e-7 * rng.normal(size=(int(stuck.sum()), 3)))
        d[stuck] = unit(nudged).astype(np.float32)


def embree_first_hits(mesh, origins, dirs):
    # Robust mode: Embree's watertight traversal and triangle test.
    scene = rtcs.EmbreeScene(robust=True)
    TriangleMesh(scene, mesh.vertices[mesh.faces].astype(np.float32))
    res = scene.run(origins, dirs, output=1)
    t = res["tfar"].astype(np.float64)
    t[res["geomID"] == -1] = np.inf
    return t


def stress_rays(mesh, n=2000):
    """`n` rays of each kind, float32: incoherent from outside the bounds (1.5 to 3 sizes
    out, at random points of the bounds) and from inside them (random directions), through
    vertices and random points of edges from random directions (from 0.2 to 2 sizes
    before them), and grazing a random point of a random triangle at 1 to 6 degrees from
    its plane (from 0.05 to 1 size before it)."""
    rng = RNG_ACC
    lo, hi = mesh.bounds
    size = float(np.max(hi - lo))
    tri = mesh.vertices[mesh.faces]
    # Outside: aimed at the bounds from afar.
    targets = [rng.uniform(lo, hi, size=(n, 3))]
    dirs = [unit(rng.normal(size=(n, 3)))]
    dist = [size * rng.uniform(1.5, 3.0, size=n)]
    # Inside: from random points of the bounds (the origin is the target, distance 0).
    targets.append(rng.uniform(lo, hi, size=(n, 3)))
    dirs.append(unit(rng.normal(size=(n, 3))))
    dist.append(np.zeros(n))
    # Vertices and points of edges, from any direction.
    half = n // 2
    edges = mesh.edges_unique[rng.integers(len(mesh.edges_unique), size=n - half)]
    w = rng.uniform(0.0, 1.0, size=(n - half, 1))
    on_edges = mesh.vertices[edges[:, 0]] * (1.0 - w) + mesh.vertices[edges[:, 1]] * w
    targets.append(np.concatenate([mesh.vertices[rng.integers(len(mesh.vertices), size=half)], on_edges]))
    dirs.append(unit(rng.normal(size=(n, 3))))
    dist.append(size * rng.uniform(0.2, 2.0, size=n))
    # Grazing: at a random point of a triangle, a direction 1 to 6 degrees off its plane,
    # entering from the front or leaving from the back.
    t = tri[rng.integers(len(tri), size=n)]
    a, b = rng.uniform(size=(n, 1)), rng.uniform(size=(n, 1))
    flip = (a + b) > 1.0
    a, b = np.where(flip, 1.0 - a, a), np.where(flip, 1.0 - b, b)
    targets.append(t[:, 0] + a * (t[:, 1] - t[:, 0]) + b * (t[:, 2] - t[:, 0]))
    normal = unit(np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0]))
    along = unit(np.cross(normal, rng.normal(size=(n, 3))))
    angle = np.radians(rng.uniform(1.0, 6.0, size=(n, 1))) * rng.choice([-1.0, 1.0], size=(n, 1))
    dirs.append(unit(along * np.cos(angle) - normal * np.sin(angle)))
    dist.append(size * rng.uniform(0.05, 1.0, size=n))
    targets, dirs, dist = np.concatenate(targets), np.concatenate(dirs), np.concatenate(dist)
    origins = (targets - dirs * dist[:, None]).astype(np.float32)
    return origins, own_unit_f32(dirs)


def exact_hit(tri, o, d):
    """The ray parameter (along `d`) of the crossing of ray `o + t d` with triangle `tri`
    in rational arithmetic, or None: the ray meets the triangle (edges and vertices
    included) when its Plucker products with the three edges are all >= 0 or all <= 0 and
    not all 0 (a ray in the triangle's plane meets none), at t > 0."""
    o = [Fraction(float(c)) for c in o]
    d = [Fraction(float(c)) for c in d]
    v = [[Fraction(float(c)) for c in p] for p in tri]

    def sub(p, q):
        return [p[0] - q[0], p[1] - q[1], p[2] - q[2]]

    def cross(p, q):
        return [p[1] * q[2] - p[2] * q[1], p[2] * q[0] - p[0] * q[2], p[0] * q[1] - p[1] * q[0]]

    def dot(p, q):
        return p[0] * q[0] + p[1] * q[1] + p[2] * q[2]

    rel = [sub(p, o) for p in v]
    s = [dot(d, cross(rel[i], rel[(i + 1) % 3])) for i in range(3)]
    if not (all(x >= 0 for x in s) or all(x <= 0 for x in s)):
        return None
    n = cross(sub(v[1], v[0]), sub(v[2], v[0]))
    dn = dot(d, n)
    if dn == 0:
        return None
    t = dot(rel[0], n) / dn
    return t if t > 0 else None


def exact_first_hits(mesh, origins, dirs, chunk=256, band=1e-9):
    """Second referee, independent of Embree: the nearest crossing of every triangle in
    float64 (Moller-Trumbore over the float32 vertices, edges inclusive). Rays whose
    answer a crossing within `band` of a triangle's edges (barycentric), or a triangle
    nearly edge-on to the ray, may decide are decided again exactly (`exact_hit`) over
    those uncertain triangles. Returns the distances along the unit directions and the
    number of rays decided exactly."""
    tri = mesh.vertices[mesh.faces]
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    out = np.full(len(origins), np.inf)
    o64, d64 = origins.astype(np.float64), dirs.astype(np.float64)
    norm = np.linalg.norm(d64, axis=1)
    area = np.linalg.norm(np.cross(e1, e2), axis=1)
    redone = 0
    candidates = []
    for a in range(0, len(origins), chunk):
        o, d = o64[a : a + chunk, None, :], d64[a : a + chunk, None, :]
        p = np.cross(d, e2)
        det = np.einsum("rtk,tk->rt", p, e1)
        with np.errstate(divide="ignore", invalid="ignore"):
            inv = 1.0 / det
            s = o - v0
            u = np.einsum("rtk,rtk->rt", s, p) * inv
            q = np.cross(s, e1)
            v = np.einsum("rtk,rtk->rt", d, q) * inv
            t = np.einsum("rtk,tk->rt", q, e2) * inv
        inner = np.minimum(np.minimum(u, v), 1.0 - u - v)
        # |det| / (|d| |e1 x e2|): the sine of the ray's angle with the triangle's plane.
        edge_on = np.abs(det) <= 1e-9 * norm[a : a + chunk, None] * area
        sure = ~edge_on & (inner > band) & (t > 0)
        best = np.where(sure, t, np.inf).min(axis=1)
        unsure = (edge_on | ((np.abs(inner) <= band) & (t > 0))) & ~sure
        # Uncertain triangles that could be crossed no farther than the sure crossing
        # (edge-on ones wherever they are).
        unsure &= edge_on | ~(t > best[:, None] * (1.0 + 1e-9))
        # Crossings within 1e-4 of an edge nearer than every crossing well inside its
        # triangle: candidates for `ill_conditioned`.
        robust = np.where((inner > 1e-4) & (t > 0), t, np.inf).min(axis=1)
        near = np.where((np.abs(inner) <= 1e-4) & (t > 0), t, np.inf).min(axis=1)
        scale = np.abs(o64[a : a + chunk]).max(axis=1) + np.where(np.isfinite(near), near, 0.0)
        candidates.append(a + np.nonzero(near < robust - 4e-7 * scale)[0])
        for r in np.nonzero(unsure.any(axis=1))[0]:
            redone += 1
            ray = a + r
            hits = [exact_hit(tri[k], origins[ray], dirs[ray]) for k in np.nonzero(unsure[r])[0]]
            hits = [float(h) for h in hits if h is not None]
            best[r] = min([best[r]] + hits)
        out[a : a + chunk] = best * norm[a : a + chunk]
    return out, redone, np.concatenate(candidates)


def ill_conditioned(mesh, origins, dirs, t, candidates, tries=8):
    """Which rays are ill-conditioned at the tests' tolerance: moving the ray (its origin
    sideways, its direction by the same angle) by `4e-7 * scale` makes its float64 first
    hit jump (from a hit to a miss or the reverse, or to another surface: by more than a
    thousand times that). Such rays pass within rounding of a silhouette edge or vertex:
    an f32 tracer's answer on them is right or wrong by the luck of its rounding. Only `candidates` (rays with a crossing near a triangle's edge
    nearer than any crossing well inside one) are tried, `tries` moves each."""
    rng = np.random.default_rng(11)
    out = np.zeros(len(origins), dtype=bool)
    if len(candidates) == 0:
        return out
    o = origins[candidates].astype(np.float64)
    d = unit(dirs[candidates].astype(np.float64))
    ref = t[candidates]
    scale = np.abs(o).max(axis=1) + np.where(np.isfinite(ref), ref, 0.0)
    tol = 4e-7 * scale
    for _ in range(tries):
        side = unit(np.cross(d, rng.normal(size=d.shape)))
        turn = unit(np.cross(d, rng.normal(size=d.shape)))
        length = np.where(np.isfinite(ref), ref, scale)
        moved_o = o + side * tol[:, None]
        moved_d = unit(d + turn * (tol / np.maximum(length, 1e-30))[:, None])
        moved, _, _ = exact_first_hits(mesh, moved_o, moved_d)
        both = np.isfinite(moved) & np.isfinite(ref)
        jump = np.abs(np.where(both, moved, 0.0) - np.where(both, ref, 0.0))
        differs = (np.isfinite(moved) != np.isfinite(ref)) | (jump > 1000.0 * tol)
        out[candidates[differs]] = True
    return out


def main(out):
    os.makedirs(out, exist_ok=True)
    geometries = cases()
    named = list(geometries.items()) + [(k, geometries[m]) for k, m in ACCURACY.items() if k != m]
    for name, geometry in named:
        geometry.export(os.path.join(out, f"{name}.obj"))
        geometry.export(os.path.join(out, f"{name}.glb"))
        mesh = geometry.to_geometry() if isinstance(geometry, trimesh.Scene) else geometry
        if name in ACCURACY:
            origins, dirs = stress_rays(mesh)
        else:
            origins, dirs = rays_for(mesh, two_sided=name == "heightfield")
        t = embree_first_hits(mesh, origins, dirs)
        # Embree's tfar is a distance along the float32 direction: rescale to the unit
        # direction the scan normalizes it to.
        t *= np.linalg.norm(dirs.astype(np.float64), axis=1)
        n = len(origins)
        rows = np.zeros((n, 8))
        rows[:, 0:3] = origins
        rows[:, 3] = 0.0
        rows[:, 4:7] = dirs
        rows[:, 7] = np.inf
        exact, redone, candidates = exact_first_hits(mesh, origins, dirs)
        ill = ill_conditioned(mesh, origins, dirs, exact, candidates)
        np.save(os.path.join(out, f"{name}_rays.npy"), rows)
        np.save(os.path.join(out, f"{name}_ill.npy"), ill.astype(np.float64))
        np.save(os.path.join(out, f"{name}_t.npy"), t)
        np.save(os.path.join(out, f"{name}_t_exact.npy"), exact)
        print(name, n, int(np.isfinite(t).sum()), redone, len(candidates), int(ill.sum()))


if __name__ == "__main__":
    main(sys.argv[1])
