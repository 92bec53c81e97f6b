//! Storing mapped Geant4 solids in a Foundry: one Foundry solid per geometry, a CSG prim
//! or a mesh prim.

use hytrace_foundry::{Foundry, Triangle};

use crate::geant4::G4Geometry;
use crate::serialize::to_tree;
use crate::shape::CsgError;

/// Appends `geometry` as a new Foundry solid named `name`; returns its index. `identity`
/// is stored in the prim and the solid (e.g. the source solid's index).
pub fn add_geometry(
    f: &mut Foundry,
    name: &str,
    geometry: &G4Geometry,
    identity: u32,
) -> Result<u32, CsgError> {
    let store_error = |e: hytrace_foundry::FoundryError| CsgError {
        primitive: "foundry",
        problem: e.to_string(),
    };
    let mut b = f.begin_solid(name);
    match geometry {
        G4Geometry::Csg(shape) => {
            let tree = to_tree(shape)?;
            b.add_csg(tree, identity, hytrace_foundry::UNSET)
                .map_err(store_error)?;
        }
        G4Geometry::Mesh(tris) => {
            let tris: Vec<Triangle> = tris
                .iter()
                .map(|t| Triangle {
                    v: t.map(|v| [v[0] as f32, v[1] as f32, v[2] as f32, 0.0]),
                })
                .collect();
            b.add_mesh(&tris, None, identity, hytrace_foundry::UNSET)
                .map_err(store_error)?;
        }
    }
    b.finish(identity).map_err(store_error)
}
