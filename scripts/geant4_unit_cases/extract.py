#!/usr/bin/env python3
"""Regenerates tests/data/geant4_unit_cases.json from Geant4's solid unit tests.

Geant4's repository history holds the testG4*.cc files of its solids (CSG, specific and
Boolean ``test`` directories, deleted from later releases). Each test constructs solids
and asks DistanceToIn / DistanceToOut from hand-picked points along hand-picked
directions. This script takes the last version of every such file from a git clone of
github.com/Geant4/geant4, compiles it against ``stand_ins.hh`` (recording stand-ins for
the Geant4 classes, no Geant4 needed) and runs it: the solids' parameters and the
queries' points and directions are recorded (the facts; none of Geant4's code is kept),
then gathered per test into the case file the oracle (``geant4_oracle.py --cases``)
answers and ``tests/tests/geant4_unit_families.rs`` checks.

Usage::

    extract.py GEANT4_GIT_DIR [OUT_JSON]

Queries whose point or direction came from an earlier answer or from
GetPointOnSurface (which the stand-ins cannot know) are dropped: non-finite values or a
zero direction. Loops over random points keep their first 40 distinct queries per
solid. Directions are normalised in f64. Solids the case file does not describe are
left out with their queries: twisted solids, G4ReflectedSolid and G4DisplacedSolid
(also as boolean operands).
"""

import glob
import json
import math
import os
import subprocess
import sys
import tempfile

HERE = os.path.dirname(os.path.abspath(__file__))
AREAS = ("CSG", "specific", "Boolean")
SKIP = ("Twisted", "Reflected", "Displaced", "Tess_")
PER_SOLID = 40
# Headers the tests include; each becomes a shim including the stand-ins.
HEADERS = """globals G4ThreeVector geomdefs G4VoxelLimits G4RotationMatrix G4AffineTransform
G4SystemOfUnits G4PhysicalConstants ApproxEqual G4GeometryTolerance G4ios G4Box G4Sphere
G4Para G4Cons G4Tubs G4Trd G4Trap G4Torus G4UnionSolid G4Timer G4Vector3D G4Point3D
G4IntersectionSolid G4DisplacedSolid Randomize G4SubtractionSolid G4TwoVector
G4Transform3D G4Polycone G4Orb G4Hype G4Ellipsoid G4Tet G4Polyhedra G4Paraboloid
G4EllipticalTube G4EllipticalCone G4ExtrudedSolid G4GenericTrap G4VSolid G4Normal3D
G4ReflectedSolid G4TessellatedSolid G4TriangularFacet G4QuadrangularFacet G4Polyhedron
G4VFacet""".split()
ABOUT = (
    "Start points and directions of the ray queries (DistanceToIn(p, v), "
    "DistanceToOut(p, v)) of Geant4's own solid unit tests, the testG4*.cc files that "
    "Geant4's repository history holds (source: path@commit of github.com/Geant4/geant4), "
    "with their solids' parameters (mm, rad, Geant4's half-lengths; the JSON solid form of "
    "tests/oracle/geant4_oracle.py). Collected by scripts/geant4_unit_cases/extract.py, "
    "which runs each test against recording stand-ins for the Geant4 classes: queries from "
    "loops over random points are kept up to 40 per solid, duplicates dropped, queries "
    "whose point or direction the stand-ins could not know (answers of earlier queries, "
    "GetPointOnSurface) dropped. rays: [solid index, ox, oy, oz, dx, dy, dz], directions "
    "normalised in f64. Twisted solids, G4DisplacedSolid and G4ReflectedSolid operands "
    "and G4Tet (no ray query) are left out.")


def git(repo, *args):
    return subprocess.check_output(["git", "-C", repo] + list(args), text=True)


def test_sources(repo):
    """(area, name, path, commit) of the last version of every solid test."""
    paths = set()
    for area in AREAS:
        log = git(repo, "log", "--all", "--format=", "--name-only", "--",
                  "source/geometry/solids/%s/test" % area)
        paths |= {p for p in log.split() if p.endswith(".cc")
                  and os.path.basename(p).startswith("testG4")}
    for path in sorted(paths):
        name = os.path.basename(path)[:-3]
        if any(s in path for s in SKIP):
            continue
        commit = git(repo, "log", "--all", "-1", "--format=%H", "--diff-filter=AM",
                     "--", path).strip()
        yield path.split("/")[3], name, path, commit


def record(repo, path, commit, work):
    """The stand-ins' JSON lines for one test."""
    inc = os.path.join(work, "inc")
    if not os.path.isdir(inc):
        os.makedirs(os.path.join(inc, "g4std"))
        for h in HEADERS:
            with open(os.path.join(inc, h + ".hh"), "w") as fh:
                fh.write('#include "stand_ins.hh"\n')
        with open(os.path.join(inc, "g4std", "fstream"), "w") as fh:
            fh.write('#include "stand_ins.hh"\n')
        for h in ("assert.h", "cassert"):  # assertions evaluate, never abort
            with open(os.path.join(inc, h), "w") as fh:
                fh.write("#undef assert\n#define assert(x) ((void)(x))\n")
    src = os.path.join(work, "test.cc")
    with open(src, "w") as fh:
        fh.write(git(repo, "show", "%s:%s" % (commit, path)))
    exe, out = os.path.join(work, "test"), os.path.join(work, "out.jsonl")
    subprocess.check_call(["g++", "-std=c++17", "-w", "-I", HERE, "-I", inc, "-include",
                           os.path.join(HERE, "stand_ins.hh"), src, "-o", exe])
    subprocess.call([exe], env=dict(os.environ, MOCK_OUT=out),
                    stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, timeout=60)
    lines = []
    with open(out) as fh:
        for line in fh:
            try:
                lines.append(json.loads(line))
            except ValueError:  # a NaN the stand-ins printed
                pass
    return lines


def family(lines):
    """(solids, rays) of one test's recorded lines."""
    specs = {d["solid"]: d["spec"] for d in lines if "spec" in d}

    def resolve(s):
        if s.get("type") in ("union", "subtraction", "intersection"):
            a, b = resolve(specs[s["a"]]), resolve(specs[s["b"]])
            return None if a is None or b is None else dict(s, a=a, b=b)
        return None if s.get("type") == "displaced" else s

    solids, index, rays, seen, per = [], {}, [], set(), {}
    for d in lines:
        if d.get("call") not in ("in", "out"):
            continue
        spec = resolve(specs[d["solid"]])
        p, v = d["p"], d["v"]
        if spec is None or any(x is None for x in p + v):
            continue
        n = math.sqrt(sum(x * x for x in v))
        if not n > 0.0 or not all(abs(x) < 1e7 for x in p):
            continue
        v = [x / n for x in v]
        key = json.dumps(spec, sort_keys=True)
        if key not in index:
            index[key] = len(solids)
            solids.append(spec)
        k = index[key]
        if (k, tuple(p), tuple(v)) in seen or per.get(k, 0) >= PER_SOLID:
            continue
        seen.add((k, tuple(p), tuple(v)))
        per[k] = per.get(k, 0) + 1
        rays.append([k] + [float(x) for x in p] + v)
    return solids, rays


def main():
    repo = sys.argv[1]
    out = sys.argv[2] if len(sys.argv) > 2 else os.path.join(
        HERE, "..", "..", "tests", "data", "geant4_unit_cases.json")
    fams = []
    with tempfile.TemporaryDirectory() as work:
        for area, name, path, commit in test_sources(repo):
            solids, rays = family(record(repo, path, commit, work))
            if not rays:
                continue
            if area == "CSG" and name in ("testG4Hype", "testG4Polycone"):
                name += " (CSG)"  # older twins of the specific/ tests
            fams.append({"family": name, "source": "%s@%s" % (path, commit),
                         "solids": solids, "rays": rays})
    lines = ['{"format": "hytrace-geant4-unit-cases", "version": 1,',
             ' "about": %s,' % json.dumps(ABOUT), ' "families": [']
    for i, f in enumerate(fams):
        lines.append('  {"family": %s, "source": %s,'
                     % (json.dumps(f["family"]), json.dumps(f["source"])))
        lines.append('   "solids": [')
        lines.append(",\n".join("    " + json.dumps(s) for s in f["solids"]))
        lines.append("   ],")
        lines.append('   "rays": [')
        lines.append(",\n".join("    " + json.dumps(r) for r in f["rays"]))
        lines.append("   ]}" + ("," if i + 1 < len(fams) else ""))
    lines.append(" ]}")
    with open(out, "w") as fh:
        fh.write("\n".join(lines) + "\n")
    sys.stderr.write("%d families, %d rays\n"
                     % (len(fams), sum(len(f["rays"]) for f in fams)))


if __name__ == "__main__":
    main()
