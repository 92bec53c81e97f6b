#!/usr/bin/env python3
"""Geant4 navigation oracle for the hytrace GDML importer.

Purpose
-------
Reads a GDML file with Geant4 (``geant4_pybind``), shoots rays from points
spread over every volume of the geometry and records what Geant4's
``G4Navigator`` answers: the physical volume (touchable) containing each
origin, its global transform, and the distance along the ray to the next
volume boundary.  The Rust tests import the same GDML file, trace the same
rays and compare.  Two more subcommands list every placement with its
global transform, and write a small GDML file from a geometry built in
Python (to test files written by Geant4 itself).

Command line::

    gdml_navigator.py sample GDML --out DIR [--rays N] [--seed S]
    gdml_navigator.py placements GDML [--check-overlaps RES]
    gdml_navigator.py roundtrip OUTDIR
    gdml_navigator.py adjudicate GDML --rays R.npy --answers T.npy --steps S.npy

Run it with ``GEANT4_DATA_DIR`` pointing to an existing (possibly empty)
directory; when it is unset the script points it to an empty temporary one,
since geant4_pybind would otherwise try to download the Geant4 data sets
(the geometry needs none of them).  GDML files are read without schema
validation (``G4GDMLParser.Read(path, False)``, no network) and with
Geant4's default name stripping: every name is the one Geant4 reports,
i.e. without the ``0x...`` pointer suffix that ``Write`` appends.
Geant4's own output (G4cout / G4cerr, e.g. G4Exception warnings) never goes
to stdout: ``sample`` writes it to ``DIR/geant4.log``, the other
subcommands to stderr.  stdout carries exactly one JSON document.

Conventions
-----------
* Units: mm and radians.
* A transform is a pair (R, t), R a 3x3 matrix written row major (9
  numbers), acting on column vectors: ``p_outer = R p_inner + t``.  A
  "global" transform maps the local frame of a volume (the frame its solid
  is defined in) to the world frame.  R is always a proper rotation
  (det +1): Geant4 turns GDML reflections (``<scale>`` with a negative
  determinant) into proper placements of reflected solids (see
  "Reflections" below).
* The placement of a daughter in its mother is
  ``(R_obj, t) = (GetObjectRotationValue(), GetObjectTranslation())`` of the
  G4PVPlacement; global transforms compose as ``R_g = R_mother R_obj``,
  ``t_g = R_mother t + t_mother``.  ``G4TouchableHistory::GetRotation()``
  is the *inverse* (frame) rotation, so the touchable's global transform is
  ``(GetRotation()^T, GetTranslation())``.  Checked at run time: every new
  touchable's transform maps its located ray origin to the point that
  ``G4Navigator::GetGlobalToLocalTransform()`` gives (``local_err`` in the
  summary), and the transform composed from the placements agrees with the
  touchable's whenever a sampled point lands in the volume it was sampled
  for (``convention_check``).  (The G4AffineTransform of the navigator
  stores the transpose of the column-vector matrix as well.)
* index paths: a volume is identified without ambiguity by the list of
  ``[i, copy]`` pairs from the world down, ``i`` the position of the
  physical volume in its mother logical volume's daughter list (GDML
  ``<physvol>`` / replica / division / paramvol order, as Geant4 keeps it)
  and ``copy`` its copy number (``GetCopyNo`` of a placement, the replica
  or parameterisation copy index of replicated volumes).  Name paths are
  also given, but names need not be unique (e.g. geant4/scale.gdml places
  several volumes with the same name and copy number in one mother).

Reflections
-----------
A physvol with ``<scale>`` of negative determinant goes through
G4ReflectionFactory: the placed logical volume is replaced by a reflected
copy named ``<lv>_refl`` whose solid is a G4ReflectedSolid (named
``<solid>_refl``) holding the original solid under a z reflection, the
placement keeps only the proper rotation, and the whole daughter subtree
is reflected the same way.  Wherever the solid of an entry is a
G4ReflectedSolid, the entry gets ``"reflection"``::

    {"constituent": NAME, "constituent_type": TYPE,
     "rotation": [9], "translation": [3],           # solid-local
     "global_rotation": [9], "global_translation": [3]}

where ``rotation`` / ``translation`` map the constituent's frame into the
reflected solid's frame (det -1, in practice diag(1, 1, -1)), and
``global_*`` is the composition with the volume's global transform, i.e.
``p_world = global_rotation p_constituent + global_translation``.

sample
------
``sample GDML --out DIR [--rays N (10000)] [--seed S (1)]`` writes

* ``DIR/rays.npy``: float64 (N, 8), rows ``ox oy oz 0 dx dy dz inf``.
  Origins are float32-representable (rounded before Geant4 sees them);
  directions are unit to double precision, 15% exactly along +-x, +-y or
  +-z (the other components exactly 0), the rest isotropic.
* ``DIR/steps.npy``: float64 (N,): ``G4Navigator::ComputeStep(o, d, 1e30)``
  right after ``LocateGlobalPointAndSetup(o, d, relativeSearch=False,
  ignoreDirection=False)`` at the origin (a fresh, non-relative locate per
  ray, which resets the navigator's stack and state).  +inf if no boundary
  was found (step >= 1e29; never seen).
* ``DIR/located.json``::

    {"format": "hytrace-gdml-located", "version": 1, "geant4": VERSION,
     "gdml": PATH, "seed": S, "rays": N,
     "touchables": [
        {"name": PV_NAME, "copy": INT, "depth": INT,
         "logical": LV_NAME, "solid": SOLID_NAME, "solid_type": TYPE,
         "path": [[PV_NAME, COPY], ...],       # world first, len depth+1
         "index_path": [[I, COPY], ...],       # below the world, len depth
         "rotation": [9], "translation": [3],  # global transform
         ("reflection": {...} for reflected solids, see above)}, ...],
     "ray_touchable": [INT] * N,   # index into touchables of each origin
     "ray_source": [INT] * N}      # 0 box, 1 walk, 2 per-logical
                                   # volume, 3 near-surface (see below)

  ``depth`` is the touchable's history depth (world = 0); ``copy`` is
  ``GetReplicaNumber(0)`` of the touchable (= ``GetCopyNo`` for a
  placement).  For parameterised volumes ``solid`` / ``solid_type`` are
  those of the copy (``ComputeSolid``); their dimensions are not written.
* ``DIR/geant4.log``: Geant4's output.
* stdout, one JSON line: ``rays, seconds, in_world`` (origins located in
  the world volume itself), ``distinct_volumes`` (distinct physical
  volumes located), ``distinct_touchables``, ``distinct_logical``,
  ``pv_total`` / ``lv_total`` (physical / logical volumes in the tree,
  replicated ones counted once), ``resampled`` (candidate origins
  rejected: outside the world or within 1e-6 mm of a surface),
  ``inf_steps``, ``g4_warnings`` (G4Exception reports in the log),
  ``local_err`` (max |R^T (o - t) - navigator local point|, mm),
  ``convention_check`` ({compared, max_rotation_err,
  max_translation_err}).

Origins come from three sources (fractions 0.25 / 0.375 / 0.375):

* box (ray_source 0): uniform in the world's bounding box clipped to the
  bounding box of the world's daughters (so a small detector in a huge
  world still gets points near it);
* walk (1): start at the world, at each level stop with probability 0.25
  (never at the world, always at a leaf), else pick a daughter -- half of
  the time uniformly, half of the time a uniformly chosen daughter logical
  volume first and then one of its placements -- and sample uniformly in
  the local bounding box (``G4VSolid::BoundingLimits``) of the volume
  where the walk stopped, mapped to the world;
* per logical volume (2, 3): a uniformly chosen logical volume below the
  world, one of its placements (up to 64 per logical volume are
  remembered), then either (2) a point uniform in its bounding box,
  retried up to 16 times until it is inside the solid (thin shells), or,
  a quarter of the time, (3) a point off the solid's surface
  (``GetPointOnSurface``, moved along ``SurfaceNormal`` inwards or
  outwards by 1e-4 .. 1 mm, log-uniform).  Source 3 origins are close to
  a boundary on purpose: expect the first step to be short.

Parameterised volumes and divisions are entered at a random copy
(``ComputeTransformation`` / ``ComputeSolid`` / ``ComputeDimensions`` of
their parameterisation); G4PVReplica daughters are never entered (their
replication data are not readable from Python; the replicas fill their
mother, whose box covers them).  Candidates are resampled (same source,
same direction) when they are outside the world, when the step is below
1e-6 mm, or when ``ComputeSafety`` is below 1e-6 mm and moving the point
by 1e-6 mm along +-x, +-y or +-z changes the located touchable (the
second test is needed because G4MultiUnion and G4Paraboloid answer a
safety of exactly 0 far from their surface).  Deterministic for a given
seed (``numpy.random.default_rng(S)``; ``GetPointOnSurface`` uses
Geant4's engine, which starts from the same state in every process).

placements
----------
``placements GDML [--check-overlaps RES]`` prints one JSON document::

    {"format": "hytrace-gdml-placements", "version": 1, "geant4": VERSION,
     "gdml": PATH, "count": N, "seconds": S,
     "placements": [
        {"path": [PV_NAME, ...], "index_path": [I, ...], "depth": INT,
         "name": PV_NAME, "copy": INT or null, "kind": KIND,
         "multiplicity": INT, "logical": LV_NAME, "solid": SOLID_NAME,
         "solid_type": TYPE, "rotation": [9] or null,
         "translation": [3] or null, ("reflection": {...}),
         ("overlaps": BOOL)}, ...]}

in depth-first GDML order, the world first (kind "world", identity).
KIND is "placement", "replica" (G4PVReplica), "division" (G4PVDivision)
or "parameterised".  Replicated entries (the last three) are listed once,
with ``copy`` / ``rotation`` / ``translation`` null, ``solid`` that of
the logical volume, and are not descended into.  ``--check-overlaps RES``
runs ``G4VPhysicalVolume::CheckOverlaps(RES, 0, verbose)`` on every
placement (reports on stderr) and adds ``overlaps``.

roundtrip
---------
``roundtrip OUTDIR`` builds a geometry in Python (a G4Box world holding a
G4Tubs with a phi segment, G4Cons, G4Sphere with a theta range,
G4Polycone, G4Polyhedra, G4Trd, G4Trap, G4Torus, a G4UnionSolid and a
G4SubtractionSolid whose second solid is rotated about two axes and
translated, a holder box rotated about two axes containing four copies
(copy numbers 10..13, rotated) of one logical volume, one of which holds a
nested daughter), writes it with ``G4GDMLParser.Write(OUTDIR/roundtrip.gdml,
world, True)`` (names get ``0x...`` suffixes; an existing file is
replaced), reads the file back in a child process (``placements``; in
the same process G4GDMLParser would return the already built world, as
it looks the world logical volume up by its stripped name in the global
store) and compares every placement (names, copy numbers, solid types,
global transforms) with the built geometry.  stdout: ``{"path": PATH, "placements": N,
"max_transform_err": E, "verified": BOOL, "seconds": S}``; exit status 1
when the check fails.

Geant4 quirks seen
------------------
* The geometry must be closed (``G4GeometryManager.CloseGeometry``, which
  builds the voxels) before navigating parameterised volumes; this script
  always closes it (as a Geant4 run does) and opens it again at the end
  (otherwise Geant4 warns at exit that stores are deleted while closed).
* geant4_pybind 0.1.3 binds ``GetReplicationData`` with its reference
  arguments as inputs (unusable), the ``const double*`` arrays of
  G4Polycone / G4Polyhedra as single floats (these two solids are built
  for ``roundtrip`` by reading a small generated GDML file), and returns
  physical volumes mostly as G4VPhysicalVolume (use ``IsReplicated``,
  ``VolumeType`` and ``GetParameterisation`` to tell the kinds apart).
  ``GetCopyNo`` of a G4PVReplica is uninitialised memory.
* Geant4 objects created from Python are kept referenced until the
  process ends; the process leaves through ``os._exit`` after flushing its
  output, so that no Geant4 destructor runs at interpreter shutdown (the
  binding crashes there for some solids).
"""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import time
import traceback

import numpy as np

FORMAT_LOCATED = "hytrace-gdml-located"
FORMAT_PLACEMENTS = "hytrace-gdml-placements"
VERSION = 1

SURFACE_SAFETY = 1e-6      # mm; origins closer to a surface are resampled
PROPOSED_STEP = 1e30       # mm; ComputeStep's proposed step length
NO_BOUNDARY = 1e29         # steps at least this long are recorded as inf
FRACTION_BOX = 0.25        # origins uniform in the (clipped) world box
FRACTION_WALK = 0.375      # origins from random walks down the tree
                           # (the rest: per logical volume, see module doc)
FRACTION_AXIS = 0.15       # directions exactly along +-x, +-y, +-z
P_STOP = 0.25              # walk: probability to stop below the world
P_BY_LOGICAL = 0.5         # walk: pick a daughter logical volume first
MAX_ROUNDS = 60            # resampling rounds before falling back to box
NODES_PER_LOGICAL = 64     # placements remembered per logical volume
INSIDE_TRIES = 16          # per-logical source: tries to land inside solid
P_NEAR_SURFACE = 0.25      # per-logical source: near-surface fraction
NEAR_SURFACE_LOG10 = (-4.0, 0.0)   # near-surface offsets 1e-4 .. 1 mm
SOURCE_BOX, SOURCE_WALK, SOURCE_LOGICAL, SOURCE_SURFACE = 0, 1, 2, 3


# ---------------------------------------------------------------------------
# Geant4 session: output capture, environment
# ---------------------------------------------------------------------------

class _G4Sink:
    """Stands in for sys.stdout / sys.stderr while Geant4 is active
    (geant4_pybind writes G4cout / G4cerr through them): everything goes to
    ``target``; G4Exception reports are counted, and fatal ones (Geant4
    aborts the process right after them) are also copied to ``echo``."""

    def __init__(self, target, counter, echo=None):
        self.target = target
        self.counter = counter
        self.echo = echo
        self.block = None       # text of the G4Exception report being read
        self.echoing = False

    def write(self, s):
        if "G4Exception-START" in s:
            self.counter[0] += 1
            self.block = []
        if self.block is not None:
            self.block.append(s)
            if self.echo is not None:
                if self.echoing:
                    self.echo.write(s)
                elif "Fatal" in s or "Abort" in s:
                    self.echo.write("".join(self.block))
                    self.echoing = True
                self.echo.flush()
            if "G4Exception-END" in s:
                self.block = None
                self.echoing = False
        self.target.write(s)
        self.target.flush()
        return len(s)

    def flush(self):
        self.target.flush()

    def isatty(self):
        return False


class Session:
    """Imports geant4_pybind with its output redirected to ``log``."""

    def __init__(self, log):
        self.real_out, self.real_err = sys.stdout, sys.stderr
        self.tmp = tempfile.TemporaryDirectory(prefix="hytrace_gdml_")
        if not os.environ.get("GEANT4_DATA_DIR"):
            # geant4_pybind would otherwise try to download its data sets;
            # the geometry needs none of them.
            data_dir = os.path.join(self.tmp.name, "g4data")
            os.makedirs(data_dir, exist_ok=True)
            os.environ["GEANT4_DATA_DIR"] = data_dir
        self.counter = [0]
        sink = _G4Sink(log, self.counter,
                       None if log is self.real_err else self.real_err)
        sys.stdout, sys.stderr = sink, sink
        import geant4_pybind
        self.g4 = geant4_pybind
        self.keep = []    # Geant4 objects that must outlive their use
        self.closed = False

    def version(self):
        return str(getattr(self.g4, "G4Version", "")).strip("$ ").replace(
            "Name: ", "")

    def read(self, path):
        parser = self.g4.G4GDMLParser()
        parser.Read(path, False)
        self.keep.append(parser)
        world = parser.GetWorldVolume()
        if world is None:
            raise RuntimeError("no world volume in %s" % path)
        return world

    def close_geometry(self):
        self.g4.G4GeometryManager.GetInstance().CloseGeometry(True, False)
        self.closed = True

    def end(self):
        if self.closed:
            self.g4.G4GeometryManager.GetInstance().OpenGeometry()
            self.closed = False
        sys.stdout.flush()
        sys.stdout, sys.stderr = self.real_out, self.real_err
        self.tmp.cleanup()


# ---------------------------------------------------------------------------
# Small conversions
# ---------------------------------------------------------------------------

def np3(v):
    return np.array([v.x, v.y, v.z], dtype=np.float64)


def rot_np(r):
    """CLHEP rotation -> 3x3 numpy matrix acting on column vectors."""
    return np.array([[r.xx, r.xy, r.xz],
                     [r.yx, r.yy, r.yz],
                     [r.zx, r.zy, r.zz]], dtype=np.float64)


def tf_np(t):
    """G4Transform3D -> (3x3, 3): p' = M p + d."""
    return (np.array([[t.xx, t.xy, t.xz],
                      [t.yx, t.yy, t.yz],
                      [t.zx, t.zy, t.zz]], dtype=np.float64),
            np.array([t.dx, t.dy, t.dz], dtype=np.float64))


def flat(a):
    return [float(x) for x in np.asarray(a, dtype=np.float64).ravel()]


def bounding_limits(g4, solid):
    lo, hi = g4.G4ThreeVector(), g4.G4ThreeVector()
    solid.BoundingLimits(lo, hi)
    return np3(lo), np3(hi)


def global_aabb(R, t, lo, hi):
    c = 0.5 * (lo + hi)
    h = 0.5 * (hi - lo)
    gc = R @ c + t
    gh = np.abs(R) @ h
    return gc - gh, gc + gh


def solid_info(g4, solid, R=None, t=None):
    """name/type of a solid, plus the reflection record for reflected ones
    (global part only when the volume's global transform R, t is given)."""
    d = {"solid": solid.GetName(), "solid_type": solid.GetEntityType()}
    if d["solid_type"] == "G4ReflectedSolid":
        M, m = tf_np(solid.GetDirectTransform3D())
        c = solid.GetConstituentMovedSolid()
        ref = {"constituent": c.GetName(),
               "constituent_type": c.GetEntityType(),
               "rotation": flat(M), "translation": flat(m)}
        if R is not None:
            ref["global_rotation"] = flat(R @ M)
            ref["global_translation"] = flat(R @ m + t)
        d["reflection"] = ref
    return d


def volume_kind(pv):
    if not pv.IsReplicated():
        return "placement"
    par = pv.GetParameterisation()
    if par is None:
        return "replica"
    if type(par).__name__.startswith("G4Parameterisation"):
        return "division"
    return "parameterised"


# ---------------------------------------------------------------------------
# Geometry tree (cached per logical volume)
# ---------------------------------------------------------------------------

class Daughter:
    __slots__ = ("index", "pv", "lv", "kind", "R", "t", "mult", "par")


class Tree:
    def __init__(self, g4, world):
        self.g4 = g4
        self.world = world
        self._kids = {}       # lv instance id -> [Daughter]
        self._groups = {}     # lv instance id -> [[Daughter]] by daughter lv
        self.pv_index = {}    # pv instance id -> index in its mother
        self.pv_ids, self.lv_ids = set(), set()
        self._count(world)

    def _count(self, pv):
        self.pv_ids.add(pv.GetInstanceID())
        lv = pv.GetLogicalVolume()
        new_lv = lv.GetInstanceID() not in self.lv_ids
        self.lv_ids.add(lv.GetInstanceID())
        if new_lv:
            for d in self.kids(lv):
                self._count(d.pv)

    def kids(self, lv):
        key = lv.GetInstanceID()
        out = self._kids.get(key)
        if out is not None:
            return out
        out = []
        groups = {}
        for i in range(lv.GetNoDaughters()):
            pv = lv.GetDaughter(i)
            d = Daughter()
            d.index, d.pv, d.lv = i, pv, pv.GetLogicalVolume()
            d.kind = volume_kind(pv)
            d.mult = pv.GetMultiplicity()
            d.par = pv.GetParameterisation() if pv.IsReplicated() else None
            if d.kind == "placement":
                d.R = rot_np(pv.GetObjectRotationValue())
                d.t = np3(pv.GetObjectTranslation())
            else:
                d.R, d.t = None, None
            self.pv_index[pv.GetInstanceID()] = i
            out.append(d)
            groups.setdefault(d.lv.GetInstanceID(), []).append(d)
        self._kids[key] = out
        self._groups[key] = list(groups.values())
        return out

    def groups(self, lv):
        self.kids(lv)
        return self._groups[lv.GetInstanceID()]

    def copy_frame(self, d, copy):
        """(R, t, lo, hi) of copy ``copy`` of a parameterised / division
        daughter, or None when it cannot be computed."""
        par = d.par
        try:
            par.ComputeTransformation(int(copy), d.pv)
            solid = par.ComputeSolid(int(copy), d.pv)
            try:
                par.ComputeDimensions(solid, int(copy), d.pv)
            except TypeError:
                pass   # solid type without a ComputeDimensions overload
            R = rot_np(d.pv.GetObjectRotationValue())
            t = np3(d.pv.GetObjectTranslation())
            lo, hi = bounding_limits(self.g4, solid)
        except Exception:
            return None
        return R, t, lo, hi


# ---------------------------------------------------------------------------
# sample
# ---------------------------------------------------------------------------

class Walker:
    """Random walks down the tree; frames cached by index path."""

    def __init__(self, g4, tree):
        self.g4 = g4
        self.tree = tree
        wl = tree.world.GetLogicalVolume()
        self.world_box = bounding_limits(g4, wl.GetSolid())
        self._frame_of = {(): (np.eye(3), np.zeros(3), wl,
                               self.world_box[0], self.world_box[1])}

    def content_box(self):
        """World box clipped to the global box of the world's daughters."""
        wl = self.tree.world.GetLogicalVolume()
        wlo, whi = self.world_box
        kids = self.tree.kids(wl)
        if not kids:
            return wlo, whi
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        for d in kids:
            if d.kind != "placement":
                return wlo, whi
            dlo, dhi = bounding_limits(self.g4, d.lv.GetSolid())
            glo, ghi = global_aabb(d.R, d.t, dlo, dhi)
            lo = np.minimum(lo, glo)
            hi = np.maximum(hi, ghi)
        lo = np.maximum(lo, wlo)
        hi = np.minimum(hi, whi)
        if np.any(hi <= lo):
            return wlo, whi
        return lo, hi

    def _child(self, key, parent, d, copy):
        """Frame of daughter ``d`` (copy ``copy``) of the frame ``parent``."""
        ck = key + ((d.index, int(copy)),)
        f = self._frame_of.get(ck)
        if f is not None:
            return ck, f
        R0, t0 = parent[0], parent[1]
        if d.kind == "placement":
            lo, hi = bounding_limits(self.g4, d.lv.GetSolid())
            R, t = d.R, d.t
        else:
            got = self.tree.copy_frame(d, copy)
            if got is None:
                return None, None
            R, t, lo, hi = got
        f = (R0 @ R, R0 @ t + t0, d.lv, lo, hi)
        self._frame_of[ck] = f
        return ck, f

    def enumerate_logical(self):
        """Remembers up to NODES_PER_LOGICAL placements of every logical
        volume below the world (depth first; a volume placed more often
        than that is not descended into again), as (parent index path,
        daughter) pairs; G4PVReplica daughters are left out (their mother
        covers them)."""
        self.by_lv = {}
        seen = {}

        def visit(key, lv):
            for d in self.tree.kids(lv):
                if d.kind == "replica":
                    continue
                lid = d.lv.GetInstanceID()
                n = seen.get(lid, 0)
                seen[lid] = n + 1
                if n >= NODES_PER_LOGICAL:
                    continue
                self.by_lv.setdefault(lid, []).append((key, d))
                if d.kind == "placement":
                    ck, f = self._child(key, self._frame_of[key], d,
                                        d.pv.GetCopyNo())
                    visit(ck, f[2])
                elif self.tree.kids(d.lv):
                    copy = 0
                    ck, f = self._child(key, self._frame_of[key], d, copy)
                    if f is not None:
                        visit(ck, f[2])

        visit((), self.tree.world.GetLogicalVolume())
        self.lv_order = list(self.by_lv.keys())

    def pick_logical(self, rng, u):
        """A point from a uniformly chosen logical volume (then one of its
        remembered placements, then a random copy of a parameterised one):
        uniform in the local bounding box, preferring points inside the
        solid (up to INSIDE_TRIES tries, placements only).  Returns
        (index path, R, t, global point, source) or None."""
        if not self.lv_order:
            return None
        lid = self.lv_order[int(rng.integers(len(self.lv_order)))]
        nodes = self.by_lv[lid]
        key, d = nodes[int(rng.integers(len(nodes)))]
        if d.kind == "placement":
            copy = d.pv.GetCopyNo()
        else:
            copy = int(rng.integers(max(d.mult, 1)))
        ck, f = self._child(key, self._frame_of[key], d, copy)
        if f is None:
            return None
        R, t, lv, lo, hi = f
        q = lo + (hi - lo) * u
        if d.kind == "placement" and rng.random() < P_NEAR_SURFACE:
            near = self._near_surface_point(lv.GetSolid(), rng)
            if near is not None:
                return ck, R, t, R @ near + t, SOURCE_SURFACE
        if d.kind == "placement":
            solid = lv.GetSolid()
            g4 = self.g4
            inside = g4.EInside.kInside
            for _ in range(INSIDE_TRIES - 1):
                if solid.Inside(g4.G4ThreeVector(q[0], q[1], q[2])) == inside:
                    break
                q = lo + (hi - lo) * rng.random(3)
        return ck, R, t, R @ q + t, SOURCE_LOGICAL

    def _near_surface_point(self, solid, rng):
        """A point off the surface of ``solid`` along its normal, inwards or
        outwards, at a log-uniform distance in 10^NEAR_SURFACE_LOG10 mm
        (GetPointOnSurface draws from Geant4's own random engine, which
        starts from the same state in every process)."""
        try:
            p = solid.GetPointOnSurface()
            n = np3(solid.SurfaceNormal(p))
        except Exception:
            return None
        p = np3(p)
        if not (np.all(np.isfinite(p)) and np.all(np.isfinite(n))):
            return None
        delta = 10.0 ** rng.uniform(*NEAR_SURFACE_LOG10)
        sign = 1.0 if rng.random() < 0.5 else -1.0
        return p + sign * delta * n

    def walk(self, rng):
        """Returns (index path, (R, t, lv, lo, hi)) of the chosen volume."""
        key = ()
        frame = self._frame_of[()]
        while True:
            lv = frame[2]
            kids = self.tree.kids(lv)
            if not kids:
                break
            if key and rng.random() < P_STOP:
                break
            if rng.random() < P_BY_LOGICAL:
                groups = self.tree.groups(lv)
                grp = groups[int(rng.integers(len(groups)))]
                d = grp[int(rng.integers(len(grp)))]
            else:
                d = kids[int(rng.integers(len(kids)))]
            if d.kind == "placement":
                copy = d.pv.GetCopyNo()
            elif d.kind == "replica":
                break      # replicas fill their mother: sample the mother
            else:
                copy = int(rng.integers(max(d.mult, 1)))
            ck, f = self._child(key, frame, d, copy)
            if f is None:
                break
            key, frame = ck, f
        return key, frame


def isotropic(rng, n):
    v = rng.normal(size=(n, 3))
    norm = np.linalg.norm(v, axis=1)
    bad = norm < 1e-6
    while np.any(bad):
        v[bad] = rng.normal(size=(int(bad.sum()), 3))
        norm = np.linalg.norm(v, axis=1)
        bad = norm < 1e-6
    return v / norm[:, None]


def make_directions(rng, n):
    d = isotropic(rng, n)
    axis = rng.random(n) < FRACTION_AXIS
    k = rng.integers(6, size=n)
    ax = np.zeros((n, 3))
    ax[np.arange(n), k % 3] = np.where(k < 3, 1.0, -1.0)
    d[axis] = ax[axis]
    return d


class Locator:
    """Locates points, computes steps and records touchables."""

    def __init__(self, g4, tree):
        self.g4 = g4
        self.tree = tree
        self.nav = g4.G4Navigator()
        self.nav.SetWorldVolume(tree.world)
        self.touchables = []
        self.by_key = {}
        self.local_err = 0.0
        self.pv_located = set()
        self.lv_located = set()

    def _key(self):
        th = self.nav.CreateTouchableHistory()
        depth = th.GetHistoryDepth()
        return th, depth, tuple((th.GetVolume(k).GetInstanceID(),
                                 th.GetReplicaNumber(k))
                                for k in range(depth + 1))

    def _near_surface(self, o, key):
        """True when moving o by SURFACE_SAFETY along +-x, +-y or +-z
        changes the located touchable (or leaves the world).  Used where
        ComputeSafety is below SURFACE_SAFETY, since some solids answer a
        safety of 0 far from their surface (G4MultiUnion from outside,
        G4Paraboloid)."""
        g4, nav = self.g4, self.nav
        for axis in range(3):
            for sign in (-1.0, 1.0):
                q = list(o)
                q[axis] += sign * SURFACE_SAFETY
                pv = nav.LocateGlobalPointAndSetup(
                    g4.G4ThreeVector(q[0], q[1], q[2]), None, False, True)
                if pv is None or self._key()[2] != key:
                    return True
        return False

    def trace(self, o, d):
        """(touchable index, step) for origin o and direction d, or None
        when o is outside the world or near a surface (see
        _near_surface; also when the step is below SURFACE_SAFETY)."""
        g4, nav = self.g4, self.nav
        P = g4.G4ThreeVector(o[0], o[1], o[2])
        D = g4.G4ThreeVector(d[0], d[1], d[2])
        pv = nav.LocateGlobalPointAndSetup(P, D, False, False)
        if pv is None:
            return None
        step = nav.ComputeStep(P, D, PROPOSED_STEP, 0.0)
        if step < SURFACE_SAFETY:
            return None
        th, depth, key = self._key()
        idx = self.by_key.get(key)
        rec = None
        if idx is None:
            rec = self._describe(th, depth, P, o)
        if nav.ComputeSafety(P) < SURFACE_SAFETY:
            if self._near_surface(o, key):
                return None
        if rec is not None:
            idx = self._commit(key, rec)
        if not step < NO_BOUNDARY:
            step = math.inf
        return idx, step

    def _describe(self, th, depth, P, o):
        """Record of the touchable th (navigator still located at P)."""
        g4 = self.g4
        vols = [th.GetVolume(k) for k in range(depth, -1, -1)]
        reps = [th.GetReplicaNumber(k) for k in range(depth, -1, -1)]
        path = [[v.GetName(), int(r)] for v, r in zip(vols, reps)]
        index_path = [[int(self.tree.pv_index.get(v.GetInstanceID(), -1)),
                       int(r)] for v, r in zip(vols[1:], reps[1:])]
        R = rot_np(th.GetRotation(0)).T
        t = np3(th.GetTranslation(0))
        local = np3(self.nav.GetGlobalToLocalTransform().TransformPoint(P))
        err = float(np.abs(R.T @ (np.asarray(o) - t) - local).max())
        pv = vols[-1]
        lv = pv.GetLogicalVolume()
        rec = {"name": pv.GetName(), "copy": int(reps[-1]),
               "depth": int(depth), "logical": lv.GetName()}
        rec.update(solid_info(g4, th.GetSolid(0), R, t))
        rec["path"] = path
        rec["index_path"] = index_path
        rec["rotation"] = flat(R)
        rec["translation"] = flat(t)
        # keep "reflection" (if any) after the transform, for readability
        if "reflection" in rec:
            rec["reflection"] = rec.pop("reflection")
        return rec, err, pv.GetInstanceID(), lv.GetInstanceID()

    def _commit(self, key, described):
        rec, err, pv_id, lv_id = described
        self.local_err = max(self.local_err, err)
        self.pv_located.add(pv_id)
        self.lv_located.add(lv_id)
        self.by_key[key] = len(self.touchables)
        self.touchables.append(rec)
        return self.by_key[key]


def cmd_sample(args):
    t_start = time.perf_counter()
    os.makedirs(args.out, exist_ok=True)
    log = open(os.path.join(args.out, "geant4.log"), "w")
    ses = Session(log)
    try:
        g4 = ses.g4
        world = ses.read(args.gdml)
        ses.close_geometry()
        tree = Tree(g4, world)
        walker = Walker(g4, tree)
        loc = Locator(g4, tree)
        rng = np.random.default_rng(args.seed)
        n = args.rays
        dirs = make_directions(rng, n)
        x = rng.random(n)
        source = np.where(x < FRACTION_BOX, SOURCE_BOX,
                          np.where(x < FRACTION_BOX + FRACTION_WALK,
                                   SOURCE_WALK, SOURCE_LOGICAL))
        category = source.astype(np.int64)
        source = category.copy()    # SOURCE_LOGICAL may become _SURFACE
        walker.enumerate_logical()
        box_lo, box_hi = walker.content_box()
        wbox_lo, wbox_hi = walker.world_box
        origins = np.zeros((n, 3))
        steps = np.zeros(n)
        ray_touchable = np.full(n, -1, dtype=np.int64)
        target = [None] * n          # walk: (index path, R, t) sampled for
        pending = np.arange(n)
        resampled = 0
        rounds = 0
        conv_n, conv_r, conv_t = 0, 0.0, 0.0
        while len(pending):
            rounds += 1
            fallback = rounds > MAX_ROUNDS
            if rounds > 2 * MAX_ROUNDS:
                raise RuntimeError("%d origins could not be placed"
                                   % len(pending))
            u = rng.random((len(pending), 3))
            retry = []
            for j, i in enumerate(pending):
                got = None
                if category[i] == SOURCE_LOGICAL and not fallback:
                    got = walker.pick_logical(rng, u[j])
                if got is not None:
                    p = got[3]
                    target[i] = got[:3]
                    source[i] = got[4]
                elif category[i] == SOURCE_WALK and not fallback:
                    key, (R, t, _lv, lo, hi) = walker.walk(rng)
                    p = R @ (lo + (hi - lo) * u[j]) + t
                    target[i] = (key, R, t)
                else:
                    lo, hi = ((wbox_lo, wbox_hi) if fallback
                              else (box_lo, box_hi))
                    p = lo + (hi - lo) * u[j]
                    target[i] = None
                    source[i] = SOURCE_BOX
                p = p.astype(np.float32).astype(np.float64)
                got = loc.trace(p, dirs[i])
                if got is None:
                    retry.append(i)
                    continue
                origins[i] = p
                ray_touchable[i], steps[i] = got
                if target[i] is not None:
                    rec = loc.touchables[got[0]]
                    if [tuple(x) for x in rec["index_path"]] == \
                            list(target[i][0]):
                        conv_n += 1
                        conv_r = max(conv_r, float(np.abs(
                            np.reshape(rec["rotation"], (3, 3))
                            - target[i][1]).max()))
                        conv_t = max(conv_t, float(np.abs(
                            np.asarray(rec["translation"])
                            - target[i][2]).max()))
            resampled += len(retry)
            pending = np.asarray(retry, dtype=np.int64)

        rays = np.zeros((n, 8))
        rays[:, 0:3] = origins
        rays[:, 4:7] = dirs
        rays[:, 7] = np.inf
        np.save(os.path.join(args.out, "rays.npy"), rays)
        np.save(os.path.join(args.out, "steps.npy"), steps.astype(np.float64))
        doc = {"format": FORMAT_LOCATED, "version": VERSION,
               "geant4": ses.version(), "gdml": args.gdml,
               "seed": args.seed, "rays": n,
               "touchables": loc.touchables,
               "ray_touchable": [int(x) for x in ray_touchable],
               "ray_source": [int(x) for x in source]}
        with open(os.path.join(args.out, "located.json"), "w") as fh:
            json.dump(doc, fh, separators=(",", ":"))
            fh.write("\n")
        depths = np.array([loc.touchables[k]["depth"] for k in ray_touchable])
        summary = {
            "rays": n,
            "seconds": round(time.perf_counter() - t_start, 3),
            "in_world": int(np.count_nonzero(depths == 0)),
            "distinct_volumes": len(loc.pv_located),
            "distinct_touchables": len(loc.touchables),
            "distinct_logical": len(loc.lv_located),
            "pv_total": len(tree.pv_ids),
            "lv_total": len(tree.lv_ids),
            "resampled": resampled,
            "inf_steps": int(np.count_nonzero(np.isinf(steps))),
            "local_err": loc.local_err,
            "convention_check": {"compared": conv_n,
                                 "max_rotation_err": conv_r,
                                 "max_translation_err": conv_t},
        }
    finally:
        ses.end()
        log.close()
    summary["g4_warnings"] = ses.counter[0]
    return summary


# ---------------------------------------------------------------------------
# placements
# ---------------------------------------------------------------------------

def list_placements(g4, tree, check_overlaps=0):
    out = []
    world = tree.world
    wl = world.GetLogicalVolume()
    rec = {"path": [world.GetName()], "index_path": [], "depth": 0,
           "name": world.GetName(), "copy": int(world.GetCopyNo()),
           "kind": "world", "multiplicity": 1, "logical": wl.GetName()}
    rec.update(solid_info(g4, wl.GetSolid(), np.eye(3), np.zeros(3)))
    rec["rotation"] = flat(np.eye(3))
    rec["translation"] = flat(np.zeros(3))
    if "reflection" in rec:
        rec["reflection"] = rec.pop("reflection")
    out.append(rec)

    def optics(pv, lv, mother_pv, mother_lv):
        """Materials and the optical surfaces Geant4 holds for this
        placement's surface: border surfaces of (pv, mother) both ways and the
        skin surfaces of both logical volumes (the names of their optical
        surface properties, None when absent)."""
        def name(x):
            return None if x is None else x.GetSurfaceProperty().GetName()

        def material(v):
            m = v.GetMaterial()
            return None if m is None else m.GetName()

        return {
            "material": material(lv),
            "mother_material": material(mother_lv),
            "border_out": name(g4.G4LogicalBorderSurface.GetSurface(
                pv, mother_pv)),
            "border_in": name(g4.G4LogicalBorderSurface.GetSurface(
                mother_pv, pv)),
            "skin": name(g4.G4LogicalSkinSurface.GetSurface(lv)),
            "mother_skin": name(g4.G4LogicalSkinSurface.GetSurface(mother_lv)),
        }

    def visit(lv, R0, t0, path, ipath, mother_pv):
        for d in tree.kids(lv):
            name = d.pv.GetName()
            rec = {"path": path + [name], "index_path": ipath + [d.index],
                   "depth": len(ipath) + 1, "name": name}
            rec["optics"] = optics(d.pv, d.lv, mother_pv, lv)
            if d.kind == "placement":
                R = R0 @ d.R
                t = R0 @ d.t + t0
                rec.update({"copy": int(d.pv.GetCopyNo()), "kind": d.kind,
                            "multiplicity": 1, "logical": d.lv.GetName()})
                rec.update(solid_info(g4, d.lv.GetSolid(), R, t))
                rec["rotation"] = flat(R)
                rec["translation"] = flat(t)
            else:
                rec.update({"copy": None, "kind": d.kind,
                            "multiplicity": int(d.mult),
                            "logical": d.lv.GetName()})
                rec.update(solid_info(g4, d.lv.GetSolid()))
                rec["rotation"] = None
                rec["translation"] = None
            if "reflection" in rec:
                rec["reflection"] = rec.pop("reflection")
            if check_overlaps:
                rec["overlaps"] = bool(d.pv.CheckOverlaps(
                    int(check_overlaps), 0.0, True, 1))
            out.append(rec)
            if d.kind == "placement":
                visit(d.lv, R, t, rec["path"], rec["index_path"], d.pv)

    visit(wl, np.eye(3), np.zeros(3), [world.GetName()], [], world)
    return out


def cmd_placements(args):
    t_start = time.perf_counter()
    ses = Session(sys.stderr)
    try:
        g4 = ses.g4
        world = ses.read(args.gdml)
        tree = Tree(g4, world)
        pl = list_placements(g4, tree, args.check_overlaps)
        doc = {"format": FORMAT_PLACEMENTS, "version": VERSION,
               "geant4": ses.version(), "gdml": args.gdml,
               "count": len(pl),
               "seconds": round(time.perf_counter() - t_start, 3),
               "g4_warnings": ses.counter[0], "placements": pl}
    finally:
        ses.end()
    return doc


# ---------------------------------------------------------------------------
# roundtrip
# ---------------------------------------------------------------------------

def rotation(g4, angles):
    """G4RotationMatrix = product of rotations about axes, applied in the
    given order: [("x", a), ("y", b)] -> Ry(b) Rx(a)."""
    r = g4.G4RotationMatrix()
    for axis, a in angles:
        getattr(r, "rotate" + axis.upper())(a)
    return r


def polycones_from_gdml(ses, specs):
    """Builds G4Polycone / G4Polyhedra solids by reading a generated GDML
    file (geant4_pybind cannot pass their z/r arrays), returns them."""
    g4 = ses.g4
    body = []
    for spec in specs:
        kind = spec["type"]
        extra = ' numsides="%d"' % spec["numsides"] if kind == "polyhedra" \
            else ""
        body.append('<%s name="%s" startphi="%r" deltaphi="%r"%s '
                    'aunit="rad" lunit="mm">'
                    % (kind, spec["name"], spec["sphi"], spec["dphi"], extra))
        for z, r0, r1 in spec["planes"]:
            body.append('  <zplane z="%r" rmin="%r" rmax="%r"/>'
                        % (float(z), float(r0), float(r1)))
        body.append("</%s>" % kind)
    text = "\n".join([
        '<?xml version="1.0" encoding="UTF-8"?>', "<gdml>", "<define/>",
        "<materials>",
        '<material name="pc_tmp_vacuum" Z="1.0"><D value="1e-25" '
        'unit="g/cm3"/><atom value="1.008" unit="g/mole"/></material>',
        "</materials>", "<solids>",
        '<box name="pc_tmp_box" x="1" y="1" z="1" lunit="mm"/>'] + body + [
        "</solids>", "<structure>",
        '<volume name="pc_tmp_world"><materialref ref="pc_tmp_vacuum"/>'
        '<solidref ref="pc_tmp_box"/></volume>', "</structure>",
        '<setup name="Default" version="1.0"><world ref="pc_tmp_world"/>'
        "</setup>", "</gdml>", ""])
    path = os.path.join(ses.tmp.name, "polycones.gdml")
    with open(path, "w") as fh:
        fh.write(text)
    parser = g4.G4GDMLParser()
    parser.SetStripFlag(False)
    parser.Read(path, False)
    ses.keep.append(parser)
    store = g4.G4SolidStore.GetInstance()
    out = []
    for spec in specs:
        s = store.GetSolid(spec["name"], False)
        want = "G4Polycone" if spec["type"] == "polycone" else "G4Polyhedra"
        if s is None or s.GetEntityType() != want:
            raise RuntimeError("GDML did not produce %s %s"
                               % (want, spec["name"]))
        out.append(s)
    return out


def material(g4, keep, nist_name, z, a, density):
    """NIST material, or a simple one built by hand if NIST fails."""
    try:
        m = g4.G4NistManager.Instance().FindOrBuildMaterial(nist_name)
    except Exception:
        m = None
    if m is None:
        m = g4.G4Material("rt_" + nist_name, z, a * g4.g / g4.mole,
                          density * g4.g / g4.cm3)
    keep.append(m)
    return m


def build_roundtrip(ses):
    """The roundtrip geometry; returns the world placement."""
    g4 = ses.g4
    keep = ses.keep
    deg = math.pi / 180.0
    air = material(g4, keep, "G4_AIR", 7.3, 14.6, 0.0012)
    al = material(g4, keep, "G4_Al", 13.0, 26.98, 2.699)
    fe = material(g4, keep, "G4_Fe", 26.0, 55.85, 7.874)

    def K(x):
        keep.append(x)
        return x

    world_s = K(g4.G4Box("rt_world_box", 2000.0, 2000.0, 2000.0))
    world_lv = K(g4.G4LogicalVolume(world_s, air, "rt_world"))
    world_pv = K(g4.G4PVPlacement(None, g4.G4ThreeVector(), world_lv,
                                  "rt_world_pv", None, False, 0))

    pc, ph = polycones_from_gdml(ses, [
        {"type": "polycone", "name": "rt_polycone", "sphi": 0.25,
         "dphi": 4.5, "planes": [(-80.0, 0.0, 60.0), (-10.0, 10.0, 90.0),
                                 (40.0, 20.0, 50.0), (90.0, 0.0, 30.0)]},
        {"type": "polyhedra", "name": "rt_polyhedra", "sphi": 0.1,
         "dphi": 2 * math.pi, "numsides": 6,
         "planes": [(-70.0, 15.0, 60.0), (0.0, 25.0, 100.0),
                    (70.0, 15.0, 50.0)]},
    ])
    K(pc)
    K(ph)
    solids = [
        K(g4.G4Tubs("rt_tubs", 20.0, 100.0, 80.0, 30 * deg, 250 * deg)),
        K(g4.G4Cons("rt_cons", 10.0, 60.0, 20.0, 110.0, 90.0, 0.0,
                    2 * math.pi)),
        K(g4.G4Sphere("rt_sphere", 30.0, 120.0, 0.0, 2 * math.pi,
                      20 * deg, 110 * deg)),
        pc, ph,
        K(g4.G4Trd("rt_trd", 60.0, 110.0, 40.0, 90.0, 100.0)),
        K(g4.G4Trap("rt_trap", 90.0, 12 * deg, 35 * deg, 50.0, 40.0, 60.0,
                    10 * deg, 70.0, 56.0, 84.0, 10 * deg)),
        K(g4.G4Torus("rt_torus", 10.0, 35.0, 90.0, 20 * deg, 300 * deg)),
    ]
    ub_a = K(g4.G4Box("rt_union_a", 100.0, 40.0, 40.0))
    ub_b = K(g4.G4Tubs("rt_union_b", 0.0, 35.0, 110.0, 0.0, 2 * math.pi))
    solids.append(K(g4.G4UnionSolid(
        "rt_union", ub_a, ub_b,
        g4.G4Transform3D(rotation(g4, [("x", 90 * deg)]),
                         g4.G4ThreeVector(40.0, 0.0, 0.0)))))
    sb_a = K(g4.G4Box("rt_sub_a", 110.0, 100.0, 90.0))
    sb_b = K(g4.G4Tubs("rt_sub_b", 0.0, 45.0, 150.0, 0.0, 2 * math.pi))
    solids.append(K(g4.G4SubtractionSolid(
        "rt_subtraction", sb_a, sb_b,
        g4.G4Transform3D(rotation(g4, [("x", 35 * deg), ("y", 50 * deg)]),
                         g4.G4ThreeVector(20.0, -15.0, 10.0)))))

    # a 3 x 4 grid of the solids, 600 mm apart, each rotated differently
    for k, s in enumerate(solids):
        lv = K(g4.G4LogicalVolume(s, al, "rt_lv_" + s.GetName()[3:]))
        ix, iy = k % 4, k // 4
        pos = g4.G4ThreeVector(-900.0 + 600.0 * ix, -600.0 + 600.0 * iy,
                               -700.0)
        rot = rotation(g4, [("z", (15 + 20 * k) * deg),
                            ("x", (10 + 7 * k) * deg)])
        K(g4.G4PVPlacement(g4.G4Transform3D(rot, pos), lv,
                           "rt_pv_" + s.GetName()[3:], world_lv, False, k))

    # holder rotated about two axes, with four copies of one cell volume
    holder_s = K(g4.G4Box("rt_holder_box", 450.0, 300.0, 200.0))
    holder_lv = K(g4.G4LogicalVolume(holder_s, air, "rt_holder"))
    K(g4.G4PVPlacement(
        g4.G4Transform3D(rotation(g4, [("x", 30 * deg), ("z", 40 * deg)]),
                         g4.G4ThreeVector(150.0, 250.0, 900.0)),
        holder_lv, "rt_holder_pv", world_lv, False, 0))
    cell_s = K(g4.G4Tubs("rt_cell_tubs", 0.0, 60.0, 90.0, 0.0, 2 * math.pi))
    cell_lv = K(g4.G4LogicalVolume(cell_s, fe, "rt_cell"))
    core_s = K(g4.G4Box("rt_core_box", 10.0, 15.0, 20.0))
    core_lv = K(g4.G4LogicalVolume(core_s, al, "rt_core"))
    K(g4.G4PVPlacement(
        g4.G4Transform3D(rotation(g4, [("y", 25 * deg), ("z", 60 * deg)]),
                         g4.G4ThreeVector(10.0, -5.0, 25.0)),
        core_lv, "rt_core_pv", cell_lv, False, 7))
    for c in range(4):
        pos = g4.G4ThreeVector(-300.0 + 200.0 * c, 40.0 * (c % 2) - 20.0,
                               10.0 * c)
        rot = rotation(g4, [("y", (20 + 15 * c) * deg),
                            ("x", (-10 * c) * deg)])
        K(g4.G4PVPlacement(g4.G4Transform3D(rot, pos), cell_lv,
                           "rt_cell_pv", holder_lv, False, 10 + c))
    return world_pv


def strip_pointer(name):
    i = name.find("0x")
    return name[:i] if i > 0 else name


def cmd_roundtrip(args):
    t_start = time.perf_counter()
    ses = Session(sys.stderr)
    try:
        g4 = ses.g4
        os.makedirs(args.outdir, exist_ok=True)
        path = os.path.join(args.outdir, "roundtrip.gdml")
        world_pv = build_roundtrip(ses)
        if os.path.exists(path):
            os.remove(path)
        writer = g4.G4GDMLParser()
        ses.keep.append(writer)
        writer.Write(path, world_pv, True)
        if not os.path.exists(path):
            raise RuntimeError("G4GDMLParser.Write did not write %s" % path)
        built = list_placements(g4, Tree(g4, world_pv))
        # Read back in a fresh process: in this one the reader would find
        # the built world (G4GDMLReadStructure looks the world logical
        # volume up by its stripped name in the global store).
        child = subprocess.run(
            [sys.executable, os.path.abspath(__file__), "placements", path],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=os.environ,
            universal_newlines=True)
        if child.returncode != 0:
            raise RuntimeError("placements on %s failed:\n%s"
                               % (path, child.stderr))
        reread = json.loads(child.stdout)["placements"]
        err = 0.0
        ok = len(built) == len(reread)
        for a, b in zip(built, reread):
            keys = ("copy", "logical", "solid", "solid_type")
            if a["depth"] > 0:
                # the world's placement is not written; Geant4 names it
                # <world logical>_PV when reading
                keys = ("name",) + keys
            for k in keys:
                va, vb = a[k], b[k]
                if isinstance(vb, str):
                    va, vb = strip_pointer(va), strip_pointer(vb)
                if va != vb:
                    ok = False
                    sys.stderr.write("roundtrip mismatch %s: %r != %r\n"
                                     % (k, a[k], b[k]))
            err = max(err, float(np.abs(np.subtract(a["rotation"],
                                                    b["rotation"])).max()),
                      float(np.abs(np.subtract(a["translation"],
                                               b["translation"])).max()))
        ok = ok and err < 1e-9
        doc = {"path": os.path.abspath(path), "placements": len(built),
               "max_transform_err": err, "verified": ok,
               "seconds": round(time.perf_counter() - t_start, 3)}
    finally:
        ses.end()
    doc["g4_warnings"] = ses.counter[0]
    return doc


# ---------------------------------------------------------------------------
# main
# ---------------------------------------------------------------------------

def cmd_adjudicate(args):
    """For each ray with hytrace's distance ``t``: whether Geant4's own point
    location (``LocateGlobalPointAndSetup``) sees the located touchable change
    across ``t`` (a real boundary there) and across Geant4's step ``step``.
    Rays where the two navigator answers differ are judged with it: Geant4's
    ComputeStep contradicts its own point location when it steps over a
    boundary that location sees, or stops at one that location does not."""
    ses = Session(sys.stderr)
    try:
        g4 = ses.g4
        world = ses.read(args.gdml)
        ses.close_geometry()
        tree = Tree(g4, world)
        loc = Locator(g4, tree)
        rays = np.load(args.rays)
        ts = np.load(args.answers)
        steps = np.load(args.steps)

        def where(p):
            pv = loc.nav.LocateGlobalPointAndSetup(
                g4.G4ThreeVector(*[float(v) for v in p]), None, False, False)
            if pv is None:
                return None
            return loc._key()[2]

        def changes(o, d, t):
            if not np.isfinite(t):
                return False
            delta = max(1e-3, 1e-7 * (np.linalg.norm(o) + t))
            return where(o + (t - delta) * d) != where(o + (t + delta) * d)

        out = []
        for row, t, step in zip(rays, ts, steps):
            o, d = row[:3], row[4:7]
            out.append({"boundary_at_hytrace": bool(changes(o, d, t)),
                        "boundary_at_geant4": bool(changes(o, d, step))})
        return {"rays": out}
    finally:
        ses.end()


def parse_args(argv):
    ap = argparse.ArgumentParser(
        description="Geant4 navigation oracle for the hytrace GDML importer.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    s = sub.add_parser("sample", help="locate random ray origins and compute "
                       "the step to the next boundary")
    s.add_argument("gdml")
    s.add_argument("--out", required=True, help="output directory")
    s.add_argument("--rays", type=int, default=10000)
    s.add_argument("--seed", type=int, default=1)
    p = sub.add_parser("placements", help="print every placement with its "
                       "global transform (JSON)")
    p.add_argument("gdml")
    p.add_argument("--check-overlaps", type=int, default=0, metavar="RES",
                   help="run CheckOverlaps with RES surface points on every "
                   "placement")
    r = sub.add_parser("roundtrip", help="write a Python-built geometry to "
                       "OUTDIR/roundtrip.gdml and check it reads back")
    r.add_argument("outdir")
    a = sub.add_parser("adjudicate", help="check with Geant4's point "
                       "location whether boundaries exist at given distances")
    a.add_argument("gdml")
    a.add_argument("--rays", required=True, help="(N, 8) float64 rays")
    a.add_argument("--answers", required=True, help="(N,) hytrace distances")
    a.add_argument("--steps", required=True, help="(N,) Geant4 steps")
    args = ap.parse_args(argv)
    if args.cmd == "sample" and args.rays < 0:
        ap.error("--rays must be >= 0")
    if args.cmd in ("sample", "placements", "adjudicate") and \
            not os.path.isfile(args.gdml):
        ap.error("no such file: %s" % args.gdml)
    return args


def main(argv=None):
    args = parse_args(sys.argv[1:] if argv is None else argv)
    real_out, real_err = sys.stdout, sys.stderr
    try:
        if args.cmd == "sample":
            doc = cmd_sample(args)
            text = json.dumps(doc)
        elif args.cmd == "adjudicate":
            doc = cmd_adjudicate(args)
            text = json.dumps(doc)
        elif args.cmd == "placements":
            doc = cmd_placements(args)
            text = json.dumps(doc, indent=1)
        else:
            doc = cmd_roundtrip(args)
            text = json.dumps(doc)
        rc = 0 if doc.get("verified", True) else 1
    except Exception:
        sys.stdout, sys.stderr = real_out, real_err
        traceback.print_exc()
        rc, text = 1, None
    if text is not None:
        real_out.write(text + "\n")
    real_out.flush()
    real_err.flush()
    # No Geant4 destructors at interpreter shutdown (see module doc).
    os._exit(rc)


if __name__ == "__main__":
    main()
