"""Embree oracle of the mesh-scene tests (run in the .venv oracle environment).

Usage: mesh_oracle.py DIR

Writes, for each case, CASE.obj and CASE.glb (exported by trimesh), CASE_rays.npy (N, 8)
float64 rows `ox oy oz tmin dx dy dz tmax`, CASE_t.npy (N,) float64: Embree's first-hit
distance of each ray against the case's triangles (inf on a miss), computed with embreex
in robust mode, and CASE_t_exact.npy: the same by brute force in float64 with NumPy, the
referee where hytrace and Embree disagree (Embree's float32 test still misses a few
head-on rays at vertices and reports a few crossings no triangle has).

Cases:
  icosphere   a 3-times subdivided icosphere of radius 10 about (1, 2, 3)
  boxes       a 4 x 4 x 3 block of touching unit boxes: one box mesh placed by 48 scene
              nodes (the .glb shares the mesh between nodes; the .obj has them baked)
  far         an icosphere of radius 5 translated 1e5 away from the origin
  heightfield an open 40 x 40 random heightfield (rays from above, below and the sides)

Rays come from outside each case's bounds, aimed at random points of the bounds from random
directions, and head-on at vertices and edge midpoints (rays grazing a vertex or edge
tangentially are ill-posed: within rounding they may hit or miss, so none is aimed so). Origins and directions are rounded to float32 before both
Embree (which traces in float32) and the written rays see them, so both trace the same rays.
"""

import os
import sys

import numpy as np
import trimesh
from embreex import rtcore_scene as rtcs
from embreex.mesh_construction import TriangleMesh

RNG = np.random.default_rng(20261122)


def boxes_scene():
    scene = trimesh.Scene()
    box = trimesh.creation.box(extents=[1.0, 1.0, 1.0])
    for i in range(4):
        for j in range(4):
            for k in range(3):
                scene.add_geometry(
                    box,
                    geom_name="box",
                    node_name=f"box_{i}_{j}_{k}",
                    transform=trimesh.transformations.translation_matrix([i, j, k]),
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
    dirs = unit(targets - origins).astype(np.float32)
    return origins, dirs


def embree_first_hits(mesh, origins, dirs):
    # Robust mode: Embree's watertight traversal and triangle test.
    scene = rtcs.EmbreeScene(robust=True)
    TriangleMesh(scene, mesh.vertices[mesh.faces].astype(np.float32))
    res = scene.run(origins, dirs, output=1)
    t = res["tfar"].astype(np.float64)
    t[res["geomID"] == -1] = np.inf
    return t


def exact_first_hits(mesh, origins, dirs, chunk=256):
    """Second referee, independent of Embree: the nearest crossing of every triangle in
    float64 (Moller-Trumbore over the float32 vertices, edges inclusive to 1e-12)."""
    tri = mesh.vertices[mesh.faces]
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    out = np.full(len(origins), np.inf)
    o64, d64 = origins.astype(np.float64), unit(dirs.astype(np.float64))
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
        eps = 1e-12
        ok = (det != 0) & (u >= -eps) & (v >= -eps) & (u + v <= 1 + eps) & (t > 0)
        out[a : a + chunk] = np.where(ok, t, np.inf).min(axis=1)
    return out


def main(out):
    os.makedirs(out, exist_ok=True)
    for name, geometry in cases().items():
        geometry.export(os.path.join(out, f"{name}.obj"))
        geometry.export(os.path.join(out, f"{name}.glb"))
        mesh = geometry.to_geometry() if isinstance(geometry, trimesh.Scene) else geometry
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
        np.save(os.path.join(out, f"{name}_rays.npy"), rows)
        np.save(os.path.join(out, f"{name}_t.npy"), t)
        np.save(os.path.join(out, f"{name}_t_exact.npy"), exact_first_hits(mesh, origins, dirs))
        print(name, n, int(np.isfinite(t).sum()))


if __name__ == "__main__":
    main(sys.argv[1])
