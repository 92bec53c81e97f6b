//! GDML files as scenes: every physical volume of the Geant4 hierarchy becomes an instance
//! of its logical volume's solid, with its boundary and copy number.
//!
//! A logical volume placed many times is one Foundry solid and many instances. Every
//! instance's surface separates its material from its mother's: its boundary records both
//! materials and the optical surfaces Geant4's boundary process would find there (a border
//! surface of the ordered pair of physical volumes, else a skin surface of the daughter's,
//! else of the mother's logical volume). The world is an instance too: a ray that meets
//! nothing else reports where it leaves the world, as Geant4's navigator does.

use std::collections::HashMap;
use std::path::Path;

use crate::error::{bail, Context};
use hytrace_csg::add_geometry;
use hytrace_csg::geant4::G4Mapping;
use hytrace_foundry::gdml::{read_gdml, strip_name, Gdml, GdmlOptions, SurfaceLink};
use hytrace_foundry::optics::{Boundary, Optics};
use hytrace_foundry::{Foundry, Transform64, UNSET};

use crate::render::spec::VolumeLabel;

/// Distance within which meshes of solids with no analytic form (generic traps with twisted
/// faces) follow the true surface, in mm.
pub const GDML_MESH_TOLERANCE: f64 = 1e-3;

/// Most instances a file may expand into (about 2 GB of Foundry).
const MAX_INSTANCES: u64 = 10_000_000;

/// How many instances each logical volume expands into with its whole subtree, saturating
/// (an iterative post-order walk; the volume graph has no cycles, since a volume can only
/// place volumes defined before it or in other files).
fn subtree_sizes(g: &Gdml) -> Vec<u64> {
    const UNKNOWN: u64 = 0;
    let mut sizes = vec![UNKNOWN; g.volumes.len()];
    for root in 0..g.volumes.len() {
        let mut stack = vec![root];
        while let Some(&v) = stack.last() {
            if sizes[v] != UNKNOWN {
                stack.pop();
                continue;
            }
            let pending: Vec<usize> = g.volumes[v]
                .daughters
                .iter()
                .map(|d| d.volume)
                .filter(|&d| sizes[d] == UNKNOWN)
                .collect();
            if pending.is_empty() {
                sizes[v] = g.volumes[v]
                    .daughters
                    .iter()
                    .fold(1u64, |n, d| n.saturating_add(sizes[d.volume]));
                stack.pop();
            } else {
                stack.extend(pending);
            }
        }
    }
    sizes
}

/// The solids of a hierarchical scene's worlds (the instances without a mother), each
/// once; none for a flat scene. Renders leave them transparent so the detector shows.
pub(crate) fn world_solids(f: &Foundry) -> Vec<String> {
    let mut worlds: Vec<String> = Vec::new();
    if f.is_hierarchical() {
        for (inst, m) in f.inst.iter().zip(&f.inst_mother) {
            let solid = &f.solid_names[inst.solid as usize];
            if m.index == UNSET && !worlds.contains(solid) {
                worlds.push(solid.clone());
            }
        }
    }
    worlds
}

/// Reads a GDML file into a Foundry.
pub fn load_gdml_scene(path: &Path, options: &GdmlOptions) -> crate::Result<Foundry> {
    Ok(load_gdml_scene_with_surfaces(path, options)?.0)
}

/// Reads a GDML file into a Foundry, with what finds the optical surface of every crossing
/// ([`VolumeSurfaces`]).
pub fn load_gdml_scene_with_surfaces(
    path: &Path,
    options: &GdmlOptions,
) -> crate::Result<(Foundry, VolumeSurfaces)> {
    let gdml = read_gdml(path, options)?;
    for w in &gdml.warnings {
        eprintln!("warning: skipped {w}");
    }
    gdml_to_foundry_with_surfaces(&gdml)
        .with_context(|| format!("{}: building the scene", path.display()))
}

/// Reads a GDML file into a Foundry with the labels of its placed volumes (one per
/// instance): names, materials, and the colour and visibility its volumes' auxiliary
/// `Color` and `Visibility` entries give.
pub fn load_gdml_render_scene(
    path: &Path,
    options: &GdmlOptions,
) -> crate::Result<(Foundry, Vec<VolumeLabel>)> {
    let gdml = read_gdml(path, options)?;
    for w in &gdml.warnings {
        eprintln!("warning: skipped {w}");
    }
    let (f, surfaces) = gdml_to_foundry_with_surfaces(&gdml)
        .with_context(|| format!("{}: building the scene", path.display()))?;
    let mut labels = Vec::with_capacity(surfaces.placed.len());
    for (pv, lv) in &surfaces.placed {
        let v = &gdml.volumes[*lv];
        let (colour, visible) = volume_display(&v.auxiliary)
            .with_context(|| format!("{}: volume `{}`", path.display(), v.name))?;
        labels.push(VolumeLabel {
            physical: strip_name(pv).to_string(),
            logical: v.name.clone(),
            material: v
                .material
                .map(|m| gdml.materials[m].name.clone())
                .unwrap_or_default(),
            colour,
            visible,
        });
    }
    Ok((f, labels))
}

/// The colour (linear RGB) and visibility a volume's auxiliary entries give: `Color` (or
/// `Colour`) as three or four numbers in [0, 1] (sRGB, alpha ignored) or `#RRGGBB`,
/// `Visibility` (or `Visible`) as true/false/1/0.
fn volume_display(aux: &[(String, String)]) -> crate::Result<(Option<[f64; 3]>, Option<bool>)> {
    let (mut colour, mut visible) = (None, None);
    for (kind, value) in aux {
        match kind.to_ascii_lowercase().as_str() {
            "color" | "colour" => colour = Some(parse_colour(value)?),
            "visibility" | "visible" => {
                visible = Some(match value.trim().to_ascii_lowercase().as_str() {
                    "true" | "1" | "yes" => true,
                    "false" | "0" | "no" => false,
                    other => bail!("auxiliary {kind} `{other}`: expected true or false"),
                })
            }
            _ => {}
        }
    }
    Ok((colour, visible))
}

/// An sRGB colour as `R G B [A]` (or comma-separated) in [0, 1], or `#RRGGBB`, in linear RGB.
fn parse_colour(text: &str) -> crate::Result<[f64; 3]> {
    let bad = || {
        crate::Error::Invalid(format!(
            "auxiliary Color `{text}`: expected three or four numbers in [0, 1] or #RRGGBB"
        ))
    };
    let t = text.trim();
    let srgb: Vec<f64> = if let Some(hex) = t.strip_prefix('#') {
        if hex.len() != 6 || !hex.is_ascii() {
            return Err(bad());
        }
        (0..3)
            .map(|k| u8::from_str_radix(&hex[2 * k..2 * k + 2], 16).map(|v| v as f64 / 255.0))
            .collect::<Result<_, _>>()
            .map_err(|_| bad())?
    } else {
        t.split(|c: char| c == ',' || c.is_whitespace())
            .filter(|s| !s.is_empty())
            .map(|s| s.parse::<f64>().map_err(|_| bad()))
            .collect::<crate::Result<_>>()?
    };
    if !(3..=4).contains(&srgb.len()) || !srgb.iter().all(|v| (0.0..=1.0).contains(v)) {
        return Err(bad());
    }
    Ok(std::array::from_fn(|k| {
        let e = srgb[k];
        if e <= 0.04045 {
            e / 12.92
        } else {
            ((e + 0.055) / 1.055).powf(2.4)
        }
    }))
}

/// The border and skin surfaces of a GDML file, by physical volume name and logical volume.
#[derive(Clone, Debug)]
struct SurfaceRules {
    border: HashMap<(String, String), u32>,
    skin: HashMap<usize, u32>,
}

impl SurfaceRules {
    fn new(g: &Gdml) -> Self {
        let (mut border, mut skin) = (HashMap::new(), HashMap::new());
        for s in &g.logical_surfaces {
            match &s.link {
                SurfaceLink::Border(a, b) => {
                    border.insert((a.clone(), b.clone()), s.surface as u32);
                }
                SurfaceLink::Skin(v) => {
                    skin.insert(*v, s.surface as u32);
                }
            }
        }
        SurfaceRules { border, skin }
    }

    /// G4OpBoundaryProcess's lookup for a crossing from the placement `pre_pv` of logical
    /// volume `pre_lv` into `post_pv` of `post_lv`: the border surface of the ordered pair,
    /// else the skin of the volume entered when it is a daughter of the one left
    /// (`entered_daughter`) and then the other's, else the skin of the volume left and then
    /// of the one entered.
    fn between(
        &self,
        (pre_pv, pre_lv): (&str, usize),
        (post_pv, post_lv): (&str, usize),
        entered_daughter: bool,
    ) -> u32 {
        if let Some(&s) = self.border.get(&(pre_pv.to_string(), post_pv.to_string())) {
            return s;
        }
        let (first, second) = if entered_daughter {
            (post_lv, pre_lv)
        } else {
            (pre_lv, post_lv)
        };
        self.skin
            .get(&first)
            .or_else(|| self.skin.get(&second))
            .copied()
            .unwrap_or(UNSET)
    }
}

/// What Geant4's boundary process needs to find the optical surface of any crossing of a
/// GDML scene, siblings included (the boundary table holds only the crossings between an
/// instance and its mother): every instance's physical volume and logical volume, and the
/// file's border and skin surfaces.
#[derive(Clone, Debug)]
pub struct VolumeSurfaces {
    rules: SurfaceRules,
    /// Per instance: the physical volume's name (as border surfaces name it) and the
    /// logical volume's index.
    placed: Vec<(String, usize)>,
    /// Per instance: its mother instance, [`UNSET`] for the world.
    mother: Vec<u32>,
    /// The rules by instance, which [`VolumeSurfaces::between`] answers from.
    by_instance: InstanceRules,
}

/// The border and skin surfaces of a file by instance, for the lookup made at every
/// crossing of a photon: numbers only, no names to hash.
#[derive(Clone, Debug)]
struct InstanceRules {
    /// Per instance: its physical volume's name as a number (the same for instances of
    /// the same name).
    name: Vec<u32>,
    /// The border surfaces by the numbers of their ordered pair of names, sorted (those
    /// naming a volume no instance has are left out: no crossing meets them).
    border: Vec<((u32, u32), u32)>,
    /// Per instance: the skin surface of its logical volume, [`UNSET`] for none.
    skin: Vec<u32>,
}

impl InstanceRules {
    fn new(rules: &SurfaceRules, placed: &[(String, usize)]) -> Self {
        let mut numbers: HashMap<&str, u32> = HashMap::new();
        let name = placed
            .iter()
            .map(|(pv, _)| {
                let next = numbers.len() as u32;
                *numbers.entry(pv.as_str()).or_insert(next)
            })
            .collect();
        let mut border: Vec<_> = rules
            .border
            .iter()
            .filter_map(|((a, b), &s)| {
                Some(((*numbers.get(a.as_str())?, *numbers.get(b.as_str())?), s))
            })
            .collect();
        border.sort_unstable();
        let skin = placed
            .iter()
            .map(|(_, lv)| rules.skin.get(lv).copied().unwrap_or(UNSET))
            .collect();
        InstanceRules { name, border, skin }
    }
}

impl VolumeSurfaces {
    /// The optical surface (index into the Foundry's surfaces, [`UNSET`] for none) that
    /// applies when a photon crosses from instance `pre` into instance `post`, as
    /// G4OpBoundaryProcess finds it.
    pub fn between(&self, pre: u32, post: u32) -> u32 {
        // SurfaceRules::between on the instances' numbers (tested against it).
        let r = &self.by_instance;
        let pair = (r.name[pre as usize], r.name[post as usize]);
        if let Ok(k) = r.border.binary_search_by_key(&pair, |&(p, _)| p) {
            return r.border[k].1;
        }
        let (first, second) = if self.mother[post as usize] == pre {
            (post, pre)
        } else {
            (pre, post)
        };
        match r.skin[first as usize] {
            UNSET => r.skin[second as usize],
            s => s,
        }
    }

    /// [`Self::between`] from the file's rules by name, as built.
    #[cfg(test)]
    fn between_by_name(&self, pre: u32, post: u32) -> u32 {
        let at = |i: u32| {
            let (pv, lv) = &self.placed[i as usize];
            (pv.as_str(), *lv)
        };
        let entered_daughter = self.mother[post as usize] == pre;
        self.rules.between(at(pre), at(post), entered_daughter)
    }

    /// The skin surface of instance `i`'s logical volume ([`UNSET`] for none).
    pub fn skin(&self, i: u32) -> u32 {
        self.by_instance.skin[i as usize]
    }

    /// Every ordered pair of instances `(pre, post)` that a border surface names, with
    /// that surface.
    pub fn border_pairs(&self) -> Vec<(u32, u32, u32)> {
        let mut by_name: HashMap<&str, Vec<u32>> = HashMap::new();
        for (i, (pv, _)) in self.placed.iter().enumerate() {
            by_name.entry(pv.as_str()).or_default().push(i as u32);
        }
        let mut pairs = Vec::new();
        for ((a, b), &s) in &self.rules.border {
            let (Some(pre), Some(post)) = (by_name.get(a.as_str()), by_name.get(b.as_str())) else {
                continue;
            };
            for &p in pre {
                pairs.extend(post.iter().map(|&q| (p, q, s)));
            }
        }
        pairs.sort_unstable();
        pairs
    }

    /// Whether a border or skin surface of the file uses surface `s`.
    pub fn uses(&self, s: u32) -> bool {
        self.rules
            .border
            .values()
            .chain(self.rules.skin.values())
            .any(|&x| x == s)
    }
}

/// Interns boundaries and volume names.
#[derive(Default)]
struct Tables {
    boundaries: HashMap<Boundary, u32>,
    names: HashMap<String, u32>,
    optics: Optics,
}

impl Tables {
    fn boundary(&mut self, b: Boundary) -> u32 {
        let list = &mut self.optics.boundaries;
        *self.boundaries.entry(b).or_insert_with(|| {
            list.push(b);
            (list.len() - 1) as u32
        })
    }
    fn name(&mut self, n: &str) -> u32 {
        if let Some(&i) = self.names.get(n) {
            return i;
        }
        let i = self.optics.volumes.len() as u32;
        self.optics.volumes.push(n.to_string());
        self.names.insert(n.to_string(), i);
        i
    }
}

fn material_index(m: Option<usize>) -> u32 {
    m.map_or(UNSET, |m| m as u32)
}

/// Builds the Foundry of a read GDML file.
pub fn gdml_to_foundry(g: &Gdml) -> crate::Result<Foundry> {
    Ok(gdml_to_foundry_with_surfaces(g)?.0)
}

/// Builds the Foundry of a read GDML file and its [`VolumeSurfaces`].
pub fn gdml_to_foundry_with_surfaces(g: &Gdml) -> crate::Result<(Foundry, VolumeSurfaces)> {
    let total = subtree_sizes(g)[g.world];
    if total > MAX_INSTANCES {
        bail!("the hierarchy expands into {total} placements, more than {MAX_INSTANCES}");
    }
    let mut f = Foundry::new();
    // One Foundry solid per GDML solid that a placed volume uses, built on first use.
    let mut solid_of: HashMap<usize, u32> = HashMap::new();
    let mut foundry_solid = |f: &mut Foundry, solid: usize| -> crate::Result<u32> {
        if let Some(&s) = solid_of.get(&solid) {
            return Ok(s);
        }
        let gs = &g.solids[solid];
        let geometry = gs
            .solid
            .to_geometry(GDML_MESH_TOLERANCE)
            .with_context(|| format!("{}: solid `{}`", gs.origin, gs.name))?;
        let s = add_geometry(f, &gs.name, &geometry, solid as u32)
            .with_context(|| format!("{}: solid `{}`", gs.origin, gs.name))?;
        solid_of.insert(solid, s);
        Ok(s)
    };
    let rules = SurfaceRules::new(g);
    let mut tables = Tables::default();
    tables.optics.materials = g.materials.clone();
    tables.optics.surfaces = g.surfaces.clone();

    let world = &g.volumes[g.world];
    let world_name = format!("{}_PV", world.name);
    let solid = foundry_solid(&mut f, world.solid)?;
    let boundary = tables.boundary(Boundary {
        outer_material: UNSET,
        outer_surface: UNSET,
        inner_surface: UNSET,
        inner_material: material_index(world.material),
    });
    let identity = tables.name(&world_name);
    let world_instance = f.add_instance(solid, Transform64::IDENTITY, identity, 0)?;
    f.inst[world_instance].boundary = boundary;
    let mut placed = vec![(world_name.clone(), g.world)];

    // Depth-first walk: (logical volume, its placement name, world transform, instance).
    let mut stack: Vec<(usize, String, Transform64, usize)> =
        vec![(g.world, world_name, Transform64::IDENTITY, world_instance)];
    while let Some((mother, mother_pv, to_world, mother_instance)) = stack.pop() {
        for d in &g.volumes[mother].daughters {
            let lv = &g.volumes[d.volume];
            let transform = to_world.compose(&d.transform);
            let solid = foundry_solid(&mut f, lv.solid)?;
            let boundary = tables.boundary(Boundary {
                outer_material: material_index(g.volumes[mother].material),
                outer_surface: rules.between((&d.name, d.volume), (&mother_pv, mother), false),
                inner_surface: rules.between((&mother_pv, mother), (&d.name, d.volume), true),
                inner_material: material_index(lv.material),
            });
            let identity = tables.name(strip_name(&d.name));
            let i = f
                .add_instance(solid, transform, identity, d.copy_number)
                .with_context(|| format!("placing `{}` in `{}`", d.name, g.volumes[mother].name))?;
            f.inst[i].boundary = boundary;
            f.inst_mother[i].index = mother_instance as u32;
            placed.push((d.name.clone(), d.volume));
            if !lv.daughters.is_empty() {
                stack.push((d.volume, d.name.clone(), transform, i));
            }
        }
    }
    f.optics = tables.optics;
    f.validate().context("built an invalid Foundry")?;
    let mother = f.inst_mother.iter().map(|m| m.index).collect();
    let surfaces = VolumeSurfaces {
        by_instance: InstanceRules::new(&rules, &placed),
        rules,
        placed,
        mother,
    };
    Ok((f, surfaces))
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Skins on a mother and on its daughter (entering the daughter takes the daughter's
    /// first, leaving it its own), a border between siblings, and a border naming a
    /// physical volume that two instances share (`cell`, placed in each of two boxes).
    const NESTED_SURFACES: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<gdml>
  <define/>
  <materials>
    <material name="M" Z="1"><D value="1" unit="g/cm3"/><atom value="1.008"/></material>
  </materials>
  <solids>
    <box name="WorldBox" x="100" y="100" z="100" lunit="mm"/>
    <box name="OuterBox" x="40" y="40" z="40" lunit="mm"/>
    <box name="CellBox" x="10" y="10" z="10" lunit="mm"/>
    <opticalsurface name="S0" model="glisur" finish="polished" type="dielectric_dielectric" value="1"/>
    <opticalsurface name="S1" model="glisur" finish="polished" type="dielectric_dielectric" value="1"/>
    <opticalsurface name="S2" model="glisur" finish="polished" type="dielectric_dielectric" value="1"/>
    <opticalsurface name="S3" model="glisur" finish="polished" type="dielectric_dielectric" value="1"/>
  </solids>
  <structure>
    <volume name="Cell"><materialref ref="M"/><solidref ref="CellBox"/></volume>
    <volume name="Outer">
      <materialref ref="M"/><solidref ref="OuterBox"/>
      <physvol name="cell"><volumeref ref="Cell"/></physvol>
    </volume>
    <volume name="World">
      <materialref ref="M"/><solidref ref="WorldBox"/>
      <physvol name="left"><volumeref ref="Outer"/><position name="pl" x="-25" unit="mm"/></physvol>
      <physvol name="right"><volumeref ref="Outer"/><position name="pr" x="25" unit="mm"/></physvol>
    </volume>
    <skinsurface name="K0" surfaceproperty="S0"><volumeref ref="Outer"/></skinsurface>
    <skinsurface name="K1" surfaceproperty="S1"><volumeref ref="Cell"/></skinsurface>
    <bordersurface name="B2" surfaceproperty="S2"><physvolref ref="left"/><physvolref ref="right"/></bordersurface>
    <bordersurface name="B3" surfaceproperty="S3"><physvolref ref="cell"/><physvolref ref="left"/></bordersurface>
  </structure>
  <setup name="Default" version="1.0"><world ref="World"/></setup>
</gdml>
"#;

    /// The lookup by instance numbers answers what the file's rules by name answer, for
    /// every ordered pair of instances of scenes with border and skin surfaces (sibling
    /// crossings included), and those scenes meet both kinds.
    #[test]
    fn surface_lookup_by_instance_agrees_with_the_rules_by_name() {
        let root = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../tests/data/photons");
        let nested = std::env::temp_dir().join(format!(
            "hytrace-nested-surfaces-{}.gdml",
            std::process::id()
        ));
        std::fs::write(&nested, NESTED_SURFACES).unwrap();
        let files = [
            "every_process.gdml",
            "rough_surfaces.gdml",
            "media_tank.gdml",
        ];
        for path in files.iter().map(|f| root.join(f)).chain([nested.clone()]) {
            let file = path.file_name().unwrap().to_string_lossy().into_owned();
            let (f, v) = load_gdml_scene_with_surfaces(&path, &GdmlOptions::default()).unwrap();
            let n = f.inst.len() as u32;
            let (mut border, mut skin) = (0, 0);
            for pre in 0..n {
                for post in (0..n).filter(|&post| post != pre) {
                    let s = v.between(pre, post);
                    assert_eq!(s, v.between_by_name(pre, post), "{file}: {pre} -> {post}");
                    let named = |i: u32| v.placed[i as usize].0.clone();
                    if v.rules.border.contains_key(&(named(pre), named(post))) {
                        border += 1;
                    } else if s != UNSET {
                        skin += 1;
                    }
                }
            }
            assert!(skin > 0, "{file}: no crossing met a skin surface");
            if file != "rough_surfaces.gdml" && file != "media_tank.gdml" {
                assert!(border > 0, "{file}: no crossing met a border surface");
            }
        }
        std::fs::remove_file(&nested).unwrap();
    }
}
