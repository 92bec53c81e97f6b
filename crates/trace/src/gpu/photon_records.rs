//! The records of the GPU photon kernel (`shaders/kernels/photons.wgsl`): the run's
//! parameters, the flattened property tables of materials and surfaces
//! ([`crate::photons::gpu_tables`]), what every instance needs at a boundary, and one
//! photon's end. Generated into `shaders/generated/trace_records.wgsl` with the tracers'
//! records ([`super::records`]), whose test checks naga's layout against Rust's.

use hytrace_csg::gpu_layout::{entry, RecordEntry};
use hytrace_foundry::record;
use hytrace_foundry::wgsl::push_struct;

record! {
    /// What every photon of a GPU run shares: the torch source (or gensteps), the
    /// wavelength or spectrum, the run's photons and seed. The kernel reads it as a
    /// uniform buffer (which spares a storage buffer: a device may allow as few as 32 a
    /// stage), so its vectors are `vec4`s (a uniform's arrays need a stride of 16 bytes).
    pub struct PhotonParams {
        /// Point: the position; beam, sphere: the centre (mm); `w` unused (0).
        pub source_at: [f32; 4],
        /// Beam: the unit direction; `w` unused (0).
        pub source_direction: [f32; 4],
        /// `PHOTON_SOURCE_*` (`PHOTON_SOURCE_GENSTEPS`: photons from the gensteps).
        pub source_kind: u32,
        /// Beam: the disk's radius; sphere: the sphere's (mm).
        pub source_radius: f32,
        /// Beam: cosine of the divergence half-angle (1: parallel).
        pub cos_divergence: f32,
        /// Sphere: 1 when photons start inward.
        pub inward: u32,
        /// Photon energy (MeV).
        pub energy: f32,
        /// Wavelength (nm).
        pub wavelength_nm: f32,
        /// Low 32 bits of the index of the batch's first photon.
        pub first_lo: u32,
        /// High 32 bits of that index.
        pub first_hi: u32,
        /// Photons in this batch.
        pub photon_count: u32,
        /// Seed of the random streams.
        pub seed: u32,
        /// Steps after which a photon is stopped.
        pub max_steps: u32,
        /// 1 for a hierarchical scene (the navigator's answers).
        pub hierarchical: u32,
        /// 2: the trip count of the loop-budget probe (`shaders/loop_budget.wgsl`).
        pub probe_trips: u32,
        /// The table of a torch run's spectrum, `(energy, integral)` rows
        /// (`u32::MAX`: every photon at `energy`).
        pub spectrum: u32,
        /// Step points written per photon (`--records`; 0: none).
        pub records: u32,
        /// Padding to a multiple of 16 bytes, the size WGSL gives a struct of `vec4`s.
        pub pad: u32,
    }
}

record! {
    /// A property table: rows `first .. first + count` of the rows array, `(energy (MeV),
    /// value)` each, energies not decreasing.
    pub struct PhotonTable {
        /// First row.
        pub first: u32,
        /// Number of rows (at least 1).
        pub count: u32,
    }
}

record! {
    /// A material's tables (indices into the tables; `u32::MAX`: none).
    pub struct PhotonMaterial {
        /// RINDEX.
        pub rindex: u32,
        /// ABSLENGTH (mm).
        pub abslength: u32,
        /// RAYLEIGH (mm).
        pub rayleigh: u32,
        /// Group velocity (mm/ns).
        pub groupvel: u32,
        /// REEMISSIONPROB (`u32::MAX`: no re-emission).
        pub reemission: u32,
        /// Scintillation components a re-emitted photon follows (0 to 3).
        pub components: u32,
        /// Each component's spectrum, `(energy, integral)` rows.
        pub spectrum: [u32; 3],
        /// Each component's decay time (ns).
        pub decay: [f32; 3],
        /// Each component's rise time (ns; 0: none).
        pub rise: [f32; 3],
        /// Each component's yield.
        pub weight: [f32; 3],
        /// WLSABSLENGTH (`u32::MAX`: no wavelength shifting).
        pub wlsabslength: u32,
        /// WLSCOMPONENT, `(energy, integral)` rows (`u32::MAX`: a shifting absorption
        /// emits nothing).
        pub wls_spectrum: u32,
        /// WLSTIMECONSTANT (ns).
        pub wls_delay: f32,
        /// WLSMEANNUMBERPHOTONS (negative: one photon per absorption).
        pub wls_mean: f32,
    }
}

record! {
    /// An optical surface: its type, finish and model and its tables (indices into the
    /// tables; `u32::MAX`: the default, REFLECTIVITY 1, the others 0).
    pub struct PhotonSurface {
        /// `PHOTON_SURFACE_*`.
        pub kind: u32,
        /// REFLECTIVITY.
        pub reflectivity: u32,
        /// EFFICIENCY.
        pub efficiency: u32,
        /// TRANSMITTANCE.
        pub transmittance: u32,
        /// `PHOTON_FINISH_*` (Geant4's enumerator order).
        pub finish: u32,
        /// 1 for the unified model, 0 for glisur.
        pub unified: u32,
        /// The model's roughness: unified `sigma_alpha` (radians), glisur `polish`.
        pub roughness: f32,
        /// RINDEX of the gap behind a back-painted finish.
        pub rindex: u32,
        /// SPECULARSPIKECONSTANT (unified).
        pub spike: u32,
        /// SPECULARLOBECONSTANT (unified).
        pub lobe: u32,
        /// BACKSCATTERCONSTANT (unified).
        pub backscatter: u32,
        /// Padding.
        pub pad: u32,
    }
}

record! {
    /// What a photon needs of an instance: its material, mother and copy number, and the
    /// optical surfaces of its crossings (`u32::MAX`: none): entering it from its mother,
    /// leaving it into its mother, and towards or from a sibling when no border surface
    /// of the pair applies (the first of the volume left, else the second of the one
    /// entered).
    pub struct PhotonInstance {
        /// Material inside.
        pub material: u32,
        /// Mother instance.
        pub mother: u32,
        /// Copy number.
        pub copy: i32,
        /// Surface entering it from its mother.
        pub enter_surface: u32,
        /// Surface leaving it into its mother.
        pub leave_surface: u32,
        /// Surface leaving it into a sibling.
        pub sibling_leave: u32,
        /// Surface entering it from a sibling.
        pub sibling_enter: u32,
        /// Padding.
        pub pad: u32,
    }
}

record! {
    /// The surface of crossings from instance `pre` into its sibling `post` (a border
    /// surface), sorted by `(pre, post)`.
    pub struct PhotonBorder {
        /// Instance left.
        pub pre: u32,
        /// Instance entered.
        pub post: u32,
        /// Surface.
        pub surface: u32,
        /// Padding.
        pub pad: u32,
    }
}

record! {
    /// A genstep as the kernel emits photons from it
    /// ([`crate::photons::gensteps::Gensteps::gpu_records`]): the step, and what its kind
    /// needs (Cherenkov: the axis, mean beta, `sin^2` bound and the yields at the ends;
    /// scintillation: each component's photons, spectrum and time profile).
    pub struct PhotonGenstep {
        /// `PHOTON_GENSTEP_*`.
        pub kind: u32,
        /// Material index.
        pub material: u32,
        /// Index of the first photon after this step's (low, high 32 bits).
        pub end_index: [u32; 2],
        /// Start of the step (mm).
        pub start: [f32; 3],
        /// Time at the start (ns).
        pub time: f32,
        /// End of the step (mm).
        pub end: [f32; 3],
        /// Charge of the particle (e).
        pub charge: f32,
        /// Beta at the start and the end.
        pub beta: [f32; 2],
        /// Cherenkov: the mean beta.
        pub mean_beta: f32,
        /// Cherenkov: `sin^2` of the cone's largest angle (the rejection's bound).
        pub max_sin2: f32,
        /// Cherenkov: the unit direction of the step.
        pub axis: [f32; 3],
        /// Padding.
        pub pad: u32,
        /// Cherenkov: the relative yields at the two betas.
        pub yields: [f32; 2],
        /// Scintillation: photons of each component, in order.
        pub counts: [u32; 3],
        /// Scintillation: each component's spectrum, `(energy, integral)` rows.
        pub spectrum: [u32; 3],
        /// Scintillation: each component's decay time (ns).
        pub decay: [f32; 3],
        /// Scintillation: each component's rise time (ns; 0: none).
        pub rise: [f32; 3],
    }
}

record! {
    /// How one photon ended, for the photons the host needs more of than their history
    /// (detected, or to be propagated again on the CPU): appended by the kernel in the
    /// order they finish, each naming its photon.
    pub struct PhotonRecord {
        /// Where it ended (mm).
        pub position: [f32; 3],
        /// Time (ns).
        pub time: f32,
        /// Direction.
        pub direction: [f32; 3],
        /// Wavelength (nm).
        pub wavelength: f32,
        /// Polarization.
        pub polarization: [f32; 3],
        /// Instance whose surface detected it (`u32::MAX` when not detected).
        pub instance: u32,
        /// Packed history, low and high 32 bits.
        pub history: [u32; 2],
        /// History mask.
        pub mask: u32,
        /// Labels recorded.
        pub labels: u32,
        /// Steps taken.
        pub steps: u32,
        /// `PHOTON_STATUS_*` bits.
        pub status: u32,
        /// The photon: its index in the batch.
        pub photon: u32,
        /// Padding.
        pub pad: u32,
    }
}

/// [`PhotonParams::source_kind`]: isotropic from a point.
pub const PHOTON_SOURCE_POINT: u32 = 0;
/// A beam over a disk.
pub const PHOTON_SOURCE_BEAM: u32 = 1;
/// From a sphere along its normal.
pub const PHOTON_SOURCE_SPHERE: u32 = 2;
/// Photons from the gensteps ([`PhotonGenstep`]).
pub const PHOTON_SOURCE_GENSTEPS: u32 = 3;
/// [`PhotonGenstep::kind`]: a Cherenkov step.
pub const PHOTON_GENSTEP_CHERENKOV: u32 = 1;
/// A scintillation step.
pub const PHOTON_GENSTEP_SCINTILLATION: u32 = 2;
/// [`PhotonSurface::kind`]: `dielectric_metal`.
pub const PHOTON_SURFACE_METAL: u32 = 0;
/// `dielectric_dielectric`.
pub const PHOTON_SURFACE_DIELECTRIC: u32 = 1;
/// [`PhotonSurface::finish`]: polished.
pub const PHOTON_FINISH_POLISHED: u32 = 0;
/// Polished, painted on the surface.
pub const PHOTON_FINISH_POLISHED_FRONT_PAINTED: u32 = 1;
/// Polished, painted behind a gap.
pub const PHOTON_FINISH_POLISHED_BACK_PAINTED: u32 = 2;
/// Ground.
pub const PHOTON_FINISH_GROUND: u32 = 3;
/// Ground, painted on the surface.
pub const PHOTON_FINISH_GROUND_FRONT_PAINTED: u32 = 4;
/// Ground, painted behind a gap.
pub const PHOTON_FINISH_GROUND_BACK_PAINTED: u32 = 5;
/// [`PhotonRecord::status`] bit: detected (the record is a hit).
pub const PHOTON_DETECTED: u32 = 1;
/// Bit: the driver's loop budget cut the photon's loops short (llvmpipe); its record is
/// wrong and it is propagated again on the CPU.
pub const PHOTON_LOOPS_CUT: u32 = 2;
/// Bit: a wavelength-shifting absorption emitted two photons or more; the photon and
/// those it emitted are propagated on the CPU (the kernel carries one photon).
pub const PHOTON_SEVERAL_EMITTED: u32 = 8;
/// Bit: the placement tree was deeper than the navigator's loop bound (never for a
/// validated scene); propagated again on the CPU.
pub const PHOTON_DEPTH_LIMIT: u32 = 4;
/// Bit: the photon read a brick a streamed brick store's pool lacked; its results are
/// discarded and it runs again from its start in a later pass, once the brick is resident.
pub const PHOTON_MISSING_BRICK: u32 = 16;

/// The photon records, in declaration order.
pub fn photon_records() -> Vec<RecordEntry> {
    vec![
        entry::<PhotonParams>(),
        entry::<PhotonTable>(),
        entry::<PhotonMaterial>(),
        entry::<PhotonSurface>(),
        entry::<PhotonInstance>(),
        entry::<PhotonBorder>(),
        entry::<PhotonGenstep>(),
        entry::<PhotonRecord>(),
    ]
}

/// Appends the photon records and constants to the generated WGSL.
pub fn push_photon_wgsl(out: &mut String) {
    push_struct::<PhotonParams>(out);
    push_struct::<PhotonTable>(out);
    push_struct::<PhotonMaterial>(out);
    push_struct::<PhotonSurface>(out);
    push_struct::<PhotonInstance>(out);
    push_struct::<PhotonBorder>(out);
    push_struct::<PhotonGenstep>(out);
    push_struct::<PhotonRecord>(out);
    for (name, value) in [
        ("PHOTON_SOURCE_POINT", PHOTON_SOURCE_POINT),
        ("PHOTON_SOURCE_BEAM", PHOTON_SOURCE_BEAM),
        ("PHOTON_SOURCE_SPHERE", PHOTON_SOURCE_SPHERE),
        ("PHOTON_SOURCE_GENSTEPS", PHOTON_SOURCE_GENSTEPS),
        ("PHOTON_GENSTEP_CHERENKOV", PHOTON_GENSTEP_CHERENKOV),
        ("PHOTON_GENSTEP_SCINTILLATION", PHOTON_GENSTEP_SCINTILLATION),
        ("PHOTON_SURFACE_METAL", PHOTON_SURFACE_METAL),
        ("PHOTON_SURFACE_DIELECTRIC", PHOTON_SURFACE_DIELECTRIC),
        ("PHOTON_FINISH_POLISHED", PHOTON_FINISH_POLISHED),
        (
            "PHOTON_FINISH_POLISHED_FRONT_PAINTED",
            PHOTON_FINISH_POLISHED_FRONT_PAINTED,
        ),
        (
            "PHOTON_FINISH_POLISHED_BACK_PAINTED",
            PHOTON_FINISH_POLISHED_BACK_PAINTED,
        ),
        ("PHOTON_FINISH_GROUND", PHOTON_FINISH_GROUND),
        (
            "PHOTON_FINISH_GROUND_FRONT_PAINTED",
            PHOTON_FINISH_GROUND_FRONT_PAINTED,
        ),
        (
            "PHOTON_FINISH_GROUND_BACK_PAINTED",
            PHOTON_FINISH_GROUND_BACK_PAINTED,
        ),
        ("PHOTON_DETECTED", PHOTON_DETECTED),
        ("PHOTON_LOOPS_CUT", PHOTON_LOOPS_CUT),
        ("PHOTON_DEPTH_LIMIT", PHOTON_DEPTH_LIMIT),
        ("PHOTON_SEVERAL_EMITTED", PHOTON_SEVERAL_EMITTED),
        ("PHOTON_MISSING_BRICK", PHOTON_MISSING_BRICK),
    ] {
        out.push_str(&format!("const {name}: u32 = {value}u;\n"));
    }
    for (code, name) in crate::photons::output::LABELS {
        out.push_str(&format!("const LABEL_{name}: u32 = {code}u;\n"));
    }
}
