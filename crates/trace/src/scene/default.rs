//! The embedded default scene: a detector-like vessel built from CSG booleans.
//!
//! An acrylic-like spherical shell with a chimney, a torus support ring, a floor slab, a ring
//! of PMT-like solids (ellipsoidal window on a cylindrical neck) placed as instances facing
//! the centre, and a procedural fog sphere (8^3 bricks) filling the vessel.

use std::f64::consts::PI;

use crate::error::Context;
use hytrace_csg::{box3, cylinder, sphere, to_tree, torus, Shape};
use hytrace_foundry::{Foundry, Transform64, UNSET};
use hytrace_volume::TexelFormat;

use super::media::{add_medium_solid, MediumSpec};
use crate::render::camera::CameraSpec;
use crate::render::spec::{Light, Material, MediumOptics, RenderSettings, RenderSpec};

/// Number of PMT-like instances in the default scene.
pub const DEFAULT_PMT_COUNT: usize = 48;

/// Extinction of the default scene's fog per mm at grid value 1.
pub const DEFAULT_FOG_DENSITY: f64 = 0.002;

fn add_csg_solid(f: &mut Foundry, name: &str, shape: &Shape, identity: u32) -> crate::Result<u32> {
    let tree = to_tree(shape).with_context(|| format!("solid `{name}`"))?;
    let mut s = f.begin_solid(name);
    s.add_csg(tree, identity, UNSET)?;
    Ok(s.finish(identity)?)
}

/// Rotation taking local +z to the unit vector `dir`, followed by a translation to `at`.
fn facing(dir: [f64; 3], at: [f64; 3]) -> Transform64 {
    // Orthonormal frame (u, v, dir) with u perpendicular to z where possible.
    let helper = if dir[2].abs() < 0.9 {
        [0.0, 0.0, 1.0]
    } else {
        [1.0, 0.0, 0.0]
    };
    let cross = |a: [f64; 3], b: [f64; 3]| {
        [
            a[1] * b[2] - a[2] * b[1],
            a[2] * b[0] - a[0] * b[2],
            a[0] * b[1] - a[1] * b[0],
        ]
    };
    let norm = |a: [f64; 3]| {
        let l = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        a.map(|x| x / l)
    };
    let u = norm(cross(helper, dir));
    let v = cross(dir, u);
    Transform64 {
        rows: [
            [u[0], v[0], dir[0], at[0]],
            [u[1], v[1], dir[1], at[1]],
            [u[2], v[2], dir[2], at[2]],
            [0.0, 0.0, 0.0, 1.0],
        ],
    }
}

/// Builds the default scene.
pub fn default_scene() -> crate::Result<Foundry> {
    let mut f = Foundry::new();
    let shell = sphere(1000.0)? - sphere(980.0)?;
    let chimney = cylinder(150.0, 900.0, 1400.0)? - cylinder(130.0, 890.0, 1410.0)?;
    let vessel = add_csg_solid(&mut f, "vessel", &(shell + chimney), 0)?;
    let ring = add_csg_solid(&mut f, "support_ring", &torus(0.0, 25.0, 1010.0)?, 1)?;
    let floor = add_csg_solid(&mut f, "floor", &box3(5000.0, 5000.0, 200.0)?, 2)?;
    // PMT: ellipsoidal window (a scaled sphere) on a neck, pointing along local +z.
    let pmt_shape = sphere(100.0)?.scale(1.0, 1.0, 0.6) + cylinder(45.0, -180.0, 0.0)?;
    let pmt = add_csg_solid(&mut f, "pmt", &pmt_shape, 3)?;

    // Fog: a sphere of radius 720 mm in 30 mm voxels (24 voxels, blended over the outer 6),
    // with an optical depth of about 2.9 along a diameter at full density.
    let fog = add_medium_solid(
        &mut f,
        "fog",
        &MediumSpec {
            source: "sphere:720,30,6".into(),
            grid: None,
            density_scale: DEFAULT_FOG_DENSITY,
            format: Some(TexelFormat::F32),
            placement: Transform64::IDENTITY,
        },
        4,
    )?;

    f.add_instance(vessel, Transform64::IDENTITY, 0, 0)?;
    f.add_instance(fog, Transform64::IDENTITY, 4, 0)?;
    f.add_instance(ring, Transform64::IDENTITY, 1, 0)?;
    f.add_instance(floor, Transform64::translation([0.0, 0.0, -1600.0]), 2, 0)?;
    // PMTs on a sphere of radius 1300 (golden-angle spiral), windows facing the centre.
    let golden = PI * (3.0 - 5f64.sqrt());
    for i in 0..DEFAULT_PMT_COUNT {
        let z = 1.0 - 2.0 * (i as f64 + 0.5) / DEFAULT_PMT_COUNT as f64;
        let r = (1.0 - z * z).sqrt();
        let phi = golden * i as f64;
        let out = [r * phi.cos(), r * phi.sin(), z];
        let at = out.map(|c| 1300.0 * c);
        f.add_instance(pmt, facing(out.map(|c| -c), at), 3, i as i32)?;
    }
    f.validate()?;
    Ok(f)
}

/// How the default scene renders: an acrylic vessel (index 1.49, 2 m absorption length)
/// holding the scattering fog, a mirror support ring, PMTs with brownish photocathodes, a
/// grey floor, lit by a point light above, a low sun and a dim sky.
pub fn default_render_spec() -> RenderSpec {
    let materials = [
        (
            "acrylic",
            Material::Dielectric {
                ior: 1.49,
                absorption_length: Some(2000.0),
            },
        ),
        (
            "steel",
            Material::Mirror {
                colour: [0.8, 0.8, 0.82],
            },
        ),
        (
            "photocathode",
            Material::Diffuse {
                colour: [0.55, 0.4, 0.2],
            },
        ),
        (
            "concrete",
            Material::Diffuse {
                colour: [0.45, 0.45, 0.42],
            },
        ),
    ];
    let assignments = [
        ("vessel", "acrylic"),
        ("support_ring", "steel"),
        ("pmt", "photocathode"),
        ("floor", "concrete"),
    ];
    RenderSpec {
        camera: Some(CameraSpec {
            eye: [3600.0, -4300.0, 1500.0],
            target: [0.0, 0.0, -250.0],
            up: [0.0, 0.0, 1.0],
            fov: Some(38.0),
            orthographic: None,
        }),
        materials: materials.map(|(n, m)| (n.to_string(), m)).into(),
        solid_materials: assignments
            .map(|(s, m)| (s.to_string(), m.to_string()))
            .into(),
        lights: vec![
            Light::Point {
                position: [0.0, 0.0, 3000.0],
                intensity: [6.0e6, 5.6e6, 5.0e6],
            },
            Light::Directional {
                direction: [-0.5, 0.8, -0.6],
                irradiance: [1.2, 1.2, 1.1],
            },
            Light::Environment {
                radiance: [0.12, 0.14, 0.18],
            },
        ],
        media: [(
            "fog".to_string(),
            MediumOptics {
                albedo: 0.9,
                g: 0.3,
                emission: [0.0; 3],
            },
        )]
        .into(),
        settings: RenderSettings::default(),
        ..RenderSpec::default()
    }
}
