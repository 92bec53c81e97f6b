#!/usr/bin/env python3
"""Geant4 reference oracle for the hytrace CSG ray tracer.

Purpose
-------
This script generates random Geant4 solids (primitives and boolean trees),
shoots random rays at them and records what Geant4 (through the
``geant4_pybind`` bindings) answers: whether the ray origin is inside the
solid and the distance along the ray to the next boundary.  The Rust test
suite rebuilds the same solids from ``solids.json``, traces the same rays and
compares its answers against ``expected.npy``.

Command line::

    geant4_oracle.py --out DIR --seed S --solids-per-kind K --rays-per-solid M
                     [--kinds k1,k2,...] [--bench] [--march N]
                     [--self-check]

Run it with ``GEANT4_DATA_DIR`` pointing to an existing (possibly empty)
directory; when it is unset the script points it to an empty temporary one,
since geant4_pybind would otherwise try to download the Geant4 data sets
(the geometry needs none of them).  ``--self-check`` runs the convention
checks of ``self_check()`` first and prints their report to stderr.

Everything is generated from ``numpy.random.default_rng`` seeded with ``S``
(each kind draws from its own stream ``default_rng([S, KIND_INDEX])`` where
KIND_INDEX is the kind's position in ``KINDS`` below, so the solids of one
kind do not depend on which other kinds are selected).  The output is fully
deterministic for given arguments.

Conventions
-----------
* Units: lengths in mm, angles in radians.
* All box-like sizes are Geant4 *half* lengths (``dx`` is the half width
  along x, ``dz`` the half length along z, ...).
* Every length and angle of a primitive spec is a float32-representable
  number (``float(np.float32(x))``): the Rust side stores primitive
  parameters in f32, and Geant4 gets exactly the same values as f64.
* Full turns are written as ``float32(2*pi)`` (= 6.2831854820251465, slightly
  larger than 2*pi) and a full theta range as ``float32(pi)``; Geant4 clamps
  both.  Whenever a phi range is a full turn ``dphi >= 2*pi`` holds in f64.
* Ray origins are float32-representable.  Directions are unit vectors to
  float64 precision (|d| = 1 +- 2e-16) and are exactly the f64 values passed
  to Geant4; they are chosen so that their float32 rounding ``d32`` is itself
  unit to within 2^-25 (3e-8) and ``d32 / |d32|`` computed in f64 gives back
  ``d`` bit for bit; axis directions are exact.  Geant4 needs |d| == 1 to
  double precision: with float32-rounded directions (|d| - 1 ~ 1e-8) its
  boolean solids returned distances off by millimetres (the pushing loops of
  G4SubtractionSolid / G4IntersectionSolid evaluate Inside(p + t*d), which
  then misses the component surface by t * (|d| - 1)).
* Boolean placement: the second operand ``b`` of a boolean node is placed in
  the frame of the first operand ``a`` by ``p_a = R p_b + t`` (``R`` = the
  row-major 3x3 ``rotation``, a proper rotation, ``t`` = ``translation``).
  In Geant4 this is ``G4Transform3D(R, t)`` (the *active* placement: the
  solid ``b`` itself is rotated by ``R`` and then moved by ``t``).  Note that
  this is NOT the ``(G4RotationMatrix*, G4ThreeVector)`` constructor of the
  Geant4 boolean solids, which takes the inverse (frame) rotation.

Outputs (in DIR, created if needed)
-----------------------------------
``solids.json``::

    {"format": "hytrace-geant4-oracle", "version": 1,
     "geant4": "<Geant4 version string>",
     "solids": [{"kind": KIND, "spec": SPEC}, ...]}

``SPEC`` is a dict with a ``"type"`` key plus the parameters (numbers are
JSON floats, ``numside`` is an int).  Primitive specs:

============  ===============================================================
type          keys (Geant4 constructor it maps to)
============  ===============================================================
box           dx, dy, dz                        G4Box (half lengths)
orb           r                                 G4Orb
sphere        rmin, rmax, sphi, dphi, stheta, dtheta       G4Sphere
tubs          rmin, rmax, dz, sphi, dphi        G4Tubs
cutTubs       rmin, rmax, dz, sphi, dphi, low:[x,y,z], high:[x,y,z]
              G4CutTubs; ``low``/``high`` are the outward normals of the
              cut planes through (0,0,-dz) and (0,0,+dz) (low z < 0,
              high z > 0), float32-rounded unit vectors (Geant4
              renormalises them).  The planes never meet inside r <= rmax.
cons          rmin1, rmax1, rmin2, rmax2, dz, sphi, dphi   G4Cons (index 1
              is at z = -dz); rmin1 and rmin2 are both 0 or both > 0.
torus         rmin, rmax, rtor, sphi, dphi      G4Torus
trd           dx1, dx2, dy1, dy2, dz            G4Trd (1 at -dz, 2 at +dz)
trap          dz, theta, phi, dy1, dx1, dx2, alpha1, dy2, dx3, dx4, alpha2
              G4Trap (11-parameter constructor); always planar:
              alpha1 == alpha2 and (dx2-dx1)/dy1 == (dx4-dx3)/dy2 exactly.
para          dx, dy, dz, alpha, theta, phi     G4Para
polycone      sphi, dphi, z:[...], rmin:[...], rmax:[...]
              G4Polycone(name, sphi, dphi, nz, z, rmin, rmax); 2-5 planes,
              z non-decreasing (at most one repeated z = a radial step,
              never at either end), rmin < rmax on every plane.
polyhedra     sphi, dphi, numside, z:[...], rmin:[...], rmax:[...]
              G4Polyhedra(name, sphi, dphi, numside, nz, z, rmin, rmax):
              rmin/rmax are distances from the z axis to the side PLANES
              (inscribed radius, apothem), not to the corners.  The first
              side starts at phi = sphi; numside sides span dphi.
hype          rmin, rmax, stereo_in, stereo_out, dz
              G4Hype: r^2 - z^2 tan^2(stereo) = R^2 for each surface;
              stereo_in == 0 whenever rmin == 0 (no inner surface).
paraboloid    dz, rlo, rhi                      G4Paraboloid: radius rlo at
              z = -dz and rhi at z = +dz, rho^2 = k1 z + k2.
ellipsoid     ax, by, cz, zbottom, ztop         G4Ellipsoid; cuts always
              explicit: no cut is zbottom = -cz / ztop = cz.  (Geant4 treats
              zbottom == ztop == 0 as "no cuts"; that pair is never written.)
eltube        dx, dy, dz                        G4EllipticalTube
elcone        xsemi, ysemi, zheight, zcut       G4EllipticalCone: xsemi and
              ysemi are dimensionless slopes; surface
              (x/xsemi)^2 + (y/ysemi)^2 = (zheight - z)^2, solid spans
              -zcut <= z <= zcut, zcut < zheight.
tet           anchor, p2, p3, p4 (each [x,y,z])  G4Tet (any orientation)
============  ===============================================================

Boolean specs (kind ``boolean``, trees of depth 1..4)::

    {"type": "union"|"subtraction"|"intersection",
     "a": SPEC, "b": SPEC,
     "rotation": [[r00,r01,r02],[r10,r11,r12],[r20,r21,r22]],
     "translation": [x, y, z]}

Leaves are box, orb, tubs, cons, sphere, torus or trd (sphere leaves never
have pi < dphi < 2 pi, see gen_leaf).  Rotation entries are
f64 (identity, signed axis permutations, or arbitrary); translations are
float32-representable.

``rays.npy``       float64 (N, 8): ox oy oz tmin dx dy dz tmax (tmin = 0,
                   tmax = inf).
``ray_solid.npy``  int32 (N,): index into ``solids``.
``ray_family.npy`` int32 (N,): 0 random (origin uniform in the bounding box
                   enlarged 1.5x about its centre, isotropic direction),
                   1 aimed (origin 1-3 bounding radii outside the bounding
                   sphere, aimed at a uniform point of the bounding box),
                   2 axis (origin as random, direction exactly one of +-x,
                   +-y, +-z), 3 inside (origin rejection-sampled with
                   Inside == kInside, isotropic direction; when sampling
                   fails the ray is a ``random`` one and recorded as 0).
``expected.npy``   float64 (N, 2): distance, inside code of the origin
                   (0 kOutside, 1 kSurface, 2 kInside).  distance is
                   DistanceToIn(p, v) when outside, DistanceToOut(p, v)
                   (calcNorm = false) when inside, NaN on the surface, and
                   ``inf`` where Geant4 returned kInfinity (no hit).
``timing.json``    {"queries", "seconds", "per_query_s", "per_kind":
                   {kind: {"queries", "seconds"}}, "flagged_rays",
                   "flagged_g4_warning", "flagged_inconsistent",
                   "flagged_missed", "g4_warnings", "total_seconds"}:
                   queries = Inside + Distance calls (1 for a surface
                   origin, else 2 per ray); seconds = wall time of the loop
                   over those calls only (the G4ThreeVectors are built
                   before the loop; the checks behind ray_flags run after
                   it).  g4_warnings counts every G4Exception printed,
                   including harmless ones while generating (e.g. "Bad
                   bounding box" of rejected empty boolean candidates).
                   With --bench also "overhead_per_call_s" (and
                   "overhead_calls"): time of one G4Orb.Inside call at a
                   fixed point (1e5 calls averaged), i.e. the pure Python
                   binding overhead.
``ray_flags.npy``  int32 (N,): 0 for a clean answer; bit 0 (1): Geant4
                   issued a G4Exception warning while answering the ray;
                   bit 1 (2): Geant4 contradicts itself: Inside(p + d*v) is
                   not kSurface for a finite distance d, or just past it
                   (1e-6 of the solid's size) the ray is not on the other
                   side, or an inside origin got d = inf; bit 2 (4): sampling Inside() along the ray
                   (inside the bounding box, before d) found a point on the
                   other side or on a surface, i.e. Geant4 skipped a
                   crossing or misclassified the interior (32 samples for
                   hype, boolean and torus, 16 for other kinds, --march N
                   for more).  Flagged answers are Geant4
                   bugs (seen with 11.4: G4Hype::DistanceToIn reporting hits
                   on the hyperboloids beyond |z| = dz, or missing entries,
                   for ~0.1% of rays); compare only unflagged rays.
``geant4.log``     whatever Geant4 printed (G4cout and G4cerr).

stdout gets exactly one JSON line on success:
``{"solids": n, "rays": n, "seconds": total_wall_time}``.

Geant4 quirks handled here
--------------------------
* geant4_pybind 0.1.3 binds the ``const G4double*`` array arguments of
  G4Polycone / G4Polyhedra as a single float, so these solids cannot be
  built directly from Python.  They are built by writing a GDML file
  (``<polycone>`` / ``<polyhedra>`` with ``<zplane>`` entries, read with
  G4GDMLParser without schema validation), which calls exactly those
  constructors; the solids are then fetched from G4SolidStore.
* Invalid parameters raise fatal G4Exceptions, which abort the process
  (no exception handler is installed), so every generator keeps well inside
  the validity domain (e.g. planarity of G4Trap faces is enforced exactly,
  with a tolerance of ~1e-6 mm in Geant4).
* G4Torus::Inside (11.4) answers kSurface or kOutside for every interior
  point when the phi range contains phi = 0 (e.g. sphi = -0.5, any dphi; or
  sphi + dphi > 2 pi); torus phi ranges are therefore kept clear of phi = 0.
* G4Cons silently replaces rmin1 = 0 (or rmin2 = 0) by 1e-6 mm when the other
  inner radius is positive; the generator never emits such a pair.
* Directions must be unit to double precision (see Conventions).
* G4Sphere::DistanceToOut(p, v) from a point p on a phi plane, with v
  leaving through that plane, returns a non-zero distance (to the rmax shell)
  in about a third of the cases when pi < dphi < 2 pi.  Rays of the sphere
  kind never start on a surface, but boolean solids restart their operands
  from surface points, so sphere leaves of booleans avoid such dphi.
* G4Hype gives wrong answers for roughly 0.2% of the rays (hits reported on
  the hyperboloids beyond |z| = dz, entries missed), mostly with
  stereo_in > stereo_out or a cylindrical inner surface; those rays are
  flagged in ray_flags.npy.
* G4IntersectionSolid::DistanceToIn(p, v) alternates between the next
  inside ranges of its operands and re-adds the offset of the range it keeps
  (``dB1 += dB`` also runs when B's range was not recomputed), so after two
  switches it can skip the overlap and answer kInfinity or a later entry.
  Rare (about 1 boolean ray in 10^4); caught by the sampling check.
* G4Ellipsoid reads zbottom == ztop == 0 as "no cuts".
"""

import argparse
import json
import math
import os
import sys
import tempfile
import time

import numpy as np

FORMAT = "hytrace-geant4-oracle"
VERSION = 1

# Order matters: a kind's index seeds its random stream.
KINDS = [
    "box", "orb", "sphere", "tubs", "cutTubs", "cons", "torus", "trd",
    "trap", "para", "polycone", "polyhedra", "hype", "paraboloid",
    "ellipsoid", "eltube", "elcone", "tet", "boolean",
]
LEAF_KINDS = ["box", "orb", "tubs", "cons", "sphere", "torus", "trd"]

PI = math.pi
TWO_PI = 2.0 * math.pi
K_INFINITY = 9.0e99  # Geant4 kInfinity
FAMILY_RANDOM, FAMILY_AIMED, FAMILY_AXIS, FAMILY_INSIDE = 0, 1, 2, 3
FLAG_G4_WARNING = 1     # Geant4 printed a G4Exception while answering
FLAG_INCONSISTENT = 2   # Geant4's distance disagrees with its own Inside()
FLAG_MISSED = 4         # sampling Inside() along the ray found a crossing
                        # before Geant4's distance (kinds in MARCH_SAMPLES)
# Inside() samples along each ray (inside the bounding box) used to detect
# crossings that Geant4's distance skipped.  G4Hype (11.4) misses entries for
# some rays and G4IntersectionSolid::DistanceToIn can skip a valid range (see
# the module doc), so those kinds are always checked; --march N extends the
# check to every kind.
MARCH_SAMPLES = {"hype": 32, "boolean": 32, "torus": 32}
# Every other kind gets this many samples: G4Torus (11.4) with a phi range over
# pi answers kSurface deep inside the solid, so no kind is trusted unchecked.
MARCH_DEFAULT = 16


def f32(x):
    """Round to the nearest float32 value and return it as a Python float."""
    return float(np.float32(x))


F32_TWO_PI = f32(TWO_PI)  # 6.2831854820251465 > 2*pi
F32_PI = f32(PI)          # 3.1415927410125732 > pi
assert F32_TWO_PI >= TWO_PI and F32_PI >= PI


def f32_up(x):
    """Smallest float32 value >= x (as a Python float)."""
    y = np.float32(x)
    if float(y) < x:
        y = np.nextafter(y, np.float32(np.inf))
    return float(y)


# ---------------------------------------------------------------------------
# Geant4 output capture
# ---------------------------------------------------------------------------

class _G4Sink:
    """Replacement for sys.stdout/sys.stderr while Geant4 is active.

    geant4_pybind routes G4cout/G4cerr through Python's sys.stdout/stderr.
    Everything goes to the log file; fatal exceptions are also echoed to the
    real stderr (the process aborts right after them)."""

    def __init__(self, log, real_err, is_err, counter):
        self.log = log
        self.real_err = real_err
        self.is_err = is_err
        self.counter = counter  # shared [n_g4_exceptions]

    def write(self, s):
        self.log.write(s)
        self.log.flush()
        if "G4Exception-START" in s:
            self.counter[0] += 1
        if self.is_err and ("Fatal" in s or "Aborting" in s):
            self.real_err.write(s)
            self.real_err.flush()
        return len(s)

    def flush(self):
        self.log.flush()

    def isatty(self):
        return False


# ---------------------------------------------------------------------------
# Parameter generation (pure numpy / Python, no Geant4)
# ---------------------------------------------------------------------------

def log_uniform(rng, lo, hi):
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def phi_range(rng, variant):
    """(sphi, dphi) for variant 'full', 'lt' (< pi) or 'gt' (> pi)."""
    if variant == "full":
        return 0.0, F32_TWO_PI
    sphi = f32(rng.uniform(-PI, PI))
    if variant == "lt":
        dphi = f32(rng.uniform(0.35, PI - 0.25))
    else:
        dphi = f32(rng.uniform(PI + 0.25, TWO_PI - 0.35))
    return sphi, dphi


def pick_phi_variant(rng, p_full=0.4):
    u = rng.uniform()
    if u < p_full:
        return "full"
    return "lt" if rng.uniform() < 0.5 else "gt"


def gen_box(rng, i, s):
    return {"type": "box", "dx": f32(s * rng.uniform(0.2, 1.0)),
            "dy": f32(s * rng.uniform(0.2, 1.0)),
            "dz": f32(s * rng.uniform(0.2, 1.0))}


def gen_orb(rng, i, s):
    return {"type": "orb", "r": f32(s * rng.uniform(0.5, 1.0))}


def gen_sphere(rng, i, s):
    variants = ["full", "inner", "phi_lt", "phi_gt", "theta", "theta_cross",
                "theta_top", "theta_bottom", "all"]
    v = variants[i % len(variants)]
    rmax = f32(s * rng.uniform(0.5, 1.0))
    rmin = 0.0
    sphi, dphi = 0.0, F32_TWO_PI
    stheta, dtheta = 0.0, F32_PI
    if v in ("inner", "all") or (v not in ("full",) and rng.uniform() < 0.3):
        rmin = f32(rmax * rng.uniform(0.15, 0.85))
    if v == "phi_lt":
        sphi, dphi = phi_range(rng, "lt")
    elif v == "phi_gt":
        sphi, dphi = phi_range(rng, "gt")
    elif v == "all":
        sphi, dphi = phi_range(rng, "lt" if rng.uniform() < 0.5 else "gt")
    if v == "theta":
        stheta = f32(rng.uniform(0.15, 1.1))
        end = rng.uniform(stheta + 0.2, min(stheta + 1.4, PI / 2 - 0.1))
        if rng.uniform() < 0.5:  # mirror into the lower hemisphere
            stheta, end = PI - end, PI - stheta
            stheta = f32(stheta)
        dtheta = f32(end - stheta)
    elif v in ("theta_cross", "all"):
        stheta = f32(rng.uniform(0.2, 1.35))
        end = rng.uniform(1.8, 2.95)
        dtheta = f32(end - stheta)
    elif v == "theta_top":  # cone around +z removed from the bottom
        stheta = 0.0
        dtheta = f32(rng.uniform(0.35, 2.8))
        if abs(dtheta - PI / 2) < 0.1:
            dtheta = f32(PI / 2 + 0.3)
    elif v == "theta_bottom":  # runs down to theta = pi
        stheta = f32(rng.uniform(0.35, 2.8))
        if abs(stheta - PI / 2) < 0.1:
            stheta = f32(PI / 2 - 0.3)
        dtheta = f32_up(F32_PI - stheta)  # stheta + dtheta >= f32(pi) > pi
    return {"type": "sphere", "rmin": rmin, "rmax": rmax, "sphi": sphi,
            "dphi": dphi, "stheta": stheta, "dtheta": dtheta}


def _variant_phi(rng, v):
    """The phi range of a solid variant ("phi_lt", "phi_gt", "inner_phi" or
    a full turn)."""
    if v == "phi_lt":
        return phi_range(rng, "lt")
    if v == "phi_gt":
        return phi_range(rng, "gt")
    if v == "inner_phi":
        return phi_range(rng, pick_phi_variant(rng, 0.0))
    return 0.0, F32_TWO_PI


def _tubs_radii_phi(rng, i, s):
    variants = ["full", "inner", "phi_lt", "phi_gt", "inner_phi"]
    v = variants[i % len(variants)]
    rmax = f32(s * rng.uniform(0.4, 1.0))
    rmin = 0.0
    if v in ("inner", "inner_phi"):
        rmin = f32(rmax * rng.uniform(0.15, 0.85))
    sphi, dphi = _variant_phi(rng, v)
    return rmin, rmax, sphi, dphi


def gen_tubs(rng, i, s):
    rmin, rmax, sphi, dphi = _tubs_radii_phi(rng, i, s)
    dz = f32(s * rng.uniform(0.2, 1.0))
    return {"type": "tubs", "rmin": rmin, "rmax": rmax, "dz": dz,
            "sphi": sphi, "dphi": dphi}


def _tilted_normal(rng, tilt, sign_z):
    az = rng.uniform(-PI, PI)
    n = [math.sin(tilt) * math.cos(az), math.sin(tilt) * math.sin(az),
         sign_z * math.cos(tilt)]
    return [f32(c) for c in n]


def gen_cut_tubs(rng, i, s):
    rmin, rmax, sphi, dphi = _tubs_radii_phi(rng, i, s)
    max_tilt = math.radians(30.0)
    tl = rng.uniform(0.0, max_tilt)
    th = rng.uniform(0.0, max_tilt)
    if i % 4 == 1:
        tl = 0.0  # only the high plane is cut
    elif i % 4 == 2:
        th = 0.0  # only the low plane is cut
    if tl < 0.02 and th < 0.02:
        th = 0.3
    low = _tilted_normal(rng, tl, -1.0)
    high = _tilted_normal(rng, th, +1.0)
    # The cut planes pass through (0,0,-+dz).  Over the disc r <= rmax the
    # low plane reaches at most -dz + rmax*tan(tl) and the high one at least
    # dz - rmax*tan(th): keep a clear gap between them.
    need = rmax * (math.tan(tl) + math.tan(th))
    dz = s * rng.uniform(0.2, 1.0)
    dz = max(dz, 0.75 * need + 0.05 * s)
    dz = f32(dz)
    assert 2.0 * dz > 1.2 * need
    return {"type": "cutTubs", "rmin": rmin, "rmax": rmax, "dz": dz,
            "sphi": sphi, "dphi": dphi, "low": low, "high": high}


def gen_cons(rng, i, s):
    variants = ["solid", "hollow", "apex_low", "apex_high", "hollow_phi",
                "solid_phi"]
    v = variants[i % len(variants)]
    dz = f32(s * rng.uniform(0.2, 1.0))
    rmax1 = f32(s * rng.uniform(0.2, 1.0))
    rmax2 = f32(s * rng.uniform(0.2, 1.0))
    rmin1 = rmin2 = 0.0
    sphi, dphi = 0.0, F32_TWO_PI
    if v == "apex_low":
        rmax1 = 0.0
    elif v == "apex_high":
        rmax2 = 0.0
    if v in ("hollow", "hollow_phi"):
        rmin1 = f32(rmax1 * rng.uniform(0.1, 0.85))
        rmin2 = f32(rmax2 * rng.uniform(0.1, 0.85))
    if v in ("hollow_phi", "solid_phi"):
        sphi, dphi = phi_range(rng, pick_phi_variant(rng, 0.0))
    elif v in ("apex_low", "apex_high") and rng.uniform() < 0.4:
        sphi, dphi = phi_range(rng, pick_phi_variant(rng, 0.0))
    return {"type": "cons", "rmin1": rmin1, "rmax1": rmax1, "rmin2": rmin2,
            "rmax2": rmax2, "dz": dz, "sphi": sphi, "dphi": dphi}


def gen_torus(rng, i, s):
    variants = ["full", "inner", "phi_lt", "phi_gt", "inner_phi"]
    v = variants[i % len(variants)]
    rmax = f32(s * rng.uniform(0.12, 0.4))
    rmin = 0.0
    if v in ("inner", "inner_phi"):
        rmin = f32(rmax * rng.uniform(0.2, 0.8))
    rtor = f32(rmax * rng.uniform(1.3, 4.0))
    sphi, dphi = _variant_phi(rng, v)
    if dphi < TWO_PI and (sphi < 0.0 or sphi + dphi > TWO_PI):
        # G4Torus::Inside (11.4) answers "not inside" for every interior point
        # when the phi range contains phi = 0, which also corrupts the
        # booleans built on it; keep the range clear of phi = 0.
        sphi = f32(rng.uniform(0.01, max(0.02, TWO_PI - dphi - 0.01)))
    return {"type": "torus", "rmin": rmin, "rmax": rmax, "rtor": rtor,
            "sphi": sphi, "dphi": dphi}


def gen_trd(rng, i, s):
    return {"type": "trd", "dx1": f32(s * rng.uniform(0.1, 1.0)),
            "dx2": f32(s * rng.uniform(0.1, 1.0)),
            "dy1": f32(s * rng.uniform(0.1, 1.0)),
            "dy2": f32(s * rng.uniform(0.1, 1.0)),
            "dz": f32(s * rng.uniform(0.2, 1.0))}


def gen_trap(rng, i, s):
    # Planarity of the +-x faces needs alpha1 == alpha2 and
    # (dx2 - dx1) / dy1 == (dx4 - dx3) / dy2.  Geant4 checks it to ~1e-6 mm,
    # so the half lengths live on a dyadic grid where the relation is exact
    # in both f32 and f64.
    grid = 1.0 / 64.0

    def on_grid(x):
        return max(grid, round(x / grid) * grid)

    while True:
        dy1 = on_grid(s * rng.uniform(0.2, 1.0))
        ratio = float(rng.choice([0.5, 0.75, 1.0, 1.25, 1.5, 2.0]))
        dy2 = dy1 * ratio
        dx1 = on_grid(s * rng.uniform(0.15, 1.0))
        dx2 = on_grid(s * rng.uniform(0.15, 1.0))
        dx3 = on_grid(s * rng.uniform(0.15, 1.0))
        dx4 = dx3 + ratio * (dx2 - dx1)
        if dx4 < 0.1 * s or dx4 < 0.5:
            continue
        break
    for x in (dy1, dy2, dx1, dx2, dx3, dx4):
        assert f32(x) == x
    assert (dx2 - dx1) * dy2 == (dx4 - dx3) * dy1
    alpha = f32(rng.uniform(-0.45, 0.45))
    return {"type": "trap", "dz": f32(s * rng.uniform(0.2, 1.0)),
            "theta": f32(rng.uniform(0.0, 0.55)),
            "phi": f32(rng.uniform(-PI, PI)),
            "dy1": dy1, "dx1": dx1, "dx2": dx2, "alpha1": alpha,
            "dy2": dy2, "dx3": dx3, "dx4": dx4, "alpha2": alpha}


def gen_para(rng, i, s):
    return {"type": "para", "dx": f32(s * rng.uniform(0.15, 1.0)),
            "dy": f32(s * rng.uniform(0.15, 1.0)),
            "dz": f32(s * rng.uniform(0.15, 1.0)),
            "alpha": f32(rng.uniform(-0.5, 0.5)),
            "theta": f32(rng.uniform(0.0, 0.6)),
            "phi": f32(rng.uniform(-PI, PI))}


def _zplanes(rng, i, s):
    """z, rmin, rmax lists for polycone/polyhedra."""
    nz = int(rng.integers(2, 6))
    hollow = (i % 2 == 1)
    z = [f32(-s * rng.uniform(0.1, 0.8))]
    step_at = -1
    if nz >= 3 and rng.uniform() < 0.45:
        step_at = int(rng.integers(1, nz - 1))  # plane step_at repeats z
    for k in range(1, nz):
        if k == step_at:
            z.append(z[-1])
        else:
            z.append(f32(z[-1] + s * rng.uniform(0.08, 0.6)))
    rmax, rmin = [], []
    for k in range(nz):
        while True:
            ro = f32(s * rng.uniform(0.2, 1.0))
            ri = f32(ro * rng.uniform(0.1, 0.8)) if hollow else 0.0
            if k == step_at:
                # radial step: keep the two rings overlapping radially and
                # the step visible
                pi_, po = rmin[-1], rmax[-1]
                if not (ri < po and pi_ < ro) or abs(ro - po) < 0.05 * s:
                    continue
            break
        rmax.append(ro)
        rmin.append(ri)
    return z, rmin, rmax


def gen_polycone(rng, i, s):
    z, rmin, rmax = _zplanes(rng, i, s)
    sphi, dphi = phi_range(rng, ["full", "lt", "gt"][(i // 2) % 3])
    return {"type": "polycone", "sphi": sphi, "dphi": dphi, "z": z,
            "rmin": rmin, "rmax": rmax}


def gen_polyhedra(rng, i, s):
    z, rmin, rmax = _zplanes(rng, i, s)
    sphi, dphi = phi_range(rng, ["full", "lt", "gt"][(i // 2) % 3])
    if dphi == F32_TWO_PI and rng.uniform() < 0.5:
        sphi = f32(rng.uniform(-PI, PI))  # rotated full polyhedra
    return {"type": "polyhedra", "sphi": sphi, "dphi": dphi,
            "numside": int(rng.integers(3, 9)), "z": z, "rmin": rmin,
            "rmax": rmax}


def gen_hype(rng, i, s):
    variants = ["solid", "hollow", "solid_cyl", "hollow_cylin"]
    v = variants[i % len(variants)]
    while True:
        rmax = f32(s * rng.uniform(0.3, 1.0))
        dz = f32(s * rng.uniform(0.3, 1.0))
        so = f32(rng.uniform(0.1, 1.2))
        rmin, si = 0.0, 0.0
        if v == "solid_cyl":
            so = 0.0
        if v in ("hollow", "hollow_cylin"):
            rmin = f32(rmax * rng.uniform(0.15, 0.75))
            si = 0.0 if v == "hollow_cylin" else f32(rng.uniform(0.1, 1.2))
        rin_end2 = rmin * rmin + (dz * math.tan(si)) ** 2
        rout_end2 = rmax * rmax + (dz * math.tan(so)) ** 2
        if rmin == 0.0 or rin_end2 < 0.8 * rout_end2:
            break
    return {"type": "hype", "rmin": rmin, "rmax": rmax, "stereo_in": si,
            "stereo_out": so, "dz": dz}


def gen_paraboloid(rng, i, s):
    rhi = f32(s * rng.uniform(0.3, 1.0))
    rlo = 0.0 if i % 3 == 0 else f32(rhi * rng.uniform(0.05, 0.9))
    return {"type": "paraboloid", "dz": f32(s * rng.uniform(0.2, 1.0)),
            "rlo": rlo, "rhi": rhi}


def gen_ellipsoid(rng, i, s):
    ax = f32(s * rng.uniform(0.2, 1.0))
    by = f32(s * rng.uniform(0.2, 1.0))
    cz = f32(s * rng.uniform(0.2, 1.0))
    v = i % 4
    zb, zt = -cz, cz
    if v in (1, 3):
        zb = f32(cz * rng.uniform(-0.9, 0.4))
    if v in (2, 3):
        zt = f32(cz * rng.uniform(max(-0.4, zb / cz + 0.2), 0.9))
    if zb == 0.0 and zt == 0.0:  # Geant4 would read this as "no cuts"
        zt = f32(0.5 * cz)
    assert -cz <= zb < zt <= cz
    return {"type": "ellipsoid", "ax": ax, "by": by, "cz": cz,
            "zbottom": zb, "ztop": zt}


def gen_eltube(rng, i, s):
    return {"type": "eltube", "dx": f32(s * rng.uniform(0.15, 1.0)),
            "dy": f32(s * rng.uniform(0.15, 1.0)),
            "dz": f32(s * rng.uniform(0.15, 1.0))}


def gen_elcone(rng, i, s):
    zheight = f32(s * rng.uniform(0.3, 1.0))
    zcut = f32(zheight * rng.uniform(0.1, 0.95))
    assert 0.0 < zcut < zheight
    return {"type": "elcone", "xsemi": f32(rng.uniform(0.1, 1.5)),
            "ysemi": f32(rng.uniform(0.1, 1.5)), "zheight": zheight,
            "zcut": zcut}


def gen_tet(rng, i, s):
    while True:
        a = rng.uniform(-0.5 * s, 0.5 * s, 3)
        pts = [a] + [a + rng.normal(size=3) * s * rng.uniform(0.3, 1.0)
                     for _ in range(3)]
        pts = [np.array([f32(c) for c in p]) for p in pts]
        e = [pts[j] - pts[0] for j in (1, 2, 3)]
        vol = abs(float(np.dot(e[0], np.cross(e[1], e[2])))) / 6.0
        edges = [np.linalg.norm(pts[j] - pts[k])
                 for j in range(4) for k in range(j + 1, 4)]
        lmax = max(edges)
        if lmax > 0 and vol > 0.02 * lmax ** 3 and min(edges) > 0.1 * lmax:
            break
    return {"type": "tet", "anchor": [float(c) for c in pts[0]],
            "p2": [float(c) for c in pts[1]], "p3": [float(c) for c in pts[2]],
            "p4": [float(c) for c in pts[3]]}


GENERATORS = {
    "box": gen_box, "orb": gen_orb, "sphere": gen_sphere, "tubs": gen_tubs,
    "cutTubs": gen_cut_tubs, "cons": gen_cons, "torus": gen_torus,
    "trd": gen_trd, "trap": gen_trap, "para": gen_para,
    "polycone": gen_polycone, "polyhedra": gen_polyhedra, "hype": gen_hype,
    "paraboloid": gen_paraboloid, "ellipsoid": gen_ellipsoid,
    "eltube": gen_eltube, "elcone": gen_elcone, "tet": gen_tet,
}


def random_rotation(rng, i):
    """Row-major proper rotation: identity, signed axis permutation or
    arbitrary (uniform quaternion)."""
    mode = i % 3
    if mode == 0:
        return [[1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]]
    if mode == 1:
        while True:
            perm = rng.permutation(3)
            signs = rng.choice([-1.0, 1.0], 3)
            m = np.zeros((3, 3))
            for r in range(3):
                m[r, perm[r]] = signs[r]
            if np.linalg.det(m) > 0 and not np.array_equal(m, np.eye(3)):
                return [[float(x) + 0.0 for x in row] for row in m]
    q = rng.normal(size=4)
    w, x, y, z = q / np.linalg.norm(q)
    m = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
         [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
         [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    return [[float(v) for v in row] for row in m]


# ---------------------------------------------------------------------------
# Geant4 construction
# ---------------------------------------------------------------------------

class Builder:
    """Builds Geant4 solids from specs and keeps every constituent alive."""

    def __init__(self, g4, tmpdir):
        self.g4 = g4
        self.tmpdir = tmpdir
        self.keep = []
        self.count = 0
        self.gdml_batches = 0

    def _name(self, kind):
        self.count += 1
        return "hy_%s_%d" % (kind, self.count)

    def vec(self, xyz):
        return self.g4.G4ThreeVector(float(xyz[0]), float(xyz[1]),
                                     float(xyz[2]))

    def rotation(self, m):
        r = self.g4.G4RotationMatrix()
        # rotateAxes(newX, newY, newZ) on the identity gives the matrix whose
        # columns are newX, newY, newZ.
        cols = [[m[0][c], m[1][c], m[2][c]] for c in range(3)]
        r.rotateAxes(self.vec(cols[0]), self.vec(cols[1]), self.vec(cols[2]))
        got = [[r.xx, r.xy, r.xz], [r.yx, r.yy, r.yz], [r.zx, r.zy, r.zz]]
        assert np.allclose(got, m, atol=1e-12), (got, m)
        self.keep.append(r)
        return r

    def build(self, spec):
        g4 = self.g4
        t = spec["type"]
        name = self._name(t)
        if t == "box":
            s = g4.G4Box(name, spec["dx"], spec["dy"], spec["dz"])
        elif t == "orb":
            s = g4.G4Orb(name, spec["r"])
        elif t == "sphere":
            s = g4.G4Sphere(name, spec["rmin"], spec["rmax"], spec["sphi"],
                            spec["dphi"], spec["stheta"], spec["dtheta"])
        elif t == "tubs":
            s = g4.G4Tubs(name, spec["rmin"], spec["rmax"], spec["dz"],
                          spec["sphi"], spec["dphi"])
        elif t == "cutTubs":
            lo, hi = self.vec(spec["low"]), self.vec(spec["high"])
            self.keep += [lo, hi]
            s = g4.G4CutTubs(name, spec["rmin"], spec["rmax"], spec["dz"],
                             spec["sphi"], spec["dphi"], lo, hi)
        elif t == "cons":
            s = g4.G4Cons(name, spec["rmin1"], spec["rmax1"], spec["rmin2"],
                          spec["rmax2"], spec["dz"], spec["sphi"],
                          spec["dphi"])
        elif t == "torus":
            s = g4.G4Torus(name, spec["rmin"], spec["rmax"], spec["rtor"],
                           spec["sphi"], spec["dphi"])
        elif t == "trd":
            s = g4.G4Trd(name, spec["dx1"], spec["dx2"], spec["dy1"],
                         spec["dy2"], spec["dz"])
        elif t == "trap":
            s = g4.G4Trap(name, spec["dz"], spec["theta"], spec["phi"],
                          spec["dy1"], spec["dx1"], spec["dx2"],
                          spec["alpha1"], spec["dy2"], spec["dx3"],
                          spec["dx4"], spec["alpha2"])
        elif t == "para":
            s = g4.G4Para(name, spec["dx"], spec["dy"], spec["dz"],
                          spec["alpha"], spec["theta"], spec["phi"])
        elif t == "hype":
            s = g4.G4Hype(name, spec["rmin"], spec["rmax"], spec["stereo_in"],
                          spec["stereo_out"], spec["dz"])
        elif t == "paraboloid":
            s = g4.G4Paraboloid(name, spec["dz"], spec["rlo"], spec["rhi"])
        elif t == "ellipsoid":
            s = g4.G4Ellipsoid(name, spec["ax"], spec["by"], spec["cz"],
                               spec["zbottom"], spec["ztop"])
        elif t == "eltube":
            s = g4.G4EllipticalTube(name, spec["dx"], spec["dy"], spec["dz"])
        elif t == "elcone":
            s = g4.G4EllipticalCone(name, spec["xsemi"], spec["ysemi"],
                                    spec["zheight"], spec["zcut"])
        elif t == "tet":
            pts = [self.vec(spec[k]) for k in ("anchor", "p2", "p3", "p4")]
            self.keep += pts
            s = g4.G4Tet(name, pts[0], pts[1], pts[2], pts[3])
        elif t in ("polycone", "polyhedra"):
            s = self.build_gdml([spec])[0]
        elif t in ("union", "subtraction", "intersection"):
            a = self.build(spec["a"])
            b = self.build(spec["b"])
            rot = self.rotation(spec["rotation"])
            tr = self.vec(spec["translation"])
            xf = g4.G4Transform3D(rot, tr)
            self.keep += [tr, xf]
            cls = {"union": g4.G4UnionSolid,
                   "subtraction": g4.G4SubtractionSolid,
                   "intersection": g4.G4IntersectionSolid}[t]
            s = cls(name, a, b, xf)
        else:
            raise ValueError("unknown solid type %r" % t)
        self.keep.append(s)
        return s

    def build_gdml(self, specs):
        """Polycone/polyhedra through the GDML reader (see module doc)."""
        g4 = self.g4
        self.gdml_batches += 1
        tag = "hyg%d" % self.gdml_batches
        names = []
        lines = ['<?xml version="1.0" encoding="UTF-8"?>', "<gdml>",
                 "<define/>", "<materials>",
                 '<material name="%s_mat" Z="1.0">' % tag,
                 '<D value="1e-20" unit="g/cm3"/>'
                 '<atom value="1.008" unit="g/mole"/></material>',
                 "</materials>", "<solids>",
                 '<box name="%s_worldbox" x="1" y="1" z="1" lunit="mm"/>'
                 % tag]
        for spec in specs:
            name = self._name(spec["type"])
            names.append(name)
            if spec["type"] == "polycone":
                lines.append('<polycone name="%s" startphi="%r" '
                             'deltaphi="%r" aunit="rad" lunit="mm">'
                             % (name, spec["sphi"], spec["dphi"]))
            else:
                lines.append('<polyhedra name="%s" startphi="%r" '
                             'deltaphi="%r" numsides="%d" aunit="rad" '
                             'lunit="mm">' % (name, spec["sphi"],
                                               spec["dphi"], spec["numside"]))
            for z, ri, ro in zip(spec["z"], spec["rmin"], spec["rmax"]):
                lines.append('<zplane z="%r" rmin="%r" rmax="%r"/>'
                             % (float(z), float(ri), float(ro)))
            lines.append("</%s>" % spec["type"])
        lines += ["</solids>", "<structure>",
                  '<volume name="%s_world"><materialref ref="%s_mat"/>'
                  '<solidref ref="%s_worldbox"/></volume>' % (tag, tag, tag),
                  "</structure>",
                  '<setup name="Default" version="1.0">'
                  '<world ref="%s_world"/></setup>' % tag, "</gdml>"]
        path = os.path.join(self.tmpdir, tag + ".gdml")
        with open(path, "w") as fh:
            fh.write("\n".join(lines) + "\n")
        parser = g4.G4GDMLParser()
        parser.SetStripFlag(False)
        parser.Read(path, False)
        self.keep.append(parser)
        store = g4.G4SolidStore.GetInstance()
        out = []
        for name, spec in zip(names, specs):
            s = store.GetSolid(name, False)
            want = "G4Polycone" if spec["type"] == "polycone" else "G4Polyhedra"
            if s is None or s.GetEntityType() != want:
                raise RuntimeError("GDML did not produce %s %s" % (want, name))
            self.keep.append(s)
            out.append(s)
        return out


def bounding_box(g4, solid):
    lo, hi = g4.G4ThreeVector(), g4.G4ThreeVector()
    solid.BoundingLimits(lo, hi)
    return (np.array([lo.x, lo.y, lo.z]), np.array([hi.x, hi.y, hi.z]))


def inside_fraction(g4, solid, rng, n):
    lo, hi = bounding_box(g4, solid)
    if not np.all(hi - lo > 1e-6):
        return 0.0  # e.g. an intersection of disjoint bounding boxes
    pts = lo + rng.uniform(size=(n, 3)) * (hi - lo)
    inside = solid.Inside
    k_in = g4.EInside.kInside
    hits = 0
    for p in pts:
        if inside(g4.G4ThreeVector(*p)) == k_in:
            hits += 1
    return hits / n


def gen_leaf(rng, s):
    kind = LEAF_KINDS[int(rng.integers(len(LEAF_KINDS)))]
    spec = GENERATORS[kind](rng, int(rng.integers(0, 1000)), s)
    if kind == "sphere" and PI < spec["dphi"] < TWO_PI:
        # G4Sphere (11.4) answers DistanceToOut from a point on a phi plane,
        # moving out through it, with a non-zero distance when dphi > pi;
        # boolean solids restart their components from such points, so a
        # boolean with such a leaf gets wrong distances.  Use the
        # complementary opening instead.
        spec["dphi"] = f32(TWO_PI - spec["dphi"])
    return spec


def gen_tree(rng, depth, s, builder):
    """Random boolean tree of exactly the given depth (>= 1)."""
    if depth == 0:
        return gen_leaf(rng, s * rng.uniform(0.6, 1.0))
    op = ["union", "subtraction", "intersection"][int(rng.integers(3))]
    a = gen_tree(rng, depth - 1, s, builder)
    b_depth = 0 if depth == 1 or rng.uniform() < 0.6 else \
        int(rng.integers(1, depth))
    b = gen_tree(rng, b_depth, s * (0.8 if op == "subtraction" else 1.0),
                 builder)
    rot = random_rotation(rng, int(rng.integers(3)))
    # place b near the middle of a's bounding box
    sa = builder.build(a)
    lo, hi = bounding_box(builder.g4, sa)
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    off = rng.uniform(-0.6, 0.6, 3) * half
    tr = [f32(c) for c in centre + off]
    return {"type": op, "a": a, "b": b, "rotation": rot, "translation": tr}


def gen_boolean(rng, i, s, builder):
    depth = 1 + (i % 4)
    for _ in range(200):
        spec = gen_tree(rng, depth, s, builder)
        solid = builder.build(spec)
        if inside_fraction(builder.g4, solid, rng, 400) >= 0.02:
            return spec, solid
    raise RuntimeError("could not generate a non-empty boolean")


# ---------------------------------------------------------------------------
# Rays
# ---------------------------------------------------------------------------

# |v32| - 1 bound below which float32(v32 / |v32|) == v32 componentwise:
# renormalising moves a component c by |c * delta|, less than half an ulp of
# c (>= |c| * 2^-25) as long as |delta| < 2^-25.
_SNAP_LIMIT = 2.0 ** -25


def snap_directions(d):
    """Unit float64 directions whose float32 rounding is a near-unit vector.

    Geant4 needs |v| == 1 to double precision: a direction that is off by
    even 5e-9 makes boolean solids return wrong distances (their pushing
    loops test Inside at p + d*v, which then misses the surface).  So each
    direction is rounded to float32 (v32), nudged by at most 2 ulps per
    component so that | |v32| - 1 | < 2^-25, and renormalised in float64:
    the result v64 = v32 / |v32| is what Geant4 gets and what is stored; it
    satisfies |v64| = 1 to ~1e-16 and float32(v64) == v32.  Axis directions
    are exact.
    """
    d = np.asarray(d, dtype=np.float64)
    m = len(d)
    if m == 0:
        return d.reshape(0, 3)
    v32 = (d / np.linalg.norm(d, axis=1)[:, None]).astype(np.float32)
    # 5 candidates per component: -2..+2 ulps
    cand = [v32]
    up, dn = v32, v32
    for _ in range(2):
        up = np.nextafter(up, np.float32(np.inf))
        dn = np.nextafter(dn, np.float32(-np.inf))
        cand += [up, dn]
    cand = np.stack(cand, axis=1).astype(np.float64)  # (m, 5, 3)
    cx = cand[:, :, 0][:, :, None, None]
    cy = cand[:, :, 1][:, None, :, None]
    cz = cand[:, :, 2][:, None, None, :]
    err = np.abs(cx * cx + cy * cy + cz * cz - 1.0).reshape(m, -1)
    best = np.argmin(err, axis=1)
    ix, iy, iz = np.unravel_index(best, (5, 5, 5))
    rows = np.arange(m)
    snapped = np.stack([cand[rows, ix, 0], cand[rows, iy, 1],
                        cand[rows, iz, 2]], axis=1)
    norm = np.sqrt(np.sum(snapped * snapped, axis=1))
    ok = np.abs(norm - 1.0) < _SNAP_LIMIT
    out = snapped / norm[:, None]
    ok &= np.all(out.astype(np.float32).astype(np.float64) == snapped, axis=1)
    # exact axis vectors stay exact (norm is exactly 1 there)
    if not np.all(ok):
        # practically never: fall back to the plain renormalised direction
        bad = ~ok
        out[bad] = d[bad] / np.linalg.norm(d[bad], axis=1)[:, None]
    return out


def _round_f32(a):
    return np.asarray(a, dtype=np.float64).astype(np.float32).astype(
        np.float64)


def _isotropic_batch(rng, m):
    v = rng.normal(size=(m, 3))
    n = np.linalg.norm(v, axis=1)
    tiny = n < 1e-9
    v[tiny] = [0.0, 0.0, 1.0]
    n[tiny] = 1.0
    return v / n[:, None]


def make_rays(g4, solid, rng, m):
    """Returns (origins (m,3), dirs (m,3), families (m,)); ray j belongs to
    family j % 4 (inside rays that could not be sampled become random)."""
    lo, hi = bounding_box(g4, solid)
    centre = 0.5 * (lo + hi)
    half = 0.5 * (hi - lo)
    radius = float(np.linalg.norm(half))
    big_lo, big_hi = centre - 1.5 * half, centre + 1.5 * half
    fams = (np.arange(m) % 4).astype(np.int32)

    # random family (also the fallback of the inside family)
    rnd_o = _round_f32(big_lo + rng.uniform(size=(m, 3)) * (big_hi - big_lo))
    rnd_d = _isotropic_batch(rng, m)
    # aimed family
    u = _isotropic_batch(rng, m)
    dist = radius * (1.0 + rng.uniform(1.0, 3.0, m))
    aim_o = _round_f32(centre + u * dist[:, None])
    target = lo + rng.uniform(size=(m, 3)) * (hi - lo)
    aim_d = target - aim_o
    # axis family
    axes = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0],
                     [0, 0, 1], [0, 0, -1]], dtype=np.float64)
    ax_o = _round_f32(big_lo + rng.uniform(size=(m, 3)) * (big_hi - big_lo))
    ax_d = axes[rng.integers(0, 6, m)]
    # inside family: rejection sampling in the bounding box
    slots = np.nonzero(fams == FAMILY_INSIDE)[0]
    budget = max(2000, 60 * len(slots))  # Inside() calls at most
    found = []
    inside = solid.Inside
    k_in = g4.EInside.kInside
    V = g4.G4ThreeVector
    while len(found) < len(slots) and budget > 0:
        n = min(budget, 256)
        budget -= n
        cand = _round_f32(lo + rng.uniform(size=(n, 3)) * (hi - lo))
        for p in cand.tolist():
            if inside(V(*p)) == k_in:
                found.append(p)
                if len(found) == len(slots):
                    break
    in_d = _isotropic_batch(rng, len(slots))

    origins = rnd_o.copy()
    dirs = rnd_d.copy()
    sel = fams == FAMILY_AIMED
    origins[sel], dirs[sel] = aim_o[sel], aim_d[sel]
    sel = fams == FAMILY_AXIS
    origins[sel], dirs[sel] = ax_o[sel], ax_d[sel]
    for k, j in enumerate(slots):
        if k < len(found):
            origins[j] = found[k]
            dirs[j] = in_d[k]
        else:
            fams[j] = FAMILY_RANDOM  # keeps the random ray of this slot
    return origins, snap_directions(dirs), fams


def trace(g4, solid, origins, dirs, counter, march=0):
    """Inside + distance for each ray; returns (expected (m,2), flags (m,),
    queries, seconds spent in the Geant4 loop); see FLAG_* for flags."""
    V = g4.G4ThreeVector
    pv = [(V(*o), V(*d)) for o, d in zip(origins.tolist(), dirs.tolist())]
    inside = solid.Inside
    dti = solid.DistanceToIn
    dto = solid.DistanceToOut
    k_out, k_in = g4.EInside.kOutside, g4.EInside.kInside
    codes = [0] * len(pv)
    dists = [0.0] * len(pv)
    flags = [0] * len(pv)
    queries = 0
    seen = counter[0]
    t0 = time.perf_counter()
    for j, (p, v) in enumerate(pv):
        c = inside(p)
        if c == k_out:
            codes[j] = 0
            dists[j] = dti(p, v)
            queries += 2
        elif c == k_in:
            codes[j] = 2
            dists[j] = dto(p, v)
            queries += 2
        else:
            codes[j] = 1
            dists[j] = math.nan
            queries += 1
        if counter[0] != seen:
            seen = counter[0]
            flags[j] = FLAG_G4_WARNING
    seconds = time.perf_counter() - t0
    out = np.empty((len(pv), 2))
    d = np.array(dists, dtype=np.float64)
    d[d >= K_INFINITY] = np.inf
    out[:, 0] = d
    out[:, 1] = codes
    # Self-consistency of Geant4's answer (outside the timed loop): the end
    # point of a finite distance must be on the surface according to the
    # solid's own Inside(), and a ray starting inside must leave.
    k_surf = g4.EInside.kSurface
    blo, bhi = bounding_box(g4, solid)
    step_past = 1e-6 * (1.0 + float(np.max(bhi - blo)))
    for j, (o, v) in enumerate(zip(origins.tolist(), dirs.tolist())):
        dj = dists[j]
        if codes[j] == 1:
            continue
        if dj >= K_INFINITY:
            bad = codes[j] == 2
        else:
            bad = inside(V(o[0] + dj * v[0], o[1] + dj * v[1],
                           o[2] + dj * v[2])) != k_surf
            # Just past the crossing the ray must be on the other side (a
            # kSurface there means Geant4 misclassifies a whole region).
            dd = dj + step_past
            other = k_in if codes[j] == 0 else k_out
            bad = bad or inside(V(o[0] + dd * v[0], o[1] + dd * v[1],
                                  o[2] + dd * v[2])) != other
        if bad:
            flags[j] |= FLAG_INCONSISTENT
    if march > 0:
        lo, hi = bounding_box(g4, solid)
        pad = 1e-6 * (1.0 + np.abs(lo) + np.abs(hi))
        lo, hi = lo - pad, hi + pad
        k_out = g4.EInside.kOutside
        frac = (np.arange(march) + 0.5) / march
        for j in range(len(pv)):
            if codes[j] == 1:
                continue
            o, v = origins[j], dirs[j]
            t0, t1 = 0.0, min(dists[j], 1e30)
            for a in range(3):  # clip the segment to the bounding box
                if v[a] != 0.0:
                    ta = (lo[a] - o[a]) / v[a]
                    tb = (hi[a] - o[a]) / v[a]
                    t0 = max(t0, min(ta, tb))
                    t1 = min(t1, max(ta, tb))
                elif not lo[a] <= o[a] <= hi[a]:
                    t1 = -1.0
            if t1 <= t0:
                continue
            ts = t0 + frac * (t1 - t0)
            pts = (o[None, :] + ts[:, None] * v[None, :]).tolist()
            # Before the crossing every sample must be on the origin's side;
            # kSurface away from any crossing is a contradiction too.
            same = k_out if codes[j] == 0 else k_in
            for q in pts:
                if inside(V(q[0], q[1], q[2])) != same:
                    flags[j] |= FLAG_MISSED
                    break
    return out, np.array(flags, dtype=np.int32), queries, seconds


# ---------------------------------------------------------------------------
# Self check (conventions), --self-check
# ---------------------------------------------------------------------------

def self_check(g4, builder):
    """Numerical checks of the conventions this file relies on."""
    V = g4.G4ThreeVector
    report = {}
    # 1. orb of radius r from an outside point on the x axis
    orb = builder.build({"type": "orb", "r": 10.0})
    report["orb_dist_in"] = orb.DistanceToIn(V(-25, 0, 0), V(1, 0, 0))
    report["orb_dist_out"] = orb.DistanceToOut(V(0, 0, 0), V(0, 0, 1))
    report["orb_miss"] = orb.DistanceToIn(V(-25, 0, 0), V(0, 1, 0))
    assert report["orb_dist_in"] == 15.0 and report["orb_dist_out"] == 10.0
    assert report["orb_miss"] >= K_INFINITY
    # 2. boolean placement p_a = R p_b + t: b is an asymmetric box, a is a
    #    tiny orb far away, so all of b is exposed in the union.
    rng = np.random.default_rng(12345)
    bad_alt = 0
    for trial in range(20):
        rot = random_rotation(rng, 2)
        t = [f32(c) for c in rng.uniform(-30, 30, 3)]
        box = {"type": "box", "dx": 7.0, "dy": 13.0, "dz": 23.0}
        spec = {"type": "union", "a": {"type": "orb", "r": 1.0}, "b": box,
                "rotation": rot, "translation": [1000.0, 0.0, 0.0]}
        spec["translation"] = [1000.0 + t[0], t[1], t[2]]
        u = builder.build(spec)
        R = np.array(rot)
        tt = np.array(spec["translation"])
        for _ in range(10):
            # random point on a face of b (in b's frame)
            ax = int(rng.integers(3))
            pb = rng.uniform(-1, 1, 3) * np.array([7.0, 13.0, 23.0])
            pb[ax] = [7.0, 13.0, 23.0][ax] * rng.choice([-1.0, 1.0])
            pa = R @ pb + tt
            assert u.Inside(V(*pa)) == g4.EInside.kSurface, (pb, pa)
            pa_alt = R.T @ pb + tt  # the other (passive) convention
            if u.Inside(V(*pa_alt)) != g4.EInside.kSurface:
                bad_alt += 1
            # a point slightly outside along the face normal is outside
            nb = np.zeros(3)
            nb[ax] = np.sign(pb[ax])
            po = R @ (pb + 0.01 * nb) + tt
            assert u.Inside(V(*po)) == g4.EInside.kOutside
            pi_ = R @ (pb - 0.01 * nb) + tt
            assert u.Inside(V(*pi_)) == g4.EInside.kInside
    report["boolean_active_convention_ok"] = True
    report["passive_convention_failures"] = bad_alt
    assert bad_alt > 100  # R^T would be wrong almost everywhere
    # 3. polyhedra radii are apothems (distance to the side planes)
    ph = builder.build({"type": "polyhedra", "sphi": 0.0, "dphi": F32_TWO_PI,
                        "numside": 6, "z": [-10.0, 10.0],
                        "rmin": [0.0, 0.0], "rmax": [20.0, 20.0]})
    mid = PI / 6  # middle of the first side
    d = ph.DistanceToIn(V(100 * math.cos(mid), 100 * math.sin(mid), 0),
                        V(-math.cos(mid), -math.sin(mid), 0))
    report["polyhedra_apothem"] = 100 - d
    assert abs(100 - d - 20.0) < 1e-9
    return report


# ---------------------------------------------------------------------------
# main
# ---------------------------------------------------------------------------

def parse_args(argv):
    ap = argparse.ArgumentParser(
        description="Generate Geant4 reference ray/solid answers for hytrace.")
    ap.add_argument("--out", required=True, help="output directory")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--solids-per-kind", type=int, default=20)
    ap.add_argument("--rays-per-solid", type=int, default=500)
    ap.add_argument("--kinds", default=",".join(KINDS),
                    help="comma separated subset of: " + ",".join(KINDS))
    ap.add_argument("--bench", action="store_true",
                    help="also measure the pure binding overhead")
    ap.add_argument("--march", type=int, default=0, metavar="N",
                    help="check every ray of every kind with N Inside() "
                         "samples for crossings Geant4 skipped (slow; hype "
                         "and boolean are always checked with %d)"
                         % MARCH_SAMPLES["hype"])
    ap.add_argument("--self-check", action="store_true",
                    help="run convention checks and print their report "
                         "to stderr")
    args = ap.parse_args(argv)
    kinds = [k.strip() for k in args.kinds.split(",") if k.strip()]
    unknown = [k for k in kinds if k not in KINDS]
    if unknown:
        sys.stderr.write("geant4_oracle.py: error: unknown kind(s) %s; known "
                         "kinds: %s\n" % (", ".join(map(repr, unknown)),
                                          ", ".join(KINDS)))
        sys.exit(2)
    if not kinds:
        sys.stderr.write("geant4_oracle.py: error: no kinds selected\n")
        sys.exit(2)
    if args.solids_per_kind < 0 or args.rays_per_solid < 0:
        sys.stderr.write("geant4_oracle.py: error: counts must be >= 0\n")
        sys.exit(2)
    # keep the canonical order, drop duplicates
    args.kinds = [k for k in KINDS if k in kinds]
    return args


def main(argv=None):
    t_start = time.perf_counter()
    args = parse_args(sys.argv[1:] if argv is None else argv)
    os.makedirs(args.out, exist_ok=True)

    real_out, real_err = sys.stdout, sys.stderr
    log = open(os.path.join(args.out, "geant4.log"), "w")
    counter = [0]
    out_sink = _G4Sink(log, real_err, False, counter)
    err_sink = _G4Sink(log, real_err, True, counter)
    tmp = tempfile.TemporaryDirectory(prefix="hytrace_g4_")
    if not os.environ.get("GEANT4_DATA_DIR"):
        # geant4_pybind would otherwise try to download its data sets; the
        # geometry needs none of them.
        data_dir = os.path.join(tmp.name, "g4data")
        os.makedirs(data_dir, exist_ok=True)
        os.environ["GEANT4_DATA_DIR"] = data_dir
    sys.stdout, sys.stderr = out_sink, err_sink
    try:
        import geant4_pybind as g4
        result = run(g4, args, tmp.name, real_err, counter)
    finally:
        sys.stdout, sys.stderr = real_out, real_err
        log.close()
        tmp.cleanup()
    timing = result["timing"]
    timing["g4_warnings"] = counter[0]
    timing["total_seconds"] = time.perf_counter() - t_start
    with open(os.path.join(args.out, "timing.json"), "w") as fh:
        json.dump(timing, fh, indent=1)
        fh.write("\n")
    real_out.write(json.dumps({"solids": result["solids"],
                               "rays": result["rays"],
                               "seconds": round(timing["total_seconds"], 3)})
                   + "\n")
    real_out.flush()
    return 0


def run(g4, args, tmpdir, real_err, counter):
    builder = Builder(g4, tmpdir)
    if args.self_check:
        report = self_check(g4, builder)
        real_err.write("self-check: %s\n" % json.dumps(report))

    solids_json = []
    rays, ray_solid, ray_family, expected, ray_flags = [], [], [], [], []
    per_kind = {}
    total_q, total_s = 0, 0.0
    K, M = args.solids_per_kind, args.rays_per_solid
    for kind in args.kinds:
        rng = np.random.default_rng([args.seed, KINDS.index(kind)])
        specs = []
        solids = []
        if kind == "boolean":
            for i in range(K):
                spec, solid = gen_boolean(rng, i, log_uniform(rng, 10, 100),
                                          builder)
                specs.append(spec)
                solids.append(solid)
        else:
            gen = GENERATORS[kind]
            for i in range(K):
                specs.append(gen(rng, i, log_uniform(rng, 3, 200)))
            if kind in ("polycone", "polyhedra"):
                solids = builder.build_gdml(specs) if specs else []
            else:
                solids = [builder.build(s) for s in specs]
        kq, ks = 0, 0.0
        for spec, solid in zip(specs, solids):
            idx = len(solids_json)
            solids_json.append({"kind": kind, "spec": spec})
            origins, dirs, fams = make_rays(g4, solid, rng, M)
            exp, flags, q, sec = trace(
                g4, solid, origins, dirs, counter,
                max(args.march, MARCH_SAMPLES.get(kind, MARCH_DEFAULT)))
            kq += q
            ks += sec
            r = np.zeros((M, 8))
            r[:, 0:3] = origins
            r[:, 3] = 0.0
            r[:, 4:7] = dirs
            r[:, 7] = np.inf
            rays.append(r)
            ray_solid.append(np.full(M, idx, dtype=np.int32))
            ray_family.append(fams)
            expected.append(exp)
            ray_flags.append(flags)
        per_kind[kind] = {"queries": kq, "seconds": ks}
        total_q += kq
        total_s += ks

    def cat(parts, shape, dtype):
        return np.concatenate(parts) if parts else np.zeros(shape, dtype)

    out = args.out
    np.save(os.path.join(out, "rays.npy"),
            cat(rays, (0, 8), np.float64).astype(np.float64))
    np.save(os.path.join(out, "ray_solid.npy"),
            cat(ray_solid, (0,), np.int32).astype(np.int32))
    np.save(os.path.join(out, "ray_family.npy"),
            cat(ray_family, (0,), np.int32).astype(np.int32))
    np.save(os.path.join(out, "expected.npy"),
            cat(expected, (0, 2), np.float64).astype(np.float64))
    np.save(os.path.join(out, "ray_flags.npy"),
            cat(ray_flags, (0,), np.int32).astype(np.int32))
    doc = {"format": FORMAT, "version": VERSION,
           "geant4": str(getattr(g4, "G4Version", "")).strip("$ ")
           .replace("Name: ", ""),
           "solids": solids_json}
    with open(os.path.join(out, "solids.json"), "w") as fh:
        json.dump(doc, fh, indent=1)
        fh.write("\n")

    timing = {"queries": total_q, "seconds": total_s,
              "per_query_s": (total_s / total_q) if total_q else 0.0,
              "per_kind": per_kind,
              "flagged_rays": int(sum(int(np.count_nonzero(f))
                                      for f in ray_flags)),
              "flagged_g4_warning": int(sum(
                  int(np.count_nonzero(f & FLAG_G4_WARNING))
                  for f in ray_flags)),
              "flagged_inconsistent": int(sum(
                  int(np.count_nonzero(f & FLAG_INCONSISTENT))
                  for f in ray_flags)),
              "flagged_missed": int(sum(
                  int(np.count_nonzero(f & FLAG_MISSED))
                  for f in ray_flags))}
    if args.bench:
        orb = builder.build({"type": "orb", "r": 10.0})
        p = g4.G4ThreeVector(1.0, 2.0, 3.0)
        f = orb.Inside
        n = 100000
        t0 = time.perf_counter()
        for _ in range(n):
            f(p)
        timing["overhead_per_call_s"] = (time.perf_counter() - t0) / n
        timing["overhead_calls"] = n
    n_rays = sum(len(r) for r in rays)
    return {"solids": len(solids_json), "rays": n_rays, "timing": timing}


if __name__ == "__main__":
    sys.exit(main())
