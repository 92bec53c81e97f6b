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
                     [--self-check] [--describe-twisted]
    geant4_oracle.py --out DIR --cases FILE
    geant4_oracle.py --describe-twisted

Run it with ``GEANT4_DATA_DIR`` pointing to an existing (possibly empty)
directory; when it is unset the script points it to an empty temporary one,
since geant4_pybind would otherwise try to download the Geant4 data sets
(the geometry needs none of them).  ``--self-check`` runs the convention
checks of ``self_check()`` first and prints their report to stderr.
``--describe-twisted`` checks the twisted-solid formulas of the section
"Twisted solids" below against Geant4 (``describe_twisted()``) and prints
its report to stderr, one JSON line per kind; without ``--out`` only this
check runs, stdout gets ``{"describe_twisted_ok": bool, "seconds": s}`` and
the exit status is 1 when a check fails.

Everything is generated from ``numpy.random.default_rng`` seeded with ``S``
(each kind draws from its own stream ``default_rng([S, KIND_INDEX])`` where
KIND_INDEX is the kind's position in ``KINDS`` below, so the solids of one
kind do not depend on which other kinds are selected; kinds added later are
appended, so older kinds keep their streams).  The output is fully
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
twistedBox    twistedangle, dx, dy, dz
              G4TwistedBox(name, twistedangle, dx, dy, dz) (half lengths);
              |twistedangle| 10..80 deg, either sign.  Exact geometry: see
              "Twisted solids" below (also for the next three).
twistedTrd    dx1, dx2, dy1, dy2, dz, twistedangle
              G4TwistedTrd(name, dx1, dx2, dy1, dy2, dz, twistedangle)
              (index 1 at z = -dz, 2 at z = +dz).
twistedTrap   twistedangle, dz, theta, phi, dy1, dx1, dx2, dy2, dx3, dx4,
              alpha
              G4TwistedTrap(name, twistedangle, dz, theta, phi, dy1, dx1,
              dx2, dy2, dx3, dx4, alpha) (the general constructor): dx1 /
              dx2 are the half x lengths of the edges at y = -dy1 / +dy1
              (z = -dz), dx3 / dx4 those at y = -dy2 / +dy2 (z = +dz).
              theta < 19 deg; either dx1 == dx2 and dx3 == dx4, or
              (dx1 - dx2) * dy2 == (dx3 - dx4) * dy1 exactly (1/64 mm grid);
              every fourth solid has theta = phi = alpha = 0.
genericTrap   dz, vertices: [[x, y] x 8]
              G4GenericTrap(name, dz, vertices): vertices 0-3 at z = -dz,
              4-7 at z = +dz, vertex k + 4 above vertex k; each quadruple
              is CLOCKWISE seen from +z (Geant4's order) and convex, and so
              is every cross-section.  Variants (i % 3): planar (top =
              k * bottom + shift, exact on a 1/64 mm grid, so every lateral
              face has exactly parallel bottom and top edges: all faces
              planar), twisted (top = bottom scaled by 0.6..1.4, rotated by
              5..40 deg either way and shifted: four twisted faces), mixed
              (planar with one top vertex moved: two twisted faces).  Three
              solids in ten (i % 10 >= 7) have coincident vertices instead,
              in turn (COLLAPSED_TRAPS): a pyramid (top a point), a wedge
              (top a segment), a triangular prism or frustum (vertices j,
              j + 1 equal at both ends), one end a triangle, a twisted top
              with one vertex on its neighbour, both ends crossing
              segments (a tetrahedron); every section between the ends is
              still convex and clockwise.
xtru          polygon: [[x, y], ...],
              sections: [{"z": z, "offset": [x, y], "scale": s}, ...]
              G4ExtrudedSolid(name, polygon, [ZSection(z, offset, scale)]).
              polygon: 3..10 vertices, CLOCKWISE (negative shoelace area),
              the order Geant4 keeps (it silently reverses an anticlockwise
              polygon); shapes (i % 5): convex, L, T, star (6/8/10
              vertices), random star-shaped (5..10); simple, no three
              vertices nearly collinear.  sections: 2..4, z strictly
              increasing; the cross-section at z_k is
              scale_k * polygon + offset_k, and between two sections scale
              and offset are linear in z (so the sides are planar
              quadrilaterals; checked with Inside on 12000 points).  Every
              third solid (i % 3 == 0) is a right prism: 2 sections,
              scale 1, offset [0, 0].
tessellated   facets: [[[x,y,z], [x,y,z], [x,y,z]], ...]
              G4TessellatedSolid with one G4TriangularFacet(a, b, c,
              ABSOLUTE) per facet, then SetSolidClosed(true).  Each facet is
              COUNTER-CLOCKWISE seen from outside: its outward normal is
              (b - a) x (c - a) (Geant4's convention: SurfaceNormal equals
              it; a reversed mesh gets a "negative cubic volume" warning
              and an inverted Inside).  Closed, non-self-intersecting,
              generally non-convex star-shaped meshes of 80 or 320 facets
              (see gen_tessellated); shared vertices are bit-identical.
genericPolycone  sphi, dphi, r:[...], z:[...]
              G4GenericPolycone(name, sphi, dphi, numRZ, r, z): the (r, z)
              corner polygon revolved about z over [sphi, sphi + dphi].
              Polygons (see _rz_polygon): 5-11 corners, either orientation,
              simple and well conditioned (_rz_polygon_ok), generally
              non-convex: random walks up the outside and down the inside,
              walks with a tooth hanging down (z slabs crossed by four
              edges), star shapes; about half of them have corners on the
              axis (r = 0 exactly).
genericPolyhedra  sphi, dphi, numside, r:[...], z:[...]
              G4Polyhedra(name, sphi, dphi, numside, numRZ, r, z) (the
              rz-corner constructor): the same polygons swept around a
              regular polygon.  Unlike the z-plane constructor, r is the
              distance from the axis to the polygon's CORNERS (the side
              planes lie at r cos(dphi / numside / 2)); see self_check().
twistedTubs   twistedangle, endinnerrad, endouterrad, halfzlen, dphi
              G4TwistedTubs(name, twistedangle, endinnerrad, endouterrad,
              halfzlen, dphi); |twistedangle| 10..80 deg either sign,
              0.3 <= dphi <= 3 (< pi, see the quirks); exact geometry in
              "Twisted tubes" below.
============  ===============================================================

Boolean specs (kind ``boolean``, trees of depth 1..4)::

    {"type": "union"|"subtraction"|"intersection",
     "a": SPEC, "b": SPEC,
     "rotation": [[r00,r01,r02],[r10,r11,r12],[r20,r21,r22]],
     "translation": [x, y, z]}

Leaves are box, orb, tubs, cons, sphere, torus or trd (sphere leaves never
have pi < dphi < 2 pi, see gen_leaf); the twisted, genericTrap and
tessellated kinds are never boolean operands.  Rotation entries are
f64 (identity, signed axis permutations, or arbitrary); translations are
float32-representable.

Kind ``xtruBoolean``: one boolean node (same spec form) with extruded
solids as operands (gen_xtru_boolean), by solid index i % 4: the union of
two xtru solids, an xtru minus a box, the intersection of two xtru solids,
and a box minus an xtru.  The second operand is placed like a boolean's
(random rotation, translated near the middle of the first one's bounding
box); solids with less than 2% of their bounding box inside are redrawn.

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
                   "flagged_missed", "flagged_formula", "g4_warnings",
                   "total_seconds"}:
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
                   for more); bit 3 (8), twistedBox, twistedTrd,
                   twistedTrap, genericTrap and twistedTubs only: the exact
                   formula ("Twisted solids", "Twisted tubes") puts a point
                   of the ray before d (inside the bounding box) more than
                   1e-6 * (1 + size) mm on the other side of the surface
                   (256 vectorised samples, then 4 rounds of zooming in on
                   the sample closest to the other side; see
                   formula_missed).  Flagged answers are Geant4
                   bugs (seen with 11.4: G4Hype::DistanceToIn reporting hits
                   on the hyperboloids beyond |z| = dz, or missing entries,
                   for ~0.1% of rays; G4VTwistedFaceted missing lateral
                   faces on rays exactly parallel to z, ~0.5% of twistedBox
                   rays); compare only unflagged rays.
``origin_distance.npy`` float64 (N,): for the twisted kinds and genericTrap,
                   the distance of the origin to the surface measured in the
                   plane z = const (an upper bound of the 3D distance), from
                   the exact section formulas below; for twistedTubs the
                   first-order 3D estimate |twisted_tubs_signed_distance|
                   (about the distance inside and near a face, at most the
                   distance outside); NaN for other kinds.
                   Lets a comparison with a tessellated approximation set
                   aside origins within its tolerance band of the surface.
``geant4.log``     whatever Geant4 printed (G4cout and G4cerr).

stdout gets exactly one JSON line on success:
``{"solids": n, "rays": n, "seconds": total_wall_time}``.

Geant4's own unit-test cases (``--out DIR --cases FILE``)
-------------------------------------------------------
Instead of random solids, answers the rays of a case file
(``tests/data/geant4_unit_cases.json``: ``{"format":
"hytrace-geant4-unit-cases", "families": [{"family", "source", "solids":
[SPEC...], "rays": [[solid, ox, oy, oz, dx, dy, dz], ...]}]}``, the start
points and directions of Geant4's testG4*.cc solid tests) with Geant4's
navigator, as a run would meet them: each solid is placed alone (identity)
in a world box far larger than it, a fresh ``LocateGlobalPointAndSetup``
with the ray's direction locates the origin (a surface origin goes into the
solid when the ray enters it) and ``ComputeStep`` gives the distance to the
next boundary; after a zero step (the navigator does not always take the
direction into account) it relocates across the boundary and steps again, as
G4Transportation does.  A step that ends on the world box is kInfinity.
Each step is then checked against the solid's own ``Inside()`` along the ray
(``Interior``: membership of the interior, kSurface counting as outside, so
a ray that runs along a face it starts on never enters, and the origin's
side is the first side the ray reaches); where the step contradicts it, the
first membership change found by sampling ``Inside()`` and bisecting is the
second judge's reference.  Writes

``unit_expected.npy``  float64 (N, 4), rays in file order: the navigator's
                   step (inf: none), where the navigator located the origin
                   (0 world, 2 solid), ``Inside()`` at the origin (0, 1, 2),
                   and the second judge's distance (NaN where the step
                   agrees with ``Inside()``; see ``unit_flags.npy``).
``unit_flags.npy`` int32 (N,): FLAG_INCONSISTENT where it does not;
                   FLAG_TOLERANCE where the origin is within Geant4's
                   angular tolerance of a phi plane but outside it by an
                   exact computation (``phi_plane_entry``), the navigator
                   taking it for the surface: the exact entry is the
                   reference there.

stdout: ``{"families": n, "rays": n}``.

Twisted solids: exact geometry
------------------------------
Established numerically with Geant4 11.4 (``--describe-twisted``, see
``describe_twisted()``; ``twisted_cross_section()`` and
``twisted_signed_distance()`` implement the formulas).

G4TwistedBox, G4TwistedTrd, G4TwistedTrap (all G4VTwistedFaceted) reduce
to the general parameters (tw, dz, theta, phi, dy1, dx1, dx2, dy2, dx3,
dx4, alpha)::

    twistedBox  (tw, dx, dy, dz)  -> (tw, dz, 0, 0, dy, dx, dx, dy, dx, dx, 0)
    twistedTrd  (dx1, dx2, dy1, dy2, dz, tw)
                -> (tw, dz, 0, 0, dy1, dx1, dx1, dy2, dx2, dx2, 0)
    twistedTrap its own parameters

For -dz <= z <= dz let u = (z + dz) / (2 dz) and::

    a(z) = dx1 + (dx3 - dx1) u     half x length of the edge at y' = -b
    c(z) = dx2 + (dx4 - dx2) u     half x length of the edge at y' = +b
    b(z) = dy1 + (dy2 - dy1) u     half y length
    t    = tan(alpha)

    local section, counter-clockwise (the untilted G4Trap section):
    A0 = (-a - b t, -b)   A1 = (a - b t, -b)   A2 = (c + b t, b)
    A3 = (-c + b t, b)

    section at height z:
    P_k(z) = R(phi(z)) A_k(z) + z tan(theta) (cos phi, sin phi)
    phi(z) = tw * z / (2 dz)

R(w) is the counter-clockwise rotation by w about +z, so the section turns
counter-clockwise (seen from +z) with increasing z for tw > 0: -tw/2 at the
bottom, 0 at z = 0, +tw/2 at the top.  alpha shears the local section
(x' += y' tan alpha) before the rotation; the theta/phi offset is applied
AFTER the rotation (it is not rotated: the section centre stays on the
straight line z tan(theta) (cos phi, sin phi), as in G4Trap).  The solid is
the union over |z| <= dz of the convex quadrilaterals P_0..P_3(z) (this is
what G4VTwistedFaceted::Inside evaluates); the end caps are the flat
sections at z = -dz and z = +dz.  Lateral face k (k = 0..3, P_4 = P_0) is
exactly the ruled surface swept by the straight segment P_k(z) P_k+1(z),
z from -dz to dz: face 0 is the -y' side, 1 the +x' side, 2 the +y' side,
3 the -x' side.  The vertices P_k(z) move on helix-like curves (turning
with phi(z)), not on straight lines, so the faces are not bilinear
patches; their straight rulings are the segments in the planes z = const.

G4GenericTrap: with v_0..v_7 the vertices as given (clockwise), the section
at height z is the quadrilateral (clockwise)::

    P_k(z) = v_k + (v_k+4 - v_k) (z + dz) / (2 dz),   k = 0..3

i.e. each lateral edge is the straight segment from v_k at z = -dz to
v_k+4 at z = +dz, and lateral face k (between P_k and P_k+1) is swept by
the straight segment P_k(z) P_k+1(z): the bilinear patch (hyperbolic
paraboloid) through v_k, v_k+1, v_k+5, v_k+4 (k + 1 taken mod 4: face 3
joins v_3, v_0, v_4, v_7), a plane when its bottom and top edges are
parallel.  Geant4 classifies a point by the four half-planes
of the section's directed edges (inside = to the right of every edge), so
this is the polygon only for convex sections (all generated ones are).

Evidence (``--describe-twisted``, 8 generated solids per kind):
classification of 16000 points per kind (half uniform in the enlarged
bounding box, half within 2% of the size around the formula's lateral
surface): 0 disagreements with Geant4's Inside for all four kinds, while
the wrong candidates disagree at many points: rotation sign flipped
3972 / 3208 / 3340 points (twistedBox / twistedTrd / twistedTrap), rotation
starting at 0 at the bottom 4355 / 3512 / 3790, x and y swapped
5160 / 4714 (box / trd), theta/phi offset rotated with the section 433,
alpha sign flipped 1599, dx1/dx2 exchanged 1184 (twistedTrap), vertices
interpolated in polar coordinates 792 (genericTrap).  The boundary found by
bisecting Geant4's Inside along 1600 rays per kind is within 5.0e-10 mm
(5.8e-10 for genericTrap) of the formula's surface, i.e. at Geant4's half
surface tolerance; the hit points of Geant4's DistanceToIn / DistanceToOut
(about 3000 per kind) lie within 1e-13 mm of it, so the distance functions
use the same surfaces; 1600 points per kind on the straight segments
P_k(z) P_k+1(z) are kSurface, and 1e-6 * (1 + size) mm off them in the plane
z = const kOutside (outward) / kInside (inward).  In the default run
(seed 1, 20 x 500) the finite distance of every unflagged ray of the four
kinds ends within 3.4e-13 mm of the formula's surface, with the formula
putting the ray on the origin's side 1e-6 mm before and on the other side
1e-6 mm after it (checked offline); bit 3 of ray_flags checks that the
formula finds no earlier crossing.

Twisted tubes: exact geometry
-----------------------------
G4TwistedTubs(tw, e_in, e_out, dz, dphi), established numerically with
Geant4 11.4 (``--describe-twisted``, ``describe_twisted_tubs()``;
``twisted_tubs_signed_distance()`` implements it).  With
kappa = tan(tw / 2) / dz and the waist radii r_in = e_in cos(tw / 2),
r_out = e_out cos(tw / 2), the solid is the image of the box
|a| <= dphi / 2, r_in <= x <= r_out, |z| <= dz under::

    (a, x, z) -> R(a) (x, kappa x z, z)

(R(a) the counter-clockwise rotation about +z).  So the cross-section at
height z is the annular sector between the one-sheet hyperboloids
rho = r_in,out sqrt(1 + (kappa z)^2) (radius e_in,out at both ends, the
waist at z = 0) over the phi range atan(kappa z) -+ dphi / 2: centred on
phi = 0 at z = 0 and turned by -+tw / 2 at z = -+dz, counter-clockwise
with z for tw > 0, NOT linearly in z (atan(kappa z), the rotation of a
straight line).  Every line a, x = const is straight in 3D: the rulings of
the hyperboloids (x = r_in, r_out) and the edges of the two side faces
a = -+dphi / 2, which are hyperbolic paraboloids y' = kappa x' z in the frame
turned by a (ruled by the radial segments at z = const); the end caps are
flat annular sectors.

Evidence (``--describe-twisted``, 8 generated solids): 0 of 16000 points
(half uniform in the enlarged bounding box, half within 2% of the size
around the lateral faces) classified differently from Geant4's Inside,
while the wrong candidates disagree at many: rotation linear in z
(tw z / (2 dz)) 221, rotation sign flipped 3217, sector [0, dphi] instead
of centred 4144, waists equal to the end radii 2151, cylinders 1536.  The
boundary found by bisecting Inside along 1600 rays is within 4.1e-8 mm of
the formula's surface (Geant4's twisted-surface tolerance band is wider than
its half surface tolerance), the 2952 hit points of DistanceToIn /
DistanceToOut within 2.1e-11 mm, and 1600 points on the lateral faces are
kSurface, 1e-6 * (1 + size) mm outward kOutside, inward kInside.

Geant4 quirks handled here
--------------------------
* geant4_pybind 0.1.3 binds the ``const G4double*`` array arguments of
  G4Polycone / G4Polyhedra / G4GenericPolycone as a single float, so these
  solids cannot be built directly from Python.  They are built by writing a
  GDML file (``<polycone>`` / ``<polyhedra>`` with ``<zplane>`` entries,
  ``<genericPolycone>`` / ``<genericPolyhedra>`` with ``<rzpoint>``
  entries, read with G4GDMLParser without schema validation), which calls
  exactly those constructors (the rz-corner one for genericPolyhedra); the
  solids are then fetched from G4SolidStore.
* G4TwistedTubs (11.4) with dphi > pi is not a segment of opening dphi: its
  Inside keeps the points inside both side surfaces' half-spaces, i.e. the
  segment of opening 2 pi - dphi (0 disagreements with that reading against
  hundreds with the dphi one at dphi = 3.2 .. 4.0); generated dphi stay
  below pi.  endinnerrad = 0 is fatal.
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
* G4VTwistedFaceted (11.4) with theta = 0: rays exactly parallel to z
  (axis family +-z) sometimes miss the twisted lateral faces (DistanceToIn
  answers kInfinity although the ray enters, DistanceToOut kInfinity from
  inside); tilting the direction by 1e-12 avoids it.  About 0.5% of all
  twistedBox rays (6% of its +-z rays), a few per 10^4 for twistedTrd and
  twistedTrap; flagged (bits 1, 2, 3: some of the inside intervals are too
  short for 16 Inside() samples, hence the formula check of bit 3).
* G4GenericTrap::DistanceToIn (11.4) misses the entry of some rays into
  some twisted solids (answers kInfinity): 10 of 10^5 genericTrap rays over
  seeds 7 and 8 (100 solids each), all on one twisted solid with an
  elongated bottom; flagged (bits 2 and 3).
* G4VTwistedFaceted aborts for |twistedangle| >= 90 deg, theta >= 90 deg,
  |alpha| >= 90 deg, any half length <= 2e-9 mm, when only one end of a
  twistedTrap is rectangular-like (dx1 == dx2 xor dx3 == dx4), or when
  dy2 != dy1 (dx3 - dx4) / (dx1 - dx2) by more than 1e-9 mm (planarity of
  the untwisted shape).
* G4GenericTrap wants clockwise vertex quadruples: anticlockwise ones are
  re-ordered (v1 <-> v3, v5 <-> v7) with a GeomSolids1001 warning; bottom
  and top in opposite orientations, non-convex quadruples, more than one
  collapsed edge or a lateral face twisted by more than 90 degrees are
  fatal.  Coincident vertices are fine (consecutive vertices equal at both
  ends, a lateral face collapsed to a line, at most once); with both ends
  of no area nothing tells the direction, and anticlockwise vertices then
  give a negative volume: "Degenerated solid", fatal.
* G4ExtrudedSolid silently reverses an anticlockwise polygon, removes
  collinear or coincident vertices with a warning, and aborts ("Making
  facets failed") when its ear clipping meets three collinear vertices
  (e.g. a T whose two arms have the same thickness: the four vertices under
  the bar are collinear), so the generator rejects polygons with any three
  nearly collinear vertices.
* geant4_pybind 0.1.3 binds G4TessellatedSolid::DistanceToOut(p, v) only
  with all five arguments (no defaults); the G4VSolid binding is used
  instead (same virtual function).  AddFacet takes ownership of the facet.
* geant4_pybind 0.1.3 segfaults when twisted or extruded solids are only
  destroyed at interpreter shutdown; all solids live in the Builder inside
  run(), and an unexpected exception ends the process with os._exit(1)
  after printing its traceback.
"""

import argparse
import json
import math
import os
import sys
import tempfile
import time
import traceback

import numpy as np

FORMAT = "hytrace-geant4-oracle"
VERSION = 1

# Order matters: a kind's index seeds its random stream.
KINDS = [
    "box", "orb", "sphere", "tubs", "cutTubs", "cons", "torus", "trd",
    "trap", "para", "polycone", "polyhedra", "hype", "paraboloid",
    "ellipsoid", "eltube", "elcone", "tet", "boolean",
    "twistedBox", "twistedTrd", "twistedTrap", "genericTrap", "xtru",
    "tessellated", "genericPolycone", "genericPolyhedra", "twistedTubs",
    "xtruBoolean",
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
FLAG_FORMULA = 8        # twisted kinds: the exact cross-section formula
                        # finds a crossing before Geant4's distance
FLAG_TOLERANCE = 16     # --cases: an origin Geant4 calls kSurface is outside
                        # a phi plane by an exact computation, and the ray
                        # enters through it (phi_plane_entry)
# Samples per ray of the FLAG_FORMULA check (vectorised, plus zooming in on
# the sample closest to the other side); G4VTwistedFaceted (11.4) misses the
# lateral faces for some rays exactly parallel to z, and 16 Inside() samples
# do not catch the short inside intervals of such rays.
FORMULA_SAMPLES = 256
# Inside() samples along each ray (inside the bounding box) used to detect
# crossings that Geant4's distance skipped.  G4Hype (11.4) misses entries for
# some rays and G4IntersectionSolid::DistanceToIn can skip a valid range (see
# the module doc), so those kinds are always checked; --march N extends the
# check to every kind.
MARCH_SAMPLES = {"hype": 32, "boolean": 32, "torus": 32, "xtruBoolean": 32}
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


# --- twisted and tessellated kinds (never boolean operands) ----------------

_GRID = 1.0 / 64.0  # dyadic grid: sums, differences and products by the
                    # ratios used below stay exact in float32 and float64


def _on_grid(x):
    return max(_GRID, round(x / _GRID) * _GRID)


def _on_grid_signed(x):
    return round(float(x) / _GRID) * _GRID


def _twist_angle(rng):
    """Twist angle of 10..80 degrees, either sign (Geant4 needs < 90)."""
    a = math.radians(rng.uniform(10.0, 80.0))
    return f32(a if rng.uniform() < 0.5 else -a)


def gen_twisted_box(rng, i, s):
    return {"type": "twistedBox", "twistedangle": _twist_angle(rng),
            "dx": f32(s * rng.uniform(0.2, 1.0)),
            "dy": f32(s * rng.uniform(0.2, 1.0)),
            "dz": f32(s * rng.uniform(0.2, 1.0))}


def gen_twisted_trd(rng, i, s):
    return {"type": "twistedTrd", "dx1": f32(s * rng.uniform(0.1, 1.0)),
            "dx2": f32(s * rng.uniform(0.1, 1.0)),
            "dy1": f32(s * rng.uniform(0.1, 1.0)),
            "dy2": f32(s * rng.uniform(0.1, 1.0)),
            "dz": f32(s * rng.uniform(0.2, 1.0)),
            "twistedangle": _twist_angle(rng)}


def gen_twisted_trap(rng, i, s):
    # G4VTwistedFaceted aborts unless either dx1 == dx2 and dx3 == dx4, or
    # dy2 == dy1 * (dx3 - dx4) / (dx1 - dx2) to 1e-9 mm (planar endcaps of
    # the untwisted shape).  As in gen_trap the half lengths live on a dyadic
    # grid where dx3 - dx4 == ratio * (dx1 - dx2) and dy2 == ratio * dy1 hold
    # exactly.  Variant 1 has rectangular-like ends (dx1 == dx2, dx3 == dx4).
    v = i % 4
    while True:
        dy1 = _on_grid(s * rng.uniform(0.2, 1.0))
        ratio = float(rng.choice([0.5, 0.75, 1.0, 1.25, 1.5, 2.0]))
        dy2 = dy1 * ratio
        dx1 = _on_grid(s * rng.uniform(0.15, 1.0))
        dx2 = dx1 if v == 1 else _on_grid(s * rng.uniform(0.15, 1.0))
        dx3 = _on_grid(s * rng.uniform(0.15, 1.0))
        dx4 = dx3 + ratio * (dx2 - dx1)
        if dx4 < 0.1 * s or dx4 < 0.5:
            continue
        break
    for x in (dy1, dy2, dx1, dx2, dx3, dx4):
        assert f32(x) == x
    assert (dx3 - dx4) * dy1 == (dx1 - dx2) * dy2
    assert (dx1 == dx2) == (dx3 == dx4)
    theta = f32(rng.uniform(0.0, math.radians(19.0)))
    phi = f32(rng.uniform(-PI, PI))
    alpha = f32(rng.uniform(-0.45, 0.45))
    if v == 3:  # no tilt at all
        theta, phi, alpha = 0.0, 0.0, 0.0
    return {"type": "twistedTrap", "twistedangle": _twist_angle(rng),
            "dz": f32(s * rng.uniform(0.2, 1.0)), "theta": theta,
            "phi": phi, "dy1": dy1, "dx1": dx1, "dx2": dx2, "dy2": dy2,
            "dx3": dx3, "dx4": dx4, "alpha": alpha}


def _cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _polygon_area(poly):
    """Signed (shoelace) area: > 0 for a counter-clockwise polygon."""
    p = np.asarray(poly, dtype=np.float64)
    return 0.5 * float(np.sum(_cross2(p, np.roll(p, -1, axis=0))))


def _strictly_convex_cw(quad, margin):
    """All turns of the closed polygon clockwise by more than margin."""
    q = np.asarray(quad, dtype=np.float64)
    e = np.roll(q, -1, axis=0) - q
    return bool(np.all(_cross2(e, np.roll(e, -1, axis=0)) < -margin))


# Variants of gen_generic_trap with coincident vertices, in turn.
COLLAPSED_TRAPS = ["pyramid", "wedge", "prism", "triangle", "twisted",
                   "segments"]


def gen_generic_trap(rng, i, s):
    # Geant4 wants each end polygon convex and clockwise (an anticlockwise
    # pair is re-ordered with a warning); vertex k + 4 is joined to vertex k.
    if i % 10 >= 7:  # 3 solids in 10 have coincident vertices
        c = (i % 10 - 7 + 3 * (i // 10)) % len(COLLAPSED_TRAPS)
        return _gen_collapsed_trap(rng, COLLAPSED_TRAPS[c], s)
    v = ["planar", "twisted", "mixed"][i % 3]
    dz = f32(s * rng.uniform(0.2, 1.0))
    while True:
        # clockwise quadrilateral inscribed in an ellipse (strictly convex)
        ang = np.sort(rng.uniform(0.0, TWO_PI, 4))[::-1]
        gaps = np.diff(np.concatenate([ang, [ang[0] - TWO_PI]]))
        if np.any(-gaps < 0.6) or np.any(-gaps > PI - 0.3):
            continue
        ax, by = s * rng.uniform(0.3, 1.0), s * rng.uniform(0.3, 1.0)
        c = s * rng.uniform(-0.2, 0.2, 2)
        bot = np.stack([c[0] + ax * np.cos(ang), c[1] + by * np.sin(ang)], 1)
        bot = np.vectorize(_on_grid_signed)(bot)
        if v == "twisted":
            rot = math.radians(rng.uniform(5.0, 40.0)) * rng.choice([-1, 1])
            k = rng.uniform(0.6, 1.4)
            cr, sr = math.cos(rot), math.sin(rot)
            R = np.array([[cr, -sr], [sr, cr]])
            top = (k * bot) @ R.T + s * rng.uniform(-0.25, 0.25, 2)
            top = np.vectorize(f32)(top)
        else:
            # top = k * bottom + shift, exactly on the grid, so that every
            # lateral face is exactly planar (parallel bottom/top edges)
            k = float(rng.choice([0.5, 0.75, 1.0, 1.25, 1.5]))
            shift = np.vectorize(_on_grid_signed)(
                s * rng.uniform(-0.25, 0.25, 2))
            top = k * bot + shift
            if v == "mixed":  # move one top vertex: its two faces twist
                j = int(rng.integers(4))
                top[j] = top[j] + np.vectorize(_on_grid_signed)(
                    s * rng.uniform(-0.2, 0.2, 2))
        size2 = float(np.max(np.abs(np.concatenate([bot, top])))) ** 2
        # every cross-section (linear interpolation) must stay convex and
        # clockwise: Geant4's Inside assumes a convex section
        ok = all(_strictly_convex_cw((1.0 - t) * bot + t * top,
                                     1e-3 * size2)
                 for t in np.linspace(0.0, 1.0, 33))
        # Geant4 aborts when a lateral face twists by more than 90 degrees
        # (angle between its bottom and top edges); keep well below
        eb = np.roll(bot, -1, axis=0) - bot
        et = np.roll(top, -1, axis=0) - top
        cosang = np.einsum("ij,ij->i", eb, et) / (
            np.linalg.norm(eb, axis=1) * np.linalg.norm(et, axis=1))
        ok = ok and bool(np.all(cosang > math.cos(math.radians(60.0))))
        if ok and all(f32(x) == x for x in np.concatenate([bot, top]).flat):
            break
    verts = [[float(x), float(y)] for x, y in np.concatenate([bot, top])]
    return {"type": "genericTrap", "dz": dz, "vertices": verts}


def _cw_quad(rng, s):
    """Clockwise quadrilateral inscribed in an ellipse, on the 1/64 grid, or
    None when its corners are too close in angle."""
    ang = np.sort(rng.uniform(0.0, TWO_PI, 4))[::-1]
    gaps = np.diff(np.concatenate([ang, [ang[0] - TWO_PI]]))
    if np.any(-gaps < 0.6) or np.any(-gaps > PI - 0.3):
        return None
    ax, by = s * rng.uniform(0.3, 1.0), s * rng.uniform(0.3, 1.0)
    c = s * rng.uniform(-0.2, 0.2, 2)
    quad = np.stack([c[0] + ax * np.cos(ang), c[1] + by * np.sin(ang)], 1)
    return np.vectorize(_on_grid_signed)(quad)


def _convex_cw_or_flat(quad, size):
    """The polygon without its repeated corners (within 1e-12 of size) is
    clockwise with every turn sharper than 1e-3 rad, or has fewer than three
    corners (a segment or a point)."""
    q = [p for k, p in enumerate(np.asarray(quad, dtype=np.float64))
         if np.linalg.norm(p - quad[k - 1]) > 1e-12 * size]
    if len(q) < 3:
        return True
    e = np.roll(np.array(q), -1, axis=0) - np.array(q)
    turns = _cross2(e, np.roll(e, -1, axis=0))
    lens = np.linalg.norm(e, axis=1) * np.linalg.norm(np.roll(e, -1, axis=0),
                                                      axis=1)
    return bool(np.all(turns < -1e-3 * lens))


def _g4_trap_volume(bot, top, dz):
    """G4GenericTrap::GetCubicVolume (clockwise vertices: positive)."""
    a, b = bot[3] - bot[1], bot[2] - bot[0]
    c, d = top[3] - top[1], top[2] - top[0]
    return ((_cross2(a, b) + _cross2(c, d)) / 3.0 +
            (_cross2(a, d) + _cross2(c, b)) / 6.0) * dz


def _gen_collapsed_trap(rng, variant, s):
    """A genericTrap with coincident vertices (Geant4 allows them as long
    as at most one lateral edge collapses at both ends and the solid has
    volume): "pyramid" (top a point), "wedge" (top a segment), "prism"
    (vertices j and j + 1 equal at both ends: a triangular prism or
    frustum), "triangle" (one end a triangle, the other a quadrilateral),
    "twisted" (twisted top with one top vertex on its neighbour) and
    "segments" (both ends segments, crossing: a tetrahedron).  Every
    section between the ends is convex and clockwise, the twisted faces
    turn by less than 60 degrees."""
    dz = f32(s * rng.uniform(0.2, 1.0))
    grid = np.vectorize(_on_grid_signed)
    while True:
        quad = _cw_quad(rng, s)
        if quad is None:
            continue
        j = int(rng.integers(4))
        nxt = [(j + k) % 4 for k in range(4)]  # j, j+1, j+2, j+3
        k = float(rng.choice([0.5, 0.75, 1.0, 1.25]))
        shift = grid(s * rng.uniform(-0.25, 0.25, 2))
        bot = quad.copy()
        if variant == "pyramid":
            top = np.tile(grid(quad.mean(axis=0) +
                               s * rng.uniform(-0.3, 0.3, 2)), (4, 1))
        elif variant == "wedge":
            # ridge between the midpoints of edges j and j + 2, pulled in
            m1 = 0.5 * (quad[nxt[0]] + quad[nxt[1]])
            m2 = 0.5 * (quad[nxt[2]] + quad[nxt[3]])
            cen = quad.mean(axis=0)
            u = rng.uniform(0.3, 1.0)
            top = np.empty((4, 2))
            top[nxt[0]] = top[nxt[1]] = grid(cen + u * (m1 - cen) + shift)
            top[nxt[2]] = top[nxt[3]] = grid(cen + u * (m2 - cen) + shift)
        elif variant == "prism":
            bot[nxt[1]] = bot[nxt[0]]
            top = k * bot + shift
        elif variant == "triangle":
            bot[nxt[1]] = bot[nxt[0]]
            top = k * quad + shift
            if rng.uniform() < 0.5:  # the triangle at the top instead
                bot, top = top, bot
        elif variant == "twisted":
            rot = math.radians(rng.uniform(5.0, 35.0)) * rng.choice([-1, 1])
            cr, sr = math.cos(rot), math.sin(rot)
            top = (k * quad) @ np.array([[cr, sr], [-sr, cr]]) + shift
            top = np.vectorize(f32)(top)
            top[nxt[1]] = top[nxt[0]]
        else:  # "segments": both ends segments, crossing
            a = rng.uniform(0.0, PI)
            da = rng.uniform(0.5, PI - 0.5)
            r1, r2 = s * rng.uniform(0.3, 1.0, 2)
            cen = s * rng.uniform(-0.2, 0.2, 2)
            d1 = r1 * np.array([math.cos(a), math.sin(a)])
            d2 = r2 * np.array([math.cos(a + da), math.sin(a + da)])
            bot = grid(np.array([cen - d1, cen - d1, cen + d1, cen + d1]))
            top = grid(np.array([cen - d2 + shift, cen + d2 + shift,
                                 cen + d2 + shift, cen - d2 + shift]))
            if _g4_trap_volume(bot, top, dz) < 0.0:
                top = top[[1, 0, 3, 2]]
        size = float(np.max(np.abs(np.concatenate([bot, top]))))
        ok = all(_convex_cw_or_flat((1.0 - t) * bot + t * top, size)
                 for t in np.linspace(0.0, 1.0, 33))
        ok = ok and _g4_trap_volume(bot, top, dz) > 0.05 * size * size * dz
        # twisted faces (both edges non-zero) turn by less than 60 degrees
        eb = np.roll(bot, -1, axis=0) - bot
        et = np.roll(top, -1, axis=0) - top
        lb, lt = np.linalg.norm(eb, axis=1), np.linalg.norm(et, axis=1)
        both = (lb > 0.0) & (lt > 0.0)
        cosang = np.einsum("ij,ij->i", eb, et)[both] / (lb * lt)[both]
        ok = ok and bool(np.all(cosang > math.cos(math.radians(60.0))))
        if ok and all(f32(x) == x for x in np.concatenate([bot, top]).flat):
            break
    verts = [[float(x), float(y)] for x, y in np.concatenate([bot, top])]
    return {"type": "genericTrap", "dz": dz, "vertices": verts}


def _xtru_polygon(rng, shape, r):
    """Clockwise polygon (list of [x, y]) of the given shape, size ~r."""
    if shape == "convex":
        n = int(rng.integers(3, 9))
        while True:
            ang = np.sort(rng.uniform(0.0, TWO_PI, n))
            gaps = np.diff(np.concatenate([ang, [ang[0] + TWO_PI]]))
            if np.all(gaps > 0.35) and np.all(gaps < PI - 0.2):
                break
        rad = r * np.ones(n)
        pts = np.stack([rad * np.cos(ang), rad * rng.uniform(0.5, 1.0) *
                        np.sin(ang)], 1)
    elif shape == "L":
        w, h = r * rng.uniform(1.0, 2.0), r * rng.uniform(1.0, 2.0)
        tx, ty = w * rng.uniform(0.2, 0.6), h * rng.uniform(0.2, 0.6)
        pts = np.array([[0, 0], [w, 0], [w, ty], [tx, ty], [tx, h], [0, h]])
        pts = pts - np.array([0.4 * w, 0.4 * h])
    elif shape == "T":
        # The two arms have different thicknesses: with equal ones the four
        # vertices under the bar are collinear, and Geant4's ear clipping
        # can then cut a degenerate triangle and abort ("Making facets
        # failed").
        w, h = r * rng.uniform(1.2, 2.0), r * rng.uniform(1.0, 2.0)
        sw = w * rng.uniform(0.15, 0.5)
        th1, th2 = h * rng.uniform(0.2, 0.35), h * rng.uniform(0.4, 0.55)
        if rng.uniform() < 0.5:
            th1, th2 = th2, th1
        x0 = rng.uniform(0.1, 0.9) * (w - sw) - 0.5 * w  # stem position
        pts = np.array([[x0, 0], [x0 + sw, 0], [x0 + sw, h - th2],
                        [0.5 * w, h - th2], [0.5 * w, h], [-0.5 * w, h],
                        [-0.5 * w, h - th1], [x0, h - th1]])
        pts = pts - np.array([0.0, 0.6 * h])
    elif shape == "star":
        k = int(rng.integers(3, 6))  # 6, 8 or 10 vertices
        ang = np.arange(2 * k) * (PI / k)
        rad = np.where(np.arange(2 * k) % 2 == 0, r,
                       r * rng.uniform(0.3, 0.6))
        rad = rad * rng.uniform(0.85, 1.0, 2 * k)
        pts = np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1)
    else:  # random star-shaped (non-convex in general) polygon
        n = int(rng.integers(5, 11))
        while True:
            ang = np.sort(rng.uniform(0.0, TWO_PI, n))
            gaps = np.diff(np.concatenate([ang, [ang[0] + TWO_PI]]))
            if np.all(gaps > 0.3) and np.all(gaps < PI - 0.2):
                break
        rad = r * rng.uniform(0.35, 1.0, n)
        pts = np.stack([rad * np.cos(ang), rad * np.sin(ang)], 1)
    a = rng.uniform(-PI, PI)
    R = np.array([[math.cos(a), -math.sin(a)], [math.sin(a), math.cos(a)]])
    pts = pts @ R.T + r * rng.uniform(-0.2, 0.2, 2)
    pts = np.vectorize(f32)(pts)
    if _polygon_area(pts) > 0.0:
        pts = pts[::-1]
    return pts


def _polygon_ok(pts, r):
    """No edge shorter than 5% of r, no three (nearly) collinear vertices
    and no self-intersection.  Geant4 drops collinear consecutive vertices
    with a warning, its ear clipping aborts when it meets a degenerate
    triangle (three collinear vertices, consecutive once the ears between
    them are cut), and a self-intersecting polygon cannot be triangulated."""
    n = len(pts)
    for k in range(n):
        if np.linalg.norm(pts[(k + 1) % n] - pts[k]) < 0.05 * r:
            return False
    for a in range(n):
        for b in range(a + 1, n):
            for c in range(b + 1, n):
                ab, ac = pts[b] - pts[a], pts[c] - pts[a]
                if abs(float(_cross2(ab, ac))) < 0.02 * np.linalg.norm(ab) \
                        * np.linalg.norm(ac):
                    return False
    for k in range(n):  # edge k: pts[k] -> pts[k+1]; non-adjacent pairs
        for m in range(k + 2, n):
            if k == 0 and m == n - 1:
                continue
            p, q = pts[k], pts[(k + 1) % n]
            u, w = pts[m], pts[(m + 1) % n]
            d1 = _cross2(q - p, u - p) * _cross2(q - p, w - p)
            d2 = _cross2(w - u, p - u) * _cross2(w - u, q - u)
            if d1 <= 0 and d2 <= 0:
                return False
    return True


def gen_xtru(rng, i, s):
    shape = ["convex", "L", "T", "star", "random"][i % 5]
    r = s * rng.uniform(0.3, 0.6)
    while True:
        pts = _xtru_polygon(rng, shape, r)
        if _polygon_ok(pts, r):
            break
    prism = (i % 3 == 0)  # right prism: 2 sections, scale 1, no offset
    nsec = 2 if prism else int(rng.integers(2, 5))
    z = [f32(-s * rng.uniform(0.2, 0.8))]
    for _ in range(nsec - 1):
        z.append(f32(z[-1] + s * rng.uniform(0.15, 0.7)))
    sections = []
    for zk in z:
        if prism:
            off, sc = [0.0, 0.0], 1.0
        else:
            off = [f32(c) for c in s * rng.uniform(-0.25, 0.25, 2)]
            sc = f32(rng.uniform(0.5, 1.5))
        sections.append({"z": zk, "offset": off, "scale": sc})
    return {"type": "xtru",
            "polygon": [[float(x), float(y)] for x, y in pts],
            "sections": sections}


_ICO_CACHE = {}


def _icosphere(level):
    """Unit-sphere triangulation: (vertices (n,3), faces (m,3) int) with
    every face counter-clockwise seen from outside."""
    if level in _ICO_CACHE:
        return _ICO_CACHE[level]
    g = (1.0 + math.sqrt(5.0)) / 2.0
    verts = [[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0],
             [0, -1, g], [0, 1, g], [0, -1, -g], [0, 1, -g],
             [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]]
    verts = [list(np.array(v, float) / np.linalg.norm(v)) for v in verts]
    # faces: the 20 triangles whose edges all have the minimal length
    V = np.array(verts)
    faces = []
    for a in range(12):
        for b in range(a + 1, 12):
            for c in range(b + 1, 12):
                dd = [np.linalg.norm(V[a] - V[b]), np.linalg.norm(V[b] - V[c]),
                      np.linalg.norm(V[a] - V[c])]
                if max(dd) < 1.1:
                    faces.append([a, b, c])
    assert len(faces) == 20
    for _ in range(level):
        mid = {}
        new_faces = []

        def midpoint(a, b):
            key = (min(a, b), max(a, b))
            if key not in mid:
                m = np.array(verts[a]) + np.array(verts[b])
                verts.append(list(m / np.linalg.norm(m)))
                mid[key] = len(verts) - 1
            return mid[key]
        for a, b, c in faces:
            ab, bc, ca = midpoint(a, b), midpoint(b, c), midpoint(c, a)
            new_faces += [[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]
        faces = new_faces
    V = np.array(verts)
    F = np.array(faces)
    # orient every face outward: (b - a) x (c - a) . a > 0
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    flip = np.einsum("ij,ij->i", n, V[F[:, 0]]) < 0
    F[flip] = F[flip][:, [0, 2, 1]]
    _ICO_CACHE[level] = (V, F)
    return V, F


def gen_tessellated(rng, i, s):
    # Star-shaped polyhedron: the vertex in direction d_k of a subdivided
    # icosahedron is placed at c + A (r_k d_k), r_k random in [0.6, 1] R and
    # A = diag(ax, ay, az) a positive scaling.  Each facet stays inside the
    # cone of its three directions, so the mesh is closed, never
    # self-intersecting, generally non-convex, and keeps the outward
    # (counter-clockwise seen from outside) orientation of the icosphere.
    V, F = _icosphere(1 + i % 2)  # 80 or 320 facets
    R = s * rng.uniform(0.5, 1.0)
    rad = R * rng.uniform(0.6, 1.0, len(V))
    A = rng.uniform(0.6, 1.0, 3)
    c = s * rng.uniform(-0.2, 0.2, 3)
    P = np.vectorize(f32)(c + (V * rad[:, None]) * A)
    tri = P[F]  # (m, 3, 3)
    rel = tri - c
    det = np.einsum("ij,ij->i", rel[:, 0], np.cross(rel[:, 1], rel[:, 2]))
    assert np.all(det > 0.0)
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert np.all(np.linalg.norm(n, axis=1) > 1e-6 * R * R)
    return {"type": "tessellated",
            "facets": [[[float(x) for x in v] for v in t] for t in tri]}


# --- generic (r, z) polygon solids and twisted tubes -----------------------

def _seg_seg_distance(p, q, u, w):
    """Distance between the 2D segments pq and uw (0 when they meet)."""
    d1 = _cross2(q - p, u - p) * _cross2(q - p, w - p)
    d2 = _cross2(w - u, p - u) * _cross2(w - u, q - u)
    if d1 <= 0 and d2 <= 0:
        return 0.0

    def point_seg(a, b, c):
        e = c - b
        t = min(1.0, max(0.0, float(np.dot(a - b, e) / np.dot(e, e))))
        return float(np.linalg.norm(a - (b + t * e)))
    return min(point_seg(p, u, w), point_seg(q, u, w), point_seg(u, p, q),
               point_seg(w, p, q))


def _rz_polygon_ok(pts, s):
    """A well-conditioned simple (r, z) polygon: r >= 0, area >= 2% of s^2,
    edges of at least 3% of s, non-adjacent edges at least 2% of s apart
    (no crossing or touching), no spike (every corner angle >= 12 degrees),
    no corner within 2% of s of the axis unless exactly on it."""
    n = len(pts)
    if n < 3 or np.any(pts[:, 0] < 0.0):
        return False
    if np.any((pts[:, 0] > 0.0) & (pts[:, 0] < 0.02 * s)):
        return False
    if abs(_polygon_area(pts)) < 0.02 * s * s:
        return False
    for k in range(n):
        a, b, c = pts[k - 1], pts[k], pts[(k + 1) % n]
        e1, e2 = a - b, c - b
        l1, l2 = np.linalg.norm(e1), np.linalg.norm(e2)
        if l2 < 0.03 * s:
            return False
        cosang = float(np.dot(e1, e2) / (l1 * l2))
        if cosang > math.cos(math.radians(12.0)):
            return False
    for k in range(n):
        for m in range(k + 2, n):
            if k == 0 and m == n - 1:
                continue
            if _seg_seg_distance(pts[k], pts[(k + 1) % n], pts[m],
                                 pts[(m + 1) % n]) < 0.02 * s:
                return False
    return True


def _rz_polygon(rng, i, s):
    """A random simple (r, z) polygon (array (n, 2) of float32 values) of
    size ~s, in one of three shapes (i % 3):

    walk  a random walk of r(z) going up on the outside (3-5 corners) and
          back down on the inside (2-4 corners at other heights), inner
          corners on the axis (r = 0) with probability 0.4;
    fold  a walk whose outer side has a tooth hanging down (an edge going
          outwards and down, then back up), so some z slabs hold two
          (inner, outer) pairs of edges;
    star  star-shaped about (0.3..0.6 s, 0) with 5-9 corners, corners with
          r < 0 moved onto the axis.

    The corner order is reversed half the time and starts at a random
    corner (Geant4 accepts either orientation)."""
    shape = ["walk", "fold", "star"][i % 3]
    while True:
        if shape == "star":
            n = int(rng.integers(5, 10))
            ang = np.sort(rng.uniform(0.0, TWO_PI, n))
            gaps = np.diff(np.concatenate([ang, [ang[0] + TWO_PI]]))
            if np.any(gaps < 0.3) or np.any(gaps > PI - 0.2):
                continue
            rc = s * rng.uniform(0.3, 0.6)
            rad = s * rng.uniform(0.3, 1.0, n)
            pts = np.stack([rc + rad * np.cos(ang), rad * np.sin(ang)], 1)
            pts[:, 0] = np.maximum(pts[:, 0], 0.0)
        else:
            n_out = int(rng.integers(3, 6))
            z = -s * rng.uniform(0.3, 0.8)
            outer = []
            for _ in range(n_out):
                outer.append([s * rng.uniform(0.35, 1.0), z])
                z += s * rng.uniform(0.15, 0.6)
            z_bot, z_top = outer[0][1], outer[-1][1]
            if shape == "fold":
                # a tooth below outer corner k (1 <= k < n_out): out and
                # down, then back up to corner k
                k = int(rng.integers(1, n_out))
                lo_z = outer[k - 1][1]
                hz = outer[k][1] - lo_z
                tip = [outer[k][0] + s * rng.uniform(0.2, 0.5),
                       lo_z + hz * rng.uniform(0.1, 0.5)]
                base = [max(outer[k - 1][0], outer[k][0]) * rng.uniform(
                    0.4, 0.8), outer[k][1] - hz * rng.uniform(0.0, 0.2)]
                outer = outer[:k] + [base, tip] + outer[k:]
            n_in = int(rng.integers(2, 5))
            zs = np.sort(rng.uniform(z_bot, z_top, n_in - 2))[::-1]
            zs = [z_top] + list(zs) + [z_bot]
            r_min_out = min(p[0] for p in outer)
            inner = []
            for zk in zs:
                if rng.uniform() < 0.4:
                    inner.append([0.0, zk])
                else:
                    inner.append([r_min_out * rng.uniform(0.1, 0.7), zk])
            pts = np.array(outer + inner)
        pts = np.vectorize(f32)(pts)
        if rng.uniform() < 0.5:
            pts = pts[::-1]
        pts = np.roll(pts, -int(rng.integers(len(pts))), axis=0)
        if _rz_polygon_ok(pts, s):
            return pts


def gen_generic_polycone(rng, i, s):
    pts = _rz_polygon(rng, i, s)
    sphi, dphi = phi_range(rng, ["full", "lt", "gt"][(i // 3) % 3])
    return {"type": "genericPolycone", "sphi": sphi, "dphi": dphi,
            "r": [float(x) for x in pts[:, 0]],
            "z": [float(x) for x in pts[:, 1]]}


def gen_generic_polyhedra(rng, i, s):
    pts = _rz_polygon(rng, i, s)
    sphi, dphi = phi_range(rng, ["full", "lt", "gt"][(i // 3) % 3])
    if dphi == F32_TWO_PI and rng.uniform() < 0.5:
        sphi = f32(rng.uniform(-PI, PI))  # rotated full polyhedra
    return {"type": "genericPolyhedra", "sphi": sphi, "dphi": dphi,
            "numside": int(rng.integers(3, 9)),
            "r": [float(x) for x in pts[:, 0]],
            "z": [float(x) for x in pts[:, 1]]}


def gen_twisted_tubs(rng, i, s):
    # G4TwistedTubs treats dphi > pi as the 2 pi - dphi segment (its Inside
    # checks both side surfaces at once), so dphi stays below pi.
    eo = s * rng.uniform(0.4, 1.0)
    return {"type": "twistedTubs", "twistedangle": _twist_angle(rng),
            "endinnerrad": f32(eo * rng.uniform(0.1, 0.85)),
            "endouterrad": f32(eo), "halfzlen": f32(s * rng.uniform(0.2, 1.0)),
            "dphi": f32(rng.uniform(0.3, 3.0))}


GENERATORS = {
    "box": gen_box, "orb": gen_orb, "sphere": gen_sphere, "tubs": gen_tubs,
    "cutTubs": gen_cut_tubs, "cons": gen_cons, "torus": gen_torus,
    "trd": gen_trd, "trap": gen_trap, "para": gen_para,
    "polycone": gen_polycone, "polyhedra": gen_polyhedra, "hype": gen_hype,
    "paraboloid": gen_paraboloid, "ellipsoid": gen_ellipsoid,
    "eltube": gen_eltube, "elcone": gen_elcone, "tet": gen_tet,
    "twistedBox": gen_twisted_box, "twistedTrd": gen_twisted_trd,
    "twistedTrap": gen_twisted_trap, "genericTrap": gen_generic_trap,
    "xtru": gen_xtru, "tessellated": gen_tessellated,
    "genericPolycone": gen_generic_polycone,
    "genericPolyhedra": gen_generic_polyhedra,
    "twistedTubs": gen_twisted_tubs,
}
GDML_KINDS = ("polycone", "polyhedra", "genericPolycone", "genericPolyhedra")


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
        elif t in GDML_KINDS:
            s = self.build_gdml([spec])[0]
        elif t == "twistedBox":
            s = g4.G4TwistedBox(name, spec["twistedangle"], spec["dx"],
                                spec["dy"], spec["dz"])
        elif t == "twistedTrd":
            s = g4.G4TwistedTrd(name, spec["dx1"], spec["dx2"], spec["dy1"],
                                spec["dy2"], spec["dz"], spec["twistedangle"])
        elif t == "twistedTrap":
            s = g4.G4TwistedTrap(name, spec["twistedangle"], spec["dz"],
                                 spec["theta"], spec["phi"], spec["dy1"],
                                 spec["dx1"], spec["dx2"], spec["dy2"],
                                 spec["dx3"], spec["dx4"], spec["alpha"])
        elif t == "twistedTubs":
            s = g4.G4TwistedTubs(name, spec["twistedangle"],
                                 spec["endinnerrad"], spec["endouterrad"],
                                 spec["halfzlen"], spec["dphi"])
        elif t == "genericTrap":
            verts = g4.G4TwoVectorVector(
                [g4.G4TwoVector(float(x), float(y))
                 for x, y in spec["vertices"]])
            self.keep.append(verts)
            s = g4.G4GenericTrap(name, spec["dz"], verts)
        elif t == "xtru":
            poly = g4.G4TwoVectorVector(
                [g4.G4TwoVector(float(x), float(y))
                 for x, y in spec["polygon"]])
            zs = [g4.G4ExtrudedSolid.ZSection(
                float(sec["z"]), g4.G4TwoVector(float(sec["offset"][0]),
                                                float(sec["offset"][1])),
                float(sec["scale"])) for sec in spec["sections"]]
            self.keep += [poly, zs]
            s = g4.G4ExtrudedSolid(name, poly, zs)
        elif t == "tessellated":
            s = g4.G4TessellatedSolid(name)
            absolute = g4.G4FacetVertexType.ABSOLUTE
            for a, b, c in spec["facets"]:
                # AddFacet takes ownership of the facet (disowned in Python)
                s.AddFacet(g4.G4TriangularFacet(self.vec(a), self.vec(b),
                                                self.vec(c), absolute))
            s.SetSolidClosed(True)
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
        """Polycone/polyhedra (z-plane and rz-corner forms) through the GDML
        reader (see module doc)."""
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
            t = spec["type"]
            if t in ("polycone", "genericPolycone"):
                lines.append('<%s name="%s" startphi="%r" '
                             'deltaphi="%r" aunit="rad" lunit="mm">'
                             % (t, name, spec["sphi"], spec["dphi"]))
            else:
                lines.append('<%s name="%s" startphi="%r" '
                             'deltaphi="%r" numsides="%d" aunit="rad" '
                             'lunit="mm">' % (t, name, spec["sphi"],
                                               spec["dphi"], spec["numside"]))
            if t in ("polycone", "polyhedra"):
                for z, ri, ro in zip(spec["z"], spec["rmin"], spec["rmax"]):
                    lines.append('<zplane z="%r" rmin="%r" rmax="%r"/>'
                                 % (float(z), float(ri), float(ro)))
            else:
                for r, z in zip(spec["r"], spec["z"]):
                    lines.append('<rzpoint r="%r" z="%r"/>'
                                 % (float(r), float(z)))
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
            want = {"polycone": "G4Polycone",
                    "genericPolycone": "G4GenericPolycone"}.get(
                        spec["type"], "G4Polyhedra")
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


def gen_xtru_boolean(rng, i, s, builder):
    """One boolean node with extruded operands (kind xtruBoolean, see the
    module doc): i % 4 picks xtru + xtru, xtru - box, xtru * xtru or
    box - xtru."""
    op = ["union", "subtraction", "intersection", "subtraction"][i % 4]
    for _ in range(200):
        xa = gen_xtru(rng, int(rng.integers(0, 1000)), s)
        if i % 4 == 1:
            a, b = xa, gen_box(rng, 0, 0.5 * s)
        elif i % 4 == 3:
            a, b = gen_box(rng, 0, s), gen_xtru(rng, int(rng.integers(0, 1000)),
                                                0.7 * s)
        else:
            a, b = xa, gen_xtru(rng, int(rng.integers(0, 1000)), s)
        rot = random_rotation(rng, int(rng.integers(3)))
        lo, hi = bounding_box(builder.g4, builder.build(a))
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        tr = [f32(c) for c in centre + rng.uniform(-0.5, 0.5, 3) * half]
        spec = {"type": op, "a": a, "b": b, "rotation": rot,
                "translation": tr}
        solid = builder.build(spec)
        if inside_fraction(builder.g4, solid, rng, 400) >= 0.02:
            return spec, solid
    raise RuntimeError("could not generate a non-empty xtru boolean")


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


def distance_to_out(g4, solid):
    """DistanceToOut(p, v) (calcNorm = false) of the solid as a callable.

    geant4_pybind 0.1.3 binds G4TessellatedSolid::DistanceToOut only with
    all five arguments (no defaults); the G4VSolid binding has the defaults
    and dispatches to the same virtual function."""
    if isinstance(solid, g4.G4TessellatedSolid) and \
            not isinstance(solid, g4.G4ExtrudedSolid):
        base = g4.G4VSolid.DistanceToOut
        return lambda p, v: base(solid, p, v)
    return solid.DistanceToOut


def trace(g4, solid, origins, dirs, counter, march=0):
    """Inside + distance for each ray; returns (expected (m,2), flags (m,),
    queries, seconds spent in the Geant4 loop); see FLAG_* for flags."""
    V = g4.G4ThreeVector
    pv = [(V(*o), V(*d)) for o, d in zip(origins.tolist(), dirs.tolist())]
    inside = solid.Inside
    dti = solid.DistanceToIn
    dto = distance_to_out(g4, solid)
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


def _formula_box(spec):
    """Bounding box (lo, hi) of a FORMULA_KINDS solid by its formula."""
    if spec["type"] == "twistedTubs":
        eo, dz = spec["endouterrad"], spec["halfzlen"]
        return np.array([-eo, -eo, -dz]), np.array([eo, eo, dz])
    dz = spec["dz"]
    poly = twisted_cross_section(spec, np.linspace(-dz, dz, 65)).reshape(-1,
                                                                       2)
    # the sections' vertices move on straight lines in genericTrap and on
    # helices (bulging by < 1 - cos(40 deg)) otherwise: pad generously
    lo = np.array([poly[:, 0].min(), poly[:, 1].min(), -dz])
    hi = np.array([poly[:, 0].max(), poly[:, 1].max(), dz])
    return lo, hi


def formula_missed(spec, origins, dirs, codes, dists, samples=FORMULA_SAMPLES,
                   zoom_rounds=4, zoom_samples=32):
    """FLAG_FORMULA check of a kind with an exact formula (FORMULA_KINDS:
    the twisted kinds and genericTrap by their cross-sections, twistedTubs by
    twisted_tubs_signed_distance): True for the
    rays on which the exact cross-section formula (twisted_signed_distance,
    checked against Geant4 by --describe-twisted) puts a point before
    Geant4's distance more than 1e-6 * (1 + size) mm on the other side of
    the surface.  The ray segment inside the formula's bounding box is
    sampled uniformly, then zoom_rounds times resampled around the sample
    that comes closest to the other side."""
    origins = np.asarray(origins, dtype=np.float64)
    dirs = np.asarray(dirs, dtype=np.float64)
    codes = np.asarray(codes)
    dists = np.minimum(np.asarray(dists, dtype=np.float64), 1e30)
    m = len(origins)
    bad = np.zeros(m, dtype=bool)
    if m == 0:
        return bad
    lo, hi = _formula_box(spec)
    size = float(np.max(hi - lo))
    lo, hi = lo - 0.05 * size, hi + 0.05 * size
    tol = 1e-6 * (1.0 + size)
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = (lo - origins) / dirs
        tb = (hi - origins) / dirs
    par = dirs == 0.0
    outside_slab = par & ((origins < lo) | (origins > hi))
    ta = np.where(par, -np.inf, ta)
    tb = np.where(par, np.inf, tb)
    t0 = np.maximum(0.0, np.max(np.minimum(ta, tb), axis=1))
    t1 = np.minimum(dists, np.min(np.maximum(ta, tb), axis=1))
    live = (codes != 1) & (t1 > t0) & ~np.any(outside_slab, axis=1)
    rows = np.nonzero(live)[0]
    if len(rows) == 0:
        return bad
    # sign: > 0 means "on the other side" (inside for outside origins)
    sgn = np.where(codes[rows] == 0, -1.0, 1.0)
    o, v = origins[rows], dirs[rows]
    a, b = t0[rows], t1[rows]

    def other_side(ts):  # ts (k, n) -> signed excursion to the other side
        k, n = ts.shape
        pts = o[:, None, :] + ts[:, :, None] * v[:, None, :]
        sd = twisted_signed_distance(spec, pts.reshape(-1, 3)).reshape(k, n)
        return sgn[:, None] * sd

    frac = (np.arange(samples) + 0.5) / samples
    ts = a[:, None] + frac[None, :] * (b - a)[:, None]
    ex = other_side(ts)
    best = np.argmax(ex, axis=1)
    worst = ex[np.arange(len(rows)), best]
    step = (b - a) / samples
    centre = ts[np.arange(len(rows)), best]
    zf = np.linspace(-1.0, 1.0, zoom_samples)
    for _ in range(zoom_rounds):
        tz = np.clip(centre[:, None] + zf[None, :] * step[:, None],
                     a[:, None], b[:, None])
        ez = other_side(tz)
        k = np.argmax(ez, axis=1)
        e = ez[np.arange(len(rows)), k]
        better = e > worst
        worst = np.where(better, e, worst)
        centre = np.where(better, tz[np.arange(len(rows)), k], centre)
        step = step * 2.0 / (zoom_samples - 1)
    bad[rows] = worst > tol
    return bad


# ---------------------------------------------------------------------------
# Twisted solids: exact cross-sections (see "Twisted solids" in the module
# doc), and --describe-twisted
# ---------------------------------------------------------------------------

TWISTED_KINDS = ["twistedBox", "twistedTrd", "twistedTrap", "genericTrap"]
# Kinds checked by an exact formula (FLAG_FORMULA, origin_distance.npy).
FORMULA_KINDS = TWISTED_KINDS + ["twistedTubs"]


def twisted_faceted_params(spec):
    """The G4VTwistedFaceted parameters (twist, dz, theta, phi, dy1, dx1,
    dx2, dy2, dx3, dx4, alpha) of a twistedBox/twistedTrd/twistedTrap."""
    t = spec["type"]
    if t == "twistedBox":
        dx, dy = spec["dx"], spec["dy"]
        return (spec["twistedangle"], spec["dz"], 0.0, 0.0,
                dy, dx, dx, dy, dx, dx, 0.0)
    if t == "twistedTrd":
        return (spec["twistedangle"], spec["dz"], 0.0, 0.0,
                spec["dy1"], spec["dx1"], spec["dx1"],
                spec["dy2"], spec["dx2"], spec["dx2"], 0.0)
    if t == "twistedTrap":
        return tuple(spec[k] for k in (
            "twistedangle", "dz", "theta", "phi", "dy1", "dx1", "dx2", "dy2",
            "dx3", "dx4", "alpha"))
    raise ValueError(t)


def twisted_cross_section(spec, z, variant="exact"):
    """Vertices (n, 4, 2) of the cross-section of a twisted solid at the
    heights z (n,), in Geant4's order: counter-clockwise for the
    G4VTwistedFaceted kinds, the given (clockwise) order for genericTrap.

    variant != "exact" gives the wrong candidate formulas that
    --describe-twisted checks against Geant4 to show that the test tells
    them apart."""
    z = np.atleast_1d(np.asarray(z, dtype=np.float64))
    if spec["type"] == "genericTrap":
        dz = spec["dz"]
        v = np.asarray(spec["vertices"], dtype=np.float64)
        bot, top = v[:4], v[4:]
        t = ((z + dz) / (2.0 * dz))[:, None, None]
        if variant == "polar":
            # vertices interpolated in polar coordinates about the centroids
            cb, ct = bot.mean(axis=0), top.mean(axis=0)
            rb, rt = bot - cb, top - ct
            ab = np.arctan2(rb[:, 1], rb[:, 0])
            at = np.arctan2(rt[:, 1], rt[:, 0])
            da = (at - ab + PI) % TWO_PI - PI
            lb, lt = np.hypot(rb[:, 0], rb[:, 1]), np.hypot(rt[:, 0],
                                                            rt[:, 1])
            tt = t[:, :, 0]
            ang = ab + da * tt
            rad = lb + (lt - lb) * tt
            c = cb + (ct - cb) * t[:, 0, :]
            return np.stack([c[:, None, 0] + rad * np.cos(ang),
                             c[:, None, 1] + rad * np.sin(ang)], axis=2)
        return bot[None] + (top - bot)[None] * t
    (tw, dz, theta, phi, dy1, dx1, dx2, dy2, dx3, dx4,
     alpha) = twisted_faceted_params(spec)
    u = (z + dz) / (2.0 * dz)           # 0 at -dz, 1 at +dz
    dxm = dx1 + (dx3 - dx1) * u          # half x length of the -y edge
    dxp = dx2 + (dx4 - dx2) * u          # half x length of the +y edge
    dy = dy1 + (dy2 - dy1) * u           # half y length
    ta = math.tan(alpha)
    if variant == "alpha_sign":
        ta = -ta
    if variant == "dx_swap":
        dxm, dxp = dxp, dxm
    loc = np.stack([np.stack([-dxm - dy * ta, -dy], 1),
                    np.stack([dxm - dy * ta, -dy], 1),
                    np.stack([dxp + dy * ta, dy], 1),
                    np.stack([-dxp + dy * ta, dy], 1)], axis=1)  # (n,4,2)
    ang = tw * z / (2.0 * dz)            # rotation, counter-clockwise
    if variant == "rot_sign":
        ang = -ang
    elif variant == "rot_from_bottom":
        ang = tw * u
    c, s = np.cos(ang)[:, None], np.sin(ang)[:, None]
    off = np.stack([z * math.tan(theta) * math.cos(phi),
                    z * math.tan(theta) * math.sin(phi)], 1)  # (n,2)
    if variant == "shift_rotated":  # tilt offset applied before rotating
        loc = loc + off[:, None, :]
        off = np.zeros_like(off)
    x = c * loc[:, :, 0] - s * loc[:, :, 1] + off[:, None, 0]
    y = s * loc[:, :, 0] + c * loc[:, :, 1] + off[:, None, 1]
    return np.stack([x, y], axis=2)


def twisted_signed_distance(spec, pts, variant="exact"):
    """Signed 'distance' of points (n, 3) to a twisted solid by the
    cross-section formula: max(|z| - dz, in-plane distances beyond the
    section's edges); < 0 inside, > 0 outside, 0 on the surface (it is the
    true distance only in the plane z = const; the cross-section is convex,
    as for every solid generated here).  twistedTubs: see
    twisted_tubs_signed_distance."""
    if spec["type"] == "twistedTubs":
        return twisted_tubs_signed_distance(spec, pts, variant)
    pts = np.asarray(pts, dtype=np.float64)
    z = pts[:, 2]
    poly = twisted_cross_section(spec, z, variant)
    a = poly
    b = np.roll(poly, -1, axis=1)
    e = b - a
    rel = pts[:, None, :2] - a
    area = np.sum(_cross2(a, b), axis=1)  # 2 * signed area
    orient = np.where(area > 0.0, 1.0, -1.0)[:, None]  # +1 ccw, -1 cw
    # outward distance beyond each edge line; edges of zero length (coincident
    # genericTrap vertices) bound nothing, and a section collapsed to a point
    # is at the distance of that point
    ln = np.linalg.norm(e, axis=2)
    with np.errstate(divide="ignore", invalid="ignore"):
        d_edge = np.where(ln > 0.0, -orient * _cross2(e, rel) / ln, -np.inf)
    d_sec = np.max(d_edge, axis=1)
    point = np.all(ln == 0.0, axis=1)
    d_sec[point] = np.linalg.norm(rel[point, 0], axis=1)
    return np.maximum(np.abs(z) - spec["dz"], d_sec)


def twisted_tubs_params(spec, variant="exact"):
    """(waist radii r_in, r_out, kappa, dz, dphi) of a twistedTubs (see
    "Twisted tubes" in the module doc); the variants are the wrong candidates
    of --describe-twisted."""
    tw, dz, dphi = spec["twistedangle"], spec["halfzlen"], spec["dphi"]
    ei, eo = spec["endinnerrad"], spec["endouterrad"]
    h = 0.5 * tw
    if variant in ("end_radii", "cylinders"):
        return ei, eo, math.tan(h) / dz, dz, dphi
    return ei * math.cos(h), eo * math.cos(h), math.tan(h) / dz, dz, dphi


def twisted_tubs_point(spec, a, x, z):
    """Points (n, 3) R_z(a) (x, kappa x z, z) of a twistedTubs: a in
    [-dphi/2, dphi/2], x in [r_in, r_out] (waist radii), |z| <= dz cover
    the solid."""
    _, _, kappa, _, _ = twisted_tubs_params(spec)
    a, x, z = np.broadcast_arrays(np.asarray(a, float), np.asarray(x, float),
                                  np.asarray(z, float))
    y = kappa * x * z
    c, s = np.cos(a), np.sin(a)
    return np.stack([c * x - s * y, s * x + c * y, z], axis=-1)


def twisted_tubs_signed_distance(spec, pts, variant="exact"):
    """Signed distance estimate of points (n, 3) to a twistedTubs: the max of
    |z| - dz, the distances beyond the inner / outer hyperboloids and beyond
    the two side surfaces, each surface's implicit function divided by its
    gradient's length (first order in 3D, so its sign is exact and near a
    face it is the distance to that face; outside near an edge it is at most
    the distance).  < 0 inside, > 0 outside."""
    pts = np.asarray(pts, dtype=np.float64)
    x, y, z = pts[:, 0], pts[:, 1], pts[:, 2]
    r_in, r_out, kappa, dz, dphi = twisted_tubs_params(spec, variant)
    rho = np.hypot(x, y)
    if variant == "cylinders":
        g = np.ones_like(z)
        t_in, t_out = r_in - rho, rho - r_out
    else:
        g = np.sqrt(1.0 + (kappa * z) ** 2)

        def grad(r0):
            return np.sqrt(1.0 + (r0 * kappa * kappa * z / g) ** 2)
        t_in = (r_in * g - rho) / grad(r_in)
        t_out = (rho - r_out * g) / grad(r_out)
    rot = np.arctan(kappa * z)
    if variant == "linear":
        rot = spec["twistedangle"] * z / (2.0 * dz)
    elif variant == "rot_sign":
        rot = -rot
    c_s, c_e = -0.5 * dphi, 0.5 * dphi
    if variant == "from_zero":
        c_s, c_e = 0.0, dphi
    sides = []
    for c, sign in ((c_s, 1.0), (c_e, -1.0)):
        a = c + rot
        # in-plane distance beyond the radial line at angle a (outward > 0)
        d = sign * (x * np.sin(a) - y * np.cos(a))
        if variant == "exact":
            # the side surface y' = kappa x' z in the frame turned by c:
            # |grad| = sqrt(1 + (kappa z)^2 + (kappa x')^2)
            xp = x * math.cos(c) + y * math.sin(c)
            d = d * g / np.sqrt(g * g + (kappa * xp) ** 2)
        sides.append(d)
    wedge = np.maximum(sides[0], sides[1])  # dphi <= pi: a convex wedge
    return np.maximum.reduce([np.abs(z) - dz, t_in, t_out, wedge])


def _tubs_ruled_points(spec, rng, n):
    """n random points on the lateral faces of a twistedTubs by the
    formula: on the hyperboloids (x = r_in or r_out, random a, z) or on the
    side faces (a = -+dphi/2, random x, z), with outward unit normals;
    returns (points (n, 3), normals (n, 3), edge (n,) bool: within 2% of the
    face's parameter range from one of its straight edges)."""
    r_in, r_out, kappa, dz, dphi = twisted_tubs_params(spec)
    face = rng.integers(0, 4, n)  # 0 inner, 1 outer, 2 start, 3 end side
    u = rng.uniform(0.0, 1.0, n)
    v = rng.uniform(0.0, 1.0, n)
    z = -dz + 2.0 * dz * v
    hyp = face < 2
    a = np.where(hyp, -0.5 * dphi + dphi * u,
                 np.where(face == 2, -0.5 * dphi, 0.5 * dphi))
    x = np.where(hyp, np.where(face == 0, r_in, r_out),
                 r_in + (r_out - r_in) * u)
    pts = twisted_tubs_point(spec, a, x, z)
    g = np.sqrt(1.0 + (kappa * z) ** 2)
    rho = np.hypot(pts[:, 0], pts[:, 1])
    nrm = np.zeros_like(pts)
    # hyperboloid: grad(rho - x g(z)) = (rho_hat, -x kappa^2 z / g)
    nrm[:, 0] = pts[:, 0] / rho
    nrm[:, 1] = pts[:, 1] / rho
    nrm[:, 2] = -x * kappa * kappa * z / g
    nrm[face == 0] *= -1.0
    # side: grad(y' - kappa x' z) = (-kappa z, 1, -kappa x') in the frame
    # turned by a; outward is minus it on the start side
    side = ~hyp
    ca, sa = np.cos(a), np.sin(a)
    gx, gy = -kappa * z, np.ones_like(z)
    sn = np.stack([ca * gx - sa * gy, sa * gx + ca * gy, -kappa * x], 1)
    sn[face == 2] *= -1.0
    nrm[side] = sn[side]
    nrm /= np.linalg.norm(nrm, axis=1)[:, None]
    edge = (u < 0.02) | (u > 0.98) | (v < 0.02) | (v > 0.98)
    return pts, nrm, edge


_TUBS_ALTERNATIVES = ["linear", "rot_sign", "from_zero", "end_radii",
                      "cylinders"]


def _check_formula(st, g4, solid, spec, pts, signed_distance, alternatives,
                   rng, n_rays, box):
    """Steps 1 and 2 of describe_twisted for one solid: the classification of
    pts by the formula signed_distance(spec, pts) and by each wrong
    candidate alternatives[a](spec, pts) against Inside, then the formula at
    the boundary found by bisecting Inside and at the hit points of
    DistanceToOut (from inside points) and DistanceToIn (from outside points
    aimed into box = (centre, half, size)); counts go into st."""
    V = g4.G4ThreeVector
    k_in, k_out = g4.EInside.kInside, g4.EInside.kOutside
    k_surf = g4.EInside.kSurface
    inside = solid.Inside
    dto = distance_to_out(g4, solid)
    centre, half, size = box
    sd = signed_distance(spec, pts)
    g = [inside(V(*p)) for p in pts.tolist()]
    g_in = np.array([c == k_in for c in g])
    g_out = np.array([c == k_out for c in g])
    far = np.abs(sd) > 1e-6
    st["points"] += len(pts)
    st["skipped_near_surface"] += int(np.count_nonzero(~far))
    bad = far & (((sd < 0) & ~g_in) | ((sd > 0) & ~g_out))
    st["disagree"] += int(np.count_nonzero(bad))
    for a, formula in alternatives.items():
        sa = formula(spec, pts)
        fa = np.abs(sa) > 1e-6
        st["alternatives_disagree"][a] += int(np.count_nonzero(
            fa & (((sa < 0) & ~g_in) | ((sa > 0) & ~g_out))))
    starts = pts[g_in][:n_rays]
    dirs = snap_directions(_isotropic_batch(rng, len(starts)))
    for o, v in zip(starts.tolist(), dirs.tolist()):
        o, v = np.array(o), np.array(v)
        a, b = 0.0, 4.0 * size
        for _ in range(60):
            m = 0.5 * (a + b)
            if inside(V(*(o + m * v))) == k_in:
                a = m
            else:
                b = m
        q = o + 0.5 * (a + b) * v
        e = abs(float(signed_distance(spec, q[None])[0]))
        st["bisect_points"] += 1
        st["bisect_max_abs_sd"] = max(st["bisect_max_abs_sd"], e)
        _check_hit(st, spec, inside, V, k_surf, o, v, dto(V(*o), V(*v)),
                   "dist_out_misses")
    outs = pts[g_out][:n_rays]
    tgt = _round_f32(centre + rng.uniform(-0.8, 0.8, (len(outs), 3)) * half)
    dirs = snap_directions(tgt - outs)
    for o, v in zip(outs.tolist(), dirs.tolist()):
        o, v = np.array(o), np.array(v)
        _check_hit(st, spec, inside, V, k_surf, o, v,
                   solid.DistanceToIn(V(*o), V(*v)), "dist_in_misses")


def describe_twisted_tubs(g4, builder, solids=8, n_points=2000, n_rays=200,
                          seed=20240611):
    """The checks of describe_twisted for twistedTubs and its formula
    (twisted_tubs_signed_distance): 1. classification of n_points points
    (half uniform in the enlarged bounding box, half within 2% of the size
    of the lateral faces) against Inside, for the formula and the wrong
    candidates (_TUBS_ALTERNATIVES: rotation linear in z, rotation sign
    flipped, sector starting at phi = 0 instead of centred, hyperboloid
    waists equal to the end radii, cylinders); 2. the formula at the
    boundary found by bisecting Inside and at the hit points of
    DistanceToIn / DistanceToOut; 3. points of the lateral faces (the
    rulings x = r_in, r_out and the radial segments of the side faces) are
    kSurface, and 1e-6 * (1 + size) off them along the normal kOutside /
    kInside (away from the faces' edges)."""
    V = g4.G4ThreeVector
    k_in, k_out = g4.EInside.kInside, g4.EInside.kOutside
    k_surf = g4.EInside.kSurface
    rng = np.random.default_rng([seed, KINDS.index("twistedTubs")])
    st = {"solids": 0, "points": 0, "skipped_near_surface": 0,
          "disagree": 0,
          "alternatives_disagree": {a: 0 for a in _TUBS_ALTERNATIVES},
          "bisect_points": 0, "bisect_max_abs_sd": 0.0,
          "dist_hits": 0, "dist_max_abs_sd": 0.0,
          "dist_hits_off_g4_surface": 0, "dist_out_misses": 0,
          "dist_in_misses": 0, "ruled_points": 0, "ruled_fail": 0}
    for i in range(solids):
        spec = gen_twisted_tubs(rng, i, log_uniform(rng, 3, 200))
        solid = builder.build(spec)
        inside = solid.Inside
        lo, hi = bounding_box(g4, solid)
        size = float(np.max(hi - lo))
        centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
        st["solids"] += 1
        n_box = n_points // 2
        pts = centre + rng.uniform(-1.2, 1.2, (n_points, 3)) * half
        on, nrm, _ = _tubs_ruled_points(spec, rng, n_points - n_box)
        off = rng.uniform(-0.02, 0.02, n_points - n_box) * size
        pts[n_box:] = on + off[:, None] * nrm
        pts = _round_f32(pts)
        alternatives = {
            a: (lambda sp, p, a=a: twisted_tubs_signed_distance(sp, p, a))
            for a in _TUBS_ALTERNATIVES}
        _check_formula(st, g4, solid, spec, pts, twisted_tubs_signed_distance,
                       alternatives, rng, n_rays, (centre, half, size))
        on, nrm, edge = _tubs_ruled_points(spec, rng, n_rays)
        eps = 1e-6 * (1.0 + size)
        for j in range(n_rays):
            checks = [(on[j], k_surf), (on[j] + eps * nrm[j], k_out),
                      (on[j] - eps * nrm[j], k_in)]
            if edge[j]:
                checks = checks[:1]
            st["ruled_points"] += 1
            for q2, want in checks:
                if inside(V(*q2.tolist())) != want:
                    st["ruled_fail"] += 1
                    break
    st["ok"] = not (st["disagree"] or st["ruled_fail"] or
                    st["bisect_max_abs_sd"] > 1e-6 or
                    st["dist_max_abs_sd"] > 1e-6)
    return st


# Wrong candidate formulas that --describe-twisted also tests (each must
# disagree with Geant4 somewhere, showing that the check can tell them apart).
_TWISTED_ALTERNATIVES = {
    "twistedBox": ["rot_sign", "rot_from_bottom", "xy_swap"],
    "twistedTrd": ["rot_sign", "rot_from_bottom", "xy_swap"],
    "twistedTrap": ["rot_sign", "rot_from_bottom", "shift_rotated",
                    "alpha_sign", "dx_swap"],
    "genericTrap": ["polar"],
}


def _xy_swapped(spec):
    """A twistedBox/twistedTrd spec with the x and y half lengths swapped
    (the wrong-axes candidate of --describe-twisted)."""
    s = dict(spec)
    if s["type"] == "twistedBox":
        s["dx"], s["dy"] = spec["dy"], spec["dx"]
    else:
        s["dx1"], s["dy1"] = spec["dy1"], spec["dx1"]
        s["dx2"], s["dy2"] = spec["dy2"], spec["dx2"]
    return s


def _candidate_distance(spec, pts, variant):
    if variant == "xy_swap":
        return twisted_signed_distance(_xy_swapped(spec), pts)
    return twisted_signed_distance(spec, pts, variant)


def describe_twisted(g4, builder, solids_per_kind=8, n_points=2000,
                     n_rays=200, seed=20240611):
    """Checks the cross-section formulas of the module doc against Geant4.

    For each twisted kind, solids_per_kind solids from the kind's generator:
    1. classification: n_points uniform points of the bounding box enlarged
       1.2x (float32-rounded); the formula (twisted_signed_distance < 0)
       against Geant4's Inside; points within 1e-6 mm of the surface by the
       formula are skipped.  The same for the wrong candidates.
    2. surface points: from inside points along random directions, the
       boundary found by bisecting Geant4's Inside (60 steps), and the hit
       points p + d v of Geant4's DistanceToOut and (from outside points
       aimed at the solid) DistanceToIn: the formula's |signed distance|
       there (mm), i.e. the distance functions use the same surfaces.
    3. ruled sides: points on the straight segment between consecutive
       cross-section vertices at random heights must be kSurface, and
       1e-6 * (1 + size) off the segment in the plane z = const, outward /
       inward, kOutside / kInside.
    Returns a JSON-able dict; "ok" is false if the formula disagrees with
    Geant4 anywhere in 1. or 3., or 2. finds a surface point of Geant4 more
    than 1e-6 mm off the formula's surface (ignoring DistanceToIn/Out
    answers that Geant4's own Inside does not put on the surface).
    """
    V = g4.G4ThreeVector
    k_in, k_out = g4.EInside.kInside, g4.EInside.kOutside
    k_surf = g4.EInside.kSurface
    report = {"ok": True, "kinds": {}}
    for kind in TWISTED_KINDS:
        rng = np.random.default_rng([seed, KINDS.index(kind)])
        alts = _TWISTED_ALTERNATIVES[kind]
        st = {"solids": 0, "points": 0, "skipped_near_surface": 0,
              "disagree": 0, "alternatives_disagree": {a: 0 for a in alts},
              "bisect_points": 0, "bisect_max_abs_sd": 0.0,
              "dist_hits": 0, "dist_max_abs_sd": 0.0,
              "dist_hits_off_g4_surface": 0, "dist_out_misses": 0,
              "dist_in_misses": 0,
              "ruled_points": 0, "ruled_fail": 0}
        for i in range(solids_per_kind):
            spec = GENERATORS[kind](rng, i, log_uniform(rng, 3, 200))
            solid = builder.build(spec)
            inside = solid.Inside
            lo, hi = bounding_box(g4, solid)
            size = float(np.max(hi - lo))
            centre, half = 0.5 * (lo + hi), 0.5 * (hi - lo)
            st["solids"] += 1
            # 1. classification: half of the points uniform in the box,
            # half in a thin shell (in-plane offsets up to 2% of the size)
            # around the formula's lateral surface, where wrong candidates
            # differ most
            n_box = n_points // 2
            pts = centre + rng.uniform(-1.2, 1.2, (n_points, 3)) * half
            shell = _ruled_points(spec, rng, n_points - n_box)
            off = rng.uniform(-0.02, 0.02, n_points - n_box) * size
            pts[n_box:, :2] = shell[0] + off[:, None] * shell[1]
            pts[n_box:, 2] = shell[2]
            pts = _round_f32(pts)
            # 2. surface points: bisection of Inside, Geant4's distances
            alternatives = {
                a: (lambda sp, p, a=a: _candidate_distance(sp, p, a))
                for a in alts}
            _check_formula(st, g4, solid, spec, pts, twisted_signed_distance,
                           alternatives, rng, n_rays, (centre, half, size))
            # 3. ruled sides
            on, nrm, zs, us = _ruled_points(spec, rng, n_rays)
            eps = 1e-6 * (1.0 + size)
            for j in range(n_rays):
                checks = [(on[j], k_surf), (on[j] + eps * nrm[j], k_out),
                          (on[j] - eps * nrm[j], k_in)]
                if not 0.02 < us[j] < 0.98:  # near a vertex: on-point only
                    checks = checks[:1]
                st["ruled_points"] += 1
                for q2, want in checks:
                    if inside(V(q2[0], q2[1], zs[j])) != want:
                        st["ruled_fail"] += 1
                        break
        if (st["disagree"] or st["ruled_fail"] or
                st["bisect_max_abs_sd"] > 1e-6 or
                st["dist_max_abs_sd"] > 1e-6):
            report["ok"] = False
        report["kinds"][kind] = st
    st = describe_twisted_tubs(g4, builder, seed=seed)
    report["ok"] = report["ok"] and st.pop("ok")
    report["kinds"]["twistedTubs"] = st
    return report


def _ruled_points(spec, rng, n):
    """n random points on the lateral surface by the formula: a random
    height z, side k and u in [0, 1] give the point (1 - u) P_k(z) +
    u P_k+1(z) of the straight segment between consecutive cross-section
    vertices.  Returns (xy (n,2), outward in-plane unit normals (n,2),
    z (n,), u (n,))."""
    dz = spec["dz"]
    zs = rng.uniform(-dz, dz, n)
    poly = twisted_cross_section(spec, zs)
    ks = rng.integers(0, 4, n)
    us = rng.uniform(0.0, 1.0, n)
    rows = np.arange(n)
    pa = poly[rows, ks]
    e = poly[rows, (ks + 1) % 4] - pa
    ln = np.linalg.norm(e, axis=1)
    # a side of zero length (coincident genericTrap vertices) is a vertex:
    # u = 0 there, so that only the point itself is checked
    us[ln == 0.0] = 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        nrm = np.where(ln[:, None] > 0.0,
                       np.stack([e[:, 1], -e[:, 0]], 1) / ln[:, None], 0.0)
    area = np.sum(_cross2(poly, np.roll(poly, -1, axis=1)), axis=1)
    nrm[area < 0] *= -1.0  # outward normal of a clockwise section
    return pa + us[:, None] * e, nrm, zs, us


def _check_hit(st, spec, inside, V, k_surf, o, v, d, miss_key):
    """Part 2 of describe_twisted for one Geant4 distance answer."""
    if d >= K_INFINITY:
        st[miss_key] += 1
        return
    q = o + d * v
    if inside(V(*q.tolist())) != k_surf:
        st["dist_hits_off_g4_surface"] += 1  # a Geant4 bug (flagged rays)
        return
    e = abs(float(twisted_signed_distance(spec, q[None])[0]))
    st["dist_hits"] += 1
    st["dist_max_abs_sd"] = max(st["dist_max_abs_sd"], e)


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
    # 4. ... but the rz-corner constructor's radii reach the corners
    ph = builder.build({"type": "genericPolyhedra", "sphi": 0.0,
                        "dphi": F32_TWO_PI, "numside": 6,
                        "r": [0.0, 20.0, 20.0, 0.0],
                        "z": [-10.0, -10.0, 10.0, 10.0]})
    d_side = ph.DistanceToIn(V(100 * math.cos(mid), 100 * math.sin(mid), 0),
                             V(-math.cos(mid), -math.sin(mid), 0))
    d_corner = ph.DistanceToIn(V(100, 0, 0), V(-1, 0, 0))
    report["generic_polyhedra_side"] = 100 - d_side
    report["generic_polyhedra_corner"] = 100 - d_corner
    assert abs(100 - d_corner - 20.0) < 1e-9
    assert abs(100 - d_side - 20.0 * math.cos(mid)) < 1e-9
    return report


# ---------------------------------------------------------------------------
# Geant4's solid unit-test cases (--cases)
# ---------------------------------------------------------------------------

CASES_FORMAT = "hytrace-geant4-unit-cases"
# Inside() samples along a ray (clipped to the solid's bounding box) that check
# the navigator's step, and those of the second judge, which gives the
# reference where the step contradicts Geant4's own Inside().
CHECK_SAMPLES = 64
JUDGE_SAMPLES = 4096


def place_in_world(g4, builder, solid):
    """A world box holding `solid` unplaced (identity) and the solid's
    placement; the world's half size W is far beyond the solid."""
    lo, hi = bounding_box(g4, solid)
    half = 10.0 * float(np.max(np.abs(np.concatenate([lo, hi])))) + 1e3
    name = builder._name("world")
    mat = g4.G4Material(name + "_vacuum", 1.0, 1.008 * g4.g / g4.mole,
                        1e-20 * g4.g / g4.cm3)
    world_lv = g4.G4LogicalVolume(g4.G4Box(name, half, half, half), mat,
                                  name + "_lv")
    world_pv = g4.G4PVPlacement(None, g4.G4ThreeVector(), world_lv,
                                name + "_pv", None, False, 0)
    lv = g4.G4LogicalVolume(solid, mat, name + "_solid_lv")
    pv = g4.G4PVPlacement(None, g4.G4ThreeVector(), lv, name + "_solid_pv",
                          world_lv, False, 0)
    builder.keep += [mat, world_lv, world_pv, lv, pv]
    return world_pv, pv, half


def navigate(g4, world_pv, pv, half, origins, dirs):
    """G4Navigator's answers for rays from `origins`: (codes, dists) with
    code 2 where the origin is located in the solid's volume (a surface
    origin as the navigator decides) and 0 in the world, dist ComputeStep's
    step after LocateGlobalPointAndSetup (a fresh, non-relative locate per
    ray, with the ray's direction), kInfinity where the step ends on the
    world box.  After a zero step (from a surface) the navigator relocates
    across the boundary and steps again, as G4Transportation makes it."""
    nav = g4.G4Navigator()
    nav.SetWorldVolume(world_pv)
    V = g4.G4ThreeVector
    codes, dists = [], []
    for o, d in zip(origins.tolist(), dirs.tolist()):
        P, D = V(*o), V(*d)
        located = nav.LocateGlobalPointAndSetup(P, D, False, False)
        step = nav.ComputeStep(P, D, 1e30, 0.0)
        for _ in range(2):
            if step > 0.0:
                break
            nav.SetGeometricallyLimitedStep()
            located = nav.LocateGlobalPointAndSetup(P, D, True, False)
            step = nav.ComputeStep(P, D, 1e30, 0.0)
        into = located is not None and located.GetName() == pv.GetName()
        if not into:
            exit_t = min(((half if d[a] > 0 else -half) - o[a]) / d[a]
                         for a in range(3) if d[a] != 0.0)
            if step >= exit_t - 1e-9 * half:
                step = K_INFINITY
        codes.append(2 if into else 0)
        dists.append(step)
    return codes, dists


class Interior:
    """Geant4's Inside() along one ray, as membership of the solid's interior
    (kInside; kSurface counts as not inside): the origin's side is that of the
    first point along the ray that Inside() does not call kSurface (tried at
    1e-9, 1e-8, ... 1e-5 mm, then at the samples up to the bounding box), so
    that a ray starting on a surface has the side it moves into, also where it
    leaves a curved surface tangentially, and a ray that runs along a face it
    starts on and then leaves is outside; a boundary is where the membership
    changes after that point."""

    def __init__(self, g4, solid, o, v):
        self.g4, self.solid, self.o, self.v = g4, solid, o, v
        lo, hi = bounding_box(g4, solid)
        self.size = float(np.max(hi - lo))
        pad = 1e-3 * (1.0 + self.size)
        lo, hi = lo - pad, hi + pad
        t1 = math.inf
        for a in range(3):  # where the ray leaves the bounding box
            if v[a] != 0.0:
                t1 = min(t1, max((lo[a] - o[a]) / v[a], (hi[a] - o[a]) / v[a]))
            elif not lo[a] <= o[a] <= hi[a]:
                t1 = 0.0
        self.end = max(t1, 1e-5)
        k_surf = g4.EInside.kSurface
        ladder = [1e-9, 1e-8, 1e-7, 1e-6, 1e-5]
        samples = np.linspace(0.0, self.end, JUDGE_SAMPLES + 1)[1:]
        self.start, self.inside = self.end, False
        for t in ladder + [t for t in samples.tolist() if t > ladder[-1]]:
            c = self.code(t)
            if c != k_surf:
                self.start, self.inside = t, c == g4.EInside.kInside
                break

    def code(self, t):
        p = self.o + t * self.v
        return self.solid.Inside(self.g4.G4ThreeVector(*p.tolist()))

    def member(self, t):
        return self.code(t) == self.g4.EInside.kInside

    def agrees(self, dist):
        """Whether a step of `dist` (inf: none) ends where the membership
        first changes: CHECK_SAMPLES samples before it on the origin's side,
        the other side just after it (at the first point Inside() does not
        call kSurface)."""
        stop = min(dist, self.end)
        if stop > self.start:
            for t in np.linspace(self.start, stop, CHECK_SAMPLES + 1)[:-1]:
                if self.member(t) != self.inside:
                    return False
        if not math.isfinite(dist):
            return not self.inside
        if dist < 0.5 * self.start:
            return False
        # The first point past the step that Inside() does not call kSurface
        # (1e-9 .. 1e-3 of the size and distance on: a ray that enters
        # tangentially stays in the tolerance band for a while).
        for k in range(9, 2, -1):
            c = self.code(dist + 10.0 ** -k * (1.0 + self.size + dist))
            if c != self.g4.EInside.kSurface:
                return (c == self.g4.EInside.kInside) != self.inside
        return False

    def first_change(self):
        """The first membership change after the origin's side is known
        (JUDGE_SAMPLES samples up to the bounding box, then bisection to
        1e-12 of the size); inf if none."""
        prev = self.start
        for t in np.linspace(self.start, self.end, JUDGE_SAMPLES + 1)[1:]:
            if self.member(t) != self.inside:
                a, b = prev, t
                while b - a > 1e-12 * (1.0 + self.size):
                    mid = 0.5 * (a + b)
                    a, b = (mid, b) if self.member(mid) == self.inside \
                        else (a, mid)
                return b
            prev = t
        return math.inf


def phi_plane_entry(g4, solid, spec, o, v):
    """Where a ray from an origin that Geant4's Inside() calls kSurface, but
    that an exact computation puts outside a phi half-plane of the solid
    (by 1e-9 to 1e-6 mm: within Geant4's angular tolerance of 1e-9 rad times
    the radius, beyond twice its surface tolerance of 5e-10 mm), enters
    through that plane; None where that is not so.  The signed distance to
    the plane through the z axis at angle a (outward normal n) is n . o in
    f64, exact to 1e-16 of |o|; the entry must lead into the solid (Inside()
    kInside just past it)."""
    dphi = spec.get("dphi")
    if dphi is None or dphi >= TWO_PI:
        return None
    sphi = spec["sphi"]
    for a, sign in ((sphi, 1.0), (sphi + dphi, -1.0)):
        c, s_ = math.cos(a), math.sin(a)
        n = (sign * s_, -sign * c)
        dist = n[0] * o[0] + n[1] * o[1]
        if not (1e-9 < dist < 1e-6) or c * o[0] + s_ * o[1] <= 0.0:
            continue
        nv = n[0] * v[0] + n[1] * v[1]
        if nv >= 0.0:
            continue
        t = dist / -nv
        past = o + (t + 1e-6 / -nv) * v
        if solid.Inside(g4.G4ThreeVector(*past.tolist())) == \
                g4.EInside.kInside:
            return t
    return None


def run_cases(g4, args, tmpdir):
    """--cases: Geant4's navigator's answers for the rays of a case file
    (see the module doc), family by family."""
    with open(args.cases) as fh:
        doc = json.load(fh)
    if doc.get("format") != CASES_FORMAT:
        raise ValueError("%s: not a %s file" % (args.cases, CASES_FORMAT))
    builder = Builder(g4, tmpdir)
    manager = g4.G4GeometryManager.GetInstance()
    rows, ray_flags = [], []
    for fam in doc["families"]:
        solids = [builder.build(spec) for spec in fam["solids"]]
        worlds = [place_in_world(g4, builder, s) for s in solids]
        rays = np.array(fam["rays"], dtype=np.float64).reshape(-1, 7)
        manager.CloseGeometry(True, False)
        for k, solid in enumerate(solids):
            sel = np.nonzero(rays[:, 0] == k)[0]
            origins, dirs = rays[sel, 1:4], rays[sel, 4:7]
            codes, dists = navigate(g4, *worlds[k], origins, dirs)
            V = g4.G4ThreeVector
            for j, i in enumerate(sel):
                o, v = origins[j], dirs[j]
                dist = math.inf if dists[j] >= K_INFINITY else dists[j]
                at = solid.Inside(V(*o.tolist()))
                code = {g4.EInside.kOutside: 0, g4.EInside.kSurface: 1,
                        g4.EInside.kInside: 2}[at]
                interior = Interior(g4, solid, o, v)
                judge, flag = math.nan, 0
                entry = None
                if code == 1:
                    entry = phi_plane_entry(g4, solid, fam["solids"][k], o, v)
                if entry is not None:
                    judge, flag = entry, FLAG_TOLERANCE
                elif not interior.agrees(dist):
                    judge, flag = interior.first_change(), FLAG_INCONSISTENT
                rows.append((int(i), [dist, codes[j], code, judge]))
                ray_flags.append((int(i), flag))
        manager.OpenGeometry()
    # rows in case-file order: families in order, rays in order
    expected, flags_out, base = [], [], 0
    for fam in doc["families"]:
        n = len(fam["rays"])
        part = sorted(rows[:n])
        fpart = sorted(ray_flags[:n])
        rows, ray_flags = rows[n:], ray_flags[n:]
        expected += [r for _, r in part]
        flags_out += [f for _, f in fpart]
        base += n
    np.save(os.path.join(args.out, "unit_expected.npy"),
            np.array(expected, dtype=np.float64).reshape(-1, 4))
    np.save(os.path.join(args.out, "unit_flags.npy"),
            np.array(flags_out, dtype=np.int32))
    return {"families": len(doc["families"]), "rays": base}


# ---------------------------------------------------------------------------
# main
# ---------------------------------------------------------------------------

def parse_args(argv):
    ap = argparse.ArgumentParser(
        description="Generate Geant4 reference ray/solid answers for hytrace.")
    ap.add_argument("--out", help="output directory (required unless "
                    "--describe-twisted is given)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--solids-per-kind", type=int, default=20)
    ap.add_argument("--rays-per-solid", type=int, default=500)
    ap.add_argument("--kinds", default=",".join(KINDS),
                    help="comma separated subset of: " + ",".join(KINDS))
    ap.add_argument("--cases", metavar="FILE",
                    help="instead of random solids, answer the rays of a "
                         "case file (tests/data/geant4_unit_cases.json) with "
                         "Geant4's navigator")
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
    ap.add_argument("--describe-twisted", action="store_true",
                    help="check the twisted-solid cross-section formulas "
                         "of the module doc against Geant4 and print the "
                         "report to stderr; without --out only this check "
                         "runs (exit status 1 if it fails)")
    args = ap.parse_args(argv)
    if args.out is None and not args.describe_twisted:
        ap.error("--out is required (unless --describe-twisted is given)")
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
    describe_only = args.out is None
    tmp = tempfile.TemporaryDirectory(prefix="hytrace_g4_")
    if not describe_only:
        os.makedirs(args.out, exist_ok=True)

    real_out, real_err = sys.stdout, sys.stderr
    log = open(os.path.join(tmp.name if describe_only else args.out,
                            "geant4.log"), "w")
    counter = [0]
    out_sink = _G4Sink(log, real_err, False, counter)
    err_sink = _G4Sink(log, real_err, True, counter)
    if not os.environ.get("GEANT4_DATA_DIR"):
        # geant4_pybind would otherwise try to download its data sets; the
        # geometry needs none of them.
        data_dir = os.path.join(tmp.name, "g4data")
        os.makedirs(data_dir, exist_ok=True)
        os.environ["GEANT4_DATA_DIR"] = data_dir
    sys.stdout, sys.stderr = out_sink, err_sink
    try:
        import geant4_pybind as g4
        if describe_only:
            report = run_describe_twisted(g4, Builder(g4, tmp.name),
                                          real_err)
        elif args.cases:
            result = run_cases(g4, args, tmp.name)
            sys.stdout, sys.stderr = real_out, real_err
            log.close()
            tmp.cleanup()
            real_out.write(json.dumps(result) + "\n")
            real_out.flush()
            os._exit(0)
        else:
            result = run(g4, args, tmp.name, real_err, counter)
    except Exception:
        # Some Geant4 solids (twisted, extruded) crash when they are only
        # destroyed at interpreter shutdown, as they would be here through
        # the traceback: report the error and leave at once.
        sys.stdout, sys.stderr = real_out, real_err
        traceback.print_exc()
        real_err.flush()
        log.close()
        tmp.cleanup()
        os._exit(1)
    finally:
        sys.stdout, sys.stderr = real_out, real_err
        log.close()
        tmp.cleanup()
    if describe_only:
        real_out.write(json.dumps({"describe_twisted_ok": report["ok"],
                                   "seconds": round(time.perf_counter() -
                                                    t_start, 3)}) + "\n")
        real_out.flush()
        return 0 if report["ok"] else 1
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


def run_describe_twisted(g4, builder, real_err):
    """--describe-twisted: run describe_twisted and print its report to
    stderr (one line per kind)."""
    report = describe_twisted(g4, builder)
    for kind, st in report["kinds"].items():
        real_err.write("describe-twisted %s: %s\n" % (kind, json.dumps(st)))
    real_err.write("describe-twisted: %s\n"
                   % ("ok" if report["ok"] else "FAILED"))
    real_err.flush()
    return report


def run(g4, args, tmpdir, real_err, counter):
    builder = Builder(g4, tmpdir)
    if args.self_check:
        report = self_check(g4, builder)
        real_err.write("self-check: %s\n" % json.dumps(report))
    if args.describe_twisted:
        run_describe_twisted(g4, builder, real_err)

    solids_json = []
    rays, ray_solid, ray_family, expected, ray_flags = [], [], [], [], []
    origin_distance = []
    per_kind = {}
    total_q, total_s = 0, 0.0
    K, M = args.solids_per_kind, args.rays_per_solid
    for kind in args.kinds:
        rng = np.random.default_rng([args.seed, KINDS.index(kind)])
        specs = []
        solids = []
        if kind in ("boolean", "xtruBoolean"):
            gen = gen_boolean if kind == "boolean" else gen_xtru_boolean
            for i in range(K):
                spec, solid = gen(rng, i, log_uniform(rng, 10, 100), builder)
                specs.append(spec)
                solids.append(solid)
        else:
            gen = GENERATORS[kind]
            for i in range(K):
                specs.append(gen(rng, i, log_uniform(rng, 3, 200)))
            if kind in GDML_KINDS:
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
            if kind in FORMULA_KINDS:
                flags[formula_missed(spec, origins, dirs, exp[:, 1],
                                     exp[:, 0])] |= FLAG_FORMULA
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
            # Distance of each origin to the surface (in the plane z = const,
            # an upper bound of the 3D distance) where the formula exists.
            near = np.full(M, np.nan)
            if kind in FORMULA_KINDS:
                near = np.abs(twisted_signed_distance(spec, origins))
            origin_distance.append(near)
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
    np.save(os.path.join(out, "origin_distance.npy"),
            cat(origin_distance, (0,), np.float64).astype(np.float64))
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
                  for f in ray_flags)),
              "flagged_formula": int(sum(
                  int(np.count_nonzero(f & FLAG_FORMULA))
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
