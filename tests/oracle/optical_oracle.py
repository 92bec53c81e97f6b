#!/usr/bin/env python3
"""Geant4 optical-photon oracle for ``hytrace photons``.

Purpose
-------
Reads a GDML file with Geant4 (``geant4_pybind``), shoots optical photons from
the same kind of source as ``hytrace photons --source`` and records, for every
photon, its step history as Opticks-style labels and whether it was detected.
The Rust tests compare the label frequencies and the detected counts with a
``hytrace photons`` run of the same source (statistically: the two programs
draw different random numbers).

Command line::

    optical_oracle.py GDML --source SPEC --wavelength NM|MATERIAL:PROPERTY -n N
        [--seed S] [--speed]

``SPEC`` is ``point:X,Y,Z`` (isotropic), ``beam:X,Y,Z:DX,DY,DZ:R[:A]`` (a
beam over a disk of radius R perpendicular to D, parallel or spread within a
cone of half-angle A degrees) or ``sphere:X,Y,Z:R:in|out``, mm, as in
``hytrace photons``. Every photon starts at time 0 with a random linear
polarization perpendicular to its direction and energy h c / lambda
(h c = 1239.84198 eV nm), or with ``MATERIAL:PROPERTY`` an energy drawn from
that intensity table of the material as Geant4 builds it (the trapezoid
integral over energy, inverted linearly between rows: written here with
NumPy, not taken from hytrace). stdout carries one JSON document::

    {"geant4": VERSION, "photons": N, "detected": D,
     "histories": {"TO BT SD": count, ...},
     "hit_times": [...], "seconds": s}

Geant4's own output goes to stderr.

With ``--speed`` Geant4 runs without Python in its loop: the photons come from
a G4GeneralParticleSource configured for the same source (its own random
directions; Geant4's primary transformer gives each photon a random
polarization perpendicular to its direction), no user tracking or stepping
action runs and nothing is recorded. The document holds the photon count,
``seconds`` (BeamOn, one thread) and ``photons_per_s``.

Physics
-------
A modular physics list with G4OpticalPhysics only (Geant4 adds
transportation); of its processes only OpAbsorption, OpRayleigh, OpWLS and
OpBoundary are active (Cerenkov, Scintillation, OpWLS2 and OpMieHG are
switched off with /process/optical/processActivation). No Geant4 data set is
needed: run with ``GEANT4_DATA_DIR`` pointing to an existing (possibly empty)
directory (the script makes a temporary one when it is unset). The run
manager's initialization reads Geant4's nuclide table (the G4ENSDFSTATE data
set, ``G4ENSDFSTATEDATA``) and aborts without it; optical physics uses none of
it, so when ``G4ENSDFSTATEDATA`` is unset the script points it to a temporary
directory holding an empty ``ENSDFSTATE.dat``.

Labels
------
Every step of a photon gives one label, in order after ``TO`` (the start):

* ``AB``: the step ended in OpAbsorption; ``SC``: in OpRayleigh; ``RE``: in
  OpWLS (absorbed by a wavelength shifter): each photon it emits carries the
  history on (``AB`` instead when it emits none);
* ``MI``: the photon left the world (step status fWorldBoundary);
* a step to a geometry boundary no longer than Geant4's surface tolerance
  (1e-9 mm) gets no label: G4OpBoundaryProcess does nothing there
  (StepTooSmall); Geant4 takes such a step back across the surface after
  every reflection;
* at a geometry boundary (fGeomBoundary), where G4OpBoundaryProcess acted:
  the photon killed there is ``SD`` when energy was deposited (Detection)
  unless that was Geant4's NoRINDEX kill (material 1 without RINDEX, or a
  polished/ground dielectric_dielectric crossing -- no surface counts as one
  -- into a material without RINDEX), else ``SA``; a photon alive after the
  boundary was reflected when its direction before and after lie on opposite
  sides of the surface (the navigator's exit normal): ``DR`` when the new
  direction is not the mirror image of the old one about that normal (a
  rough or painted surface's diffuse, lobe or backscatter reflection),
  else ``SR`` when the crossing's optical surface is dielectric_metal, else
  ``BR``; otherwise it went on: ``BT``.

Histories keep their first 16 labels (Opticks' seqhis), as hytrace does.
"""

import argparse
import json
import os
import sys
import tempfile
import time

import numpy as np

HC_EV_NM = 1239.84198
MAX_LABELS = 16
PHOTONS_PER_EVENT = 500
# Geant4's surface tolerance (mm): boundary steps no longer are StepTooSmall.
STEP_TOO_SMALL = 1e-9
# A reflected direction this close to the mirror image of the incoming one is specular.
SPECULAR_TOLERANCE = 1e-7


def parse_source(spec):
    """Source tuples: ("point", centre), ("beam", centre, axis, radius, cos of the
    divergence half-angle), ("sphere", centre, radius, inward)."""
    parts = spec.split(":")
    nums = lambda s: [float(v) for v in s.split(",")]
    if parts[0] == "point" and len(parts) == 2:
        return ("point", np.array(nums(parts[1])))
    if parts[0] == "beam" and len(parts) in (4, 5):
        d = np.array(nums(parts[2]))
        half_angle = float(parts[4]) if len(parts) == 5 else 0.0
        return ("beam", np.array(nums(parts[1])), d / np.linalg.norm(d),
                float(parts[3]), np.cos(np.radians(half_angle)))
    if parts[0] == "sphere" and len(parts) == 4 and parts[3] in ("in", "out"):
        return ("sphere", np.array(nums(parts[1])), float(parts[2]), parts[3] == "in")
    raise SystemExit("unknown source %r" % spec)


def orthonormal(d):
    """Two unit vectors completing d to an orthonormal basis."""
    a = np.array([1.0, 0.0, 0.0]) if abs(d[0]) < 0.9 else np.array([0.0, 1.0, 0.0])
    e1 = np.cross(d, a)
    e1 /= np.linalg.norm(e1)
    return e1, np.cross(d, e1)


def isotropic(rng):
    c = 1.0 - 2.0 * rng.random()
    s = np.sqrt(max(0.0, 1.0 - c * c))
    phi = 2.0 * np.pi * rng.random()
    return np.array([s * np.cos(phi), s * np.sin(phi), c])


def sample(source, rng):
    """Position, direction, polarization of one photon."""
    if source[0] == "point":
        pos, d = source[1], isotropic(rng)
    elif source[0] == "sphere":
        _, centre, radius, inward = source
        n = isotropic(rng)
        pos, d = centre + radius * n, (-n if inward else n)
    else:
        _, centre, axis, radius, cos_div = source
        e1, e2 = orthonormal(axis)
        r = radius * np.sqrt(rng.random())
        phi = 2.0 * np.pi * rng.random()
        pos = centre + r * (np.cos(phi) * e1 + np.sin(phi) * e2)
        # Uniform in solid angle within the cone: the cosine uniform in [cos A, 1].
        c = 1.0 - (1.0 - cos_div) * rng.random()
        s = np.sqrt(max(0.0, 1.0 - c * c))
        psi = 2.0 * np.pi * rng.random()
        d = c * axis + s * (np.cos(psi) * e1 + np.sin(psi) * e2)
    e1, e2 = orthonormal(d)
    a = 2.0 * np.pi * rng.random()
    return pos, d, np.cos(a) * e1 + np.sin(a) * e2


def spectrum_table(g4, material, prop):
    """Photon energies and the running trapezoid integral of a material's intensity
    table, read from Geant4's material (energies in Geant4's internal units)."""
    m = g4.G4Material.GetMaterial(material)
    if m is None or m.GetMaterialPropertiesTable() is None:
        raise SystemExit("no material %r with properties" % material)
    v = m.GetMaterialPropertiesTable().GetProperty(prop)
    if v is None:
        raise SystemExit("material %r has no property %r" % (material, prop))
    es = np.array([v.Energy(i) for i in range(v.GetVectorLength())])
    ys = np.array([v.Value(e) for e in es])
    cum = np.concatenate([[0.0], np.cumsum(0.5 * np.diff(es) * (ys[1:] + ys[:-1]))])
    return es, cum


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("gdml")
    ap.add_argument("--source", required=True)
    ap.add_argument("--wavelength", default="420")
    ap.add_argument("-n", type=int, required=True)
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--speed", action="store_true",
                    help="time Geant4's tracking alone: no user actions, no records")
    args = ap.parse_args()
    source = parse_source(args.source)

    real_out = sys.stdout
    sys.stdout = sys.stderr
    if not os.environ.get("GEANT4_DATA_DIR"):
        os.environ["GEANT4_DATA_DIR"] = tempfile.mkdtemp(prefix="hytrace_g4data_")
    if not os.environ.get("G4ENSDFSTATEDATA"):
        # The run manager builds Geant4's nuclide table from the G4ENSDFSTATE data set
        # when it initializes (optical physics uses none of it): an empty table does.
        ensdf = tempfile.mkdtemp(prefix="hytrace_ensdf_")
        open(os.path.join(ensdf, "ENSDFSTATE.dat"), "w").close()
        os.environ["G4ENSDFSTATEDATA"] = ensdf
    import geant4_pybind as g4

    t0 = time.time()
    parser = g4.G4GDMLParser()
    parser.Read(args.gdml, False)
    world = parser.GetWorldVolume()

    class Detector(g4.G4VUserDetectorConstruction):
        def Construct(self):
            return world

    class Physics(g4.G4VModularPhysicsList):
        def __init__(self):
            super().__init__()
            self.RegisterPhysics(g4.G4OpticalPhysics())

    rng = np.random.default_rng(args.seed)
    spectrum_of = args.wavelength.rsplit(":", 1) if ":" in args.wavelength else None
    energy = None if spectrum_of else HC_EV_NM / float(args.wavelength) * g4.eV

    class SpeedGun(g4.G4VUserPrimaryGeneratorAction):
        """The source as a G4GeneralParticleSource: no Python per photon."""

        def __init__(self):
            super().__init__()
            self.gps = g4.G4GeneralParticleSource()
            self.left = args.n

        def GeneratePrimaries(self, event):
            self.gps.SetNumberOfParticles(min(PHOTONS_PER_EVENT, self.left))
            self.left -= min(PHOTONS_PER_EVENT, self.left)
            self.gps.GeneratePrimaryVertex(event)

    def gps_commands():
        if energy is None:
            raise SystemExit("--speed runs fixed wavelengths only")
        x, y, z = source[1]
        cmds = ["/gps/particle opticalphoton",
                "/gps/energy %.9g eV" % (energy / g4.eV),
                "/gps/pos/centre %r %r %r mm" % (x, y, z)]
        if source[0] == "point":
            return cmds + ["/gps/pos/type Point", "/gps/ang/type iso"]
        if source[0] != "beam" or source[4] < 1.0:
            raise SystemExit("--speed runs point sources and parallel beams only")
        _, _, d, radius, _ = source
        e1, e2 = orthonormal(d)
        return cmds + ["/gps/pos/type Plane", "/gps/pos/shape Circle",
                       "/gps/pos/radius %r mm" % radius,
                       "/gps/pos/rot1 %r %r %r" % tuple(e1),
                       "/gps/pos/rot2 %r %r %r" % tuple(e2),
                       "/gps/direction %r %r %r" % tuple(d)]

    class Gun(g4.G4VUserPrimaryGeneratorAction):
        def __init__(self):
            super().__init__()
            self.gun = g4.G4ParticleGun(1)
            self.gun.SetParticleDefinition(g4.G4OpticalPhoton.Definition())
            if energy is not None:
                self.gun.SetParticleEnergy(energy)
            self.gun.SetParticleTime(0.0)
            self.left = args.n
            self.spectrum = None

        def GeneratePrimaries(self, event):
            if spectrum_of and self.spectrum is None:
                self.spectrum = spectrum_table(g4, *spectrum_of)
            for _ in range(min(PHOTONS_PER_EVENT, self.left)):
                pos, d, pol = sample(source, rng)
                if self.spectrum is not None:
                    es, cum = self.spectrum
                    self.gun.SetParticleEnergy(float(np.interp(rng.random() * cum[-1], cum, es)))
                self.gun.SetParticlePosition(g4.G4ThreeVector(*pos))
                self.gun.SetParticleMomentumDirection(g4.G4ThreeVector(*d))
                self.gun.SetParticlePolarization(g4.G4ThreeVector(*pol))
                self.gun.GeneratePrimaryVertex(event)
                self.left -= 1

    histories = {}
    hit_times = []
    hit_positions = []
    hit_wavelengths = []
    state = {"labels": None}
    navigator = [None]

    def volume(point):
        return point.GetTouchable().GetVolume()

    def has_rindex(material):
        mpt = material.GetMaterialPropertiesTable()
        return mpt is not None and mpt.GetProperty("RINDEX") is not None

    def surface_of(pre_pv, post_pv):
        """The optical surface of a crossing, found as G4OpBoundaryProcess does."""
        s = g4.G4LogicalBorderSurface.GetSurface(pre_pv, post_pv)
        if s is None:
            pre_lv, post_lv = pre_pv.GetLogicalVolume(), post_pv.GetLogicalVolume()
            order = ((post_lv, pre_lv) if post_pv.GetMotherLogical() == pre_lv
                     else (pre_lv, post_lv))
            for lv in order:
                s = g4.G4LogicalSkinSurface.GetSurface(lv)
                if s is not None:
                    break
        return None if s is None else s.GetSurfaceProperty()

    def no_rindex_kill(pre, post):
        if not has_rindex(pre.GetMaterial()):
            return True
        surface = surface_of(volume(pre), volume(post))
        polished_dd = surface is None or (
            surface.GetType() == g4.G4SurfaceType.dielectric_dielectric
            and str(surface.GetFinish()).split(".")[-1] in ("polished", "ground"))
        return polished_dd and pre.GetMaterial() != post.GetMaterial() \
            and not has_rindex(post.GetMaterial())

    # Labels of photons absorbed by a wavelength shifter, by track ID: the photons it
    # emits carry them on (hytrace keeps one history through a re-emission).
    shifted = {}

    class Tracking(g4.G4UserTrackingAction):
        def PreUserTrackingAction(self, track):
            parent = shifted.get(track.GetParentID())
            state["labels"] = list(parent) if parent is not None else ["TO"]

        def PostUserTrackingAction(self, track):
            labels = state["labels"]
            if labels[-1] == "RE":
                if track.GetStep().GetNumberOfSecondariesInCurrentStep() > 0:
                    shifted[track.GetTrackID()] = labels
                    return
                # Absorbed by the shifter with nothing emitted.
                labels[-1] = "AB"
            key = " ".join(labels[:MAX_LABELS])
            histories[key] = histories.get(key, 0) + 1

    class Stepping(g4.G4UserSteppingAction):
        def UserSteppingAction(self, step):
            labels = state["labels"]
            pre, post = step.GetPreStepPoint(), step.GetPostStepPoint()
            status = post.GetStepStatus()
            proc = post.GetProcessDefinedStep()
            name = proc.GetProcessName() if proc is not None else ""
            if status == g4.G4StepStatus.fWorldBoundary:
                labels.append("MI")
            elif name == "OpAbsorption":
                labels.append("AB")
            elif name == "OpRayleigh":
                labels.append("SC")
            elif name == "OpWLS":
                labels.append("RE")
            elif status == g4.G4StepStatus.fGeomBoundary:
                if step.GetStepLength() <= STEP_TOO_SMALL:
                    # G4OpBoundaryProcess's StepTooSmall: no boundary action. Geant4
                    # takes such a step back across the surface after a reflection.
                    return
                track = step.GetTrack()
                if track.GetTrackStatus() == g4.G4TrackStatus.fStopAndKill:
                    if step.GetTotalEnergyDeposit() > 0 and not no_rindex_kill(pre, post):
                        labels.append("SD")
                        hit_times.append(post.GetGlobalTime() / g4.ns)
                        hit_wavelengths.append(HC_EV_NM / (pre.GetTotalEnergy() / g4.eV))
                        p = post.GetPosition()
                        hit_positions.append([p.x / g4.mm, p.y / g4.mm, p.z / g4.mm])
                    else:
                        labels.append("SA")
                    return
                if navigator[0] is None:
                    navigator[0] = g4.G4TransportationManager.GetTransportationManager() \
                        .GetNavigatorForTracking()
                n = navigator[0].GetGlobalExitNormal(post.GetPosition(), True)
                d0, d1 = pre.GetMomentumDirection(), post.GetMomentumDirection()
                before, after = d0.dot(n), d1.dot(n)
                if (before > 0) != (after > 0):
                    mirror = d0 - n * (2.0 * before)
                    surface = surface_of(volume(pre), volume(post))
                    metal = surface is not None and \
                        surface.GetType() == g4.G4SurfaceType.dielectric_metal
                    if (d1 - mirror).mag() > SPECULAR_TOLERANCE:
                        labels.append("DR")
                    else:
                        labels.append("SR" if metal else "BR")
                else:
                    labels.append("BT")
            else:
                labels.append("??" + name)

    g4.HepRandom.setTheSeed(args.seed)
    rm = g4.G4RunManagerFactory.CreateRunManager(g4.G4RunManagerType.Serial)
    detector, physics = Detector(), Physics()
    ui = g4.G4UImanager.GetUIpointer()
    for process in ("Cerenkov", "Scintillation", "OpWLS2", "OpMieHG"):
        ui.ApplyCommand("/process/optical/processActivation %s false" % process)
    rm.SetUserInitialization(detector)
    rm.SetUserInitialization(physics)
    gun, tracking, stepping = (SpeedGun() if args.speed else Gun()), Tracking(), Stepping()
    rm.SetUserAction(gun)
    if not args.speed:
        rm.SetUserAction(tracking)
        rm.SetUserAction(stepping)
    rm.Initialize()
    if args.speed:
        for c in gps_commands():
            ui.ApplyCommand(c)
    events = (args.n + PHOTONS_PER_EVENT - 1) // PHOTONS_PER_EVENT
    t1 = time.perf_counter()
    rm.BeamOn(events)
    beam_on = time.perf_counter() - t1
    if args.speed:
        real_out.write(json.dumps({
            "photons": args.n,
            "seconds": beam_on,
            "photons_per_s": args.n / beam_on,
        }) + "\n")
        real_out.flush()
        os._exit(0)

    # Counted from the hits, not the histories: a history keeps its first 16 labels.
    detected = len(hit_times)
    out = {
        "geant4": str(getattr(g4, "G4Version", "")).strip("$ ").replace("Name: ", ""),
        "photons": sum(histories.values()),
        "detected": detected,
        "histories": histories,
        "hit_times": hit_times,
        "hit_positions": hit_positions,
        "hit_wavelengths": hit_wavelengths,
        "seconds": time.time() - t0,
    }
    real_out.write(json.dumps(out) + "\n")
    real_out.flush()
    # Geant4's static destructors can crash at exit under pybind; the answer is out.
    os._exit(0)


if __name__ == "__main__":
    main()
