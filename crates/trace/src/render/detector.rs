//! Detector views of hierarchical scenes (GDML), as Geant4's visualization draws them: the
//! world invisible, envelopes (volumes with drawn daughters, or whose box holds a drawn
//! sibling's) as faint shells, the volumes inside them solid; a drawing depth, volumes shown or hidden by name, and a colour per
//! material, logical volume, solid, depth, boundary or copy number, with its legend.

use std::collections::BTreeMap;

use hytrace_csg::transform_bounds;
use hytrace_foundry::{Foundry, UNSET};
use thiserror::Error;

use super::spec::{Material, VolumeLabel};

/// How much of the light an envelope's shell stands for.
pub const SHELL_OPACITY: f64 = 0.12;

/// What the colours of a detector view tell apart.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, clap::ValueEnum)]
pub enum ColorBy {
    /// The volume's material.
    #[default]
    Material,
    /// The logical volume.
    Volume,
    /// The solid.
    Solid,
    /// The depth in the placement tree (the world's daughters are 1).
    Depth,
    /// The boundary: the pair of materials (mother's and own) its surface separates.
    Boundary,
    /// The copy number.
    Copy,
}

/// What a detector view draws and how it colours it.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct DetectorStyle {
    /// Deepest level drawn (the world is 0, its daughters 1; with `show`, the shown volumes
    /// are 0); `None`: every level.
    pub depth: Option<u32>,
    /// Glob patterns (case-insensitive, on logical or physical volume names): only the
    /// matching volumes and their contents are drawn (empty: everything).
    pub show: Vec<String>,
    /// Glob patterns: the matching volumes are not drawn (their daughters still are).
    pub hide: Vec<String>,
    /// What the colours tell apart; `None`: materials, with the colours the file gives.
    pub color_by: Option<ColorBy>,
}

/// Why a detector style cannot be applied.
#[derive(Debug, Error, PartialEq)]
pub enum DetectorError {
    /// A `--show` or `--hide` pattern matches no volume.
    #[error("{option} {pattern}: no logical or physical volume matches{}", did_you_mean(.suggestions))]
    NoMatch {
        /// The option (`--show` or `--hide`).
        option: &'static str,
        /// The pattern.
        pattern: String,
        /// The nearest names.
        suggestions: Vec<String>,
    },
    /// The scene has no volume labels for its instances (a flat scene).
    #[error("the scene has no placement hierarchy: --depth, --show, --hide and --color-by apply to GDML detectors")]
    NotHierarchical,
}

fn did_you_mean(names: &[String]) -> String {
    if names.is_empty() {
        String::new()
    } else {
        format!("; did you mean {}?", names.join(", "))
    }
}

/// One colour of a legend.
#[derive(Clone, Debug, PartialEq)]
pub struct LegendEntry {
    /// The name coloured (a material, a volume, `depth 2`, ...).
    pub name: String,
    /// Linear RGB.
    pub colour: [f64; 3],
    /// How many drawn placements have it.
    pub volumes: usize,
}

/// What the colours of a detector view mean.
#[derive(Clone, Debug, PartialEq)]
pub struct Legend {
    /// What the colours tell apart (`material`, `volume`, ...; `file` when the file's own
    /// colours were used for some volumes).
    pub color_by: String,
    /// One entry per colour, by name.
    pub entries: Vec<LegendEntry>,
}

/// A detector view's materials: one per instance, and the legend of their colours.
#[derive(Clone, Debug, PartialEq)]
pub struct DetectorView {
    /// Per instance: transparent (not drawn), a shell (an envelope) or diffuse (drawn solid).
    pub materials: Vec<Material>,
    /// The colours' legend.
    pub legend: Legend,
}

/// Whether `text` matches the glob `pattern` (`*`: any run, `?`: any one character),
/// ignoring case.
pub fn glob_matches(pattern: &str, text: &str) -> bool {
    let p: Vec<char> = pattern.to_lowercase().chars().collect();
    let t: Vec<char> = text.to_lowercase().chars().collect();
    // Iterative matching with one backtrack point: the last `*` and where it resumed.
    let (mut i, mut j, mut star, mut resume) = (0, 0, None, 0);
    while j < t.len() {
        if i < p.len() && (p[i] == '?' || p[i] == t[j]) {
            i += 1;
            j += 1;
        } else if i < p.len() && p[i] == '*' {
            star = Some(i);
            resume = j;
            i += 1;
        } else if let Some(s) = star {
            i = s + 1;
            resume += 1;
            j = resume;
        } else {
            return false;
        }
    }
    p[i..].iter().all(|&c| c == '*')
}

/// The labels a Foundry alone gives its instances: physical volume names from the
/// identities, the solid's name for the logical volume, the inner material of the
/// boundary; none for a flat scene.
pub fn foundry_labels(f: &Foundry) -> Vec<VolumeLabel> {
    if f.inst_mother.iter().all(|m| m.index == UNSET) {
        return Vec::new();
    }
    let o = &f.optics;
    f.inst
        .iter()
        .map(|inst| {
            let solid = f.solid_names[inst.solid as usize].clone();
            let material = o
                .boundaries
                .get(inst.boundary as usize)
                .and_then(|b| o.materials.get(b.inner_material as usize))
                .map(|m| m.name.clone())
                .unwrap_or_default();
            VolumeLabel {
                physical: o
                    .volumes
                    .get(inst.identity as usize)
                    .cloned()
                    .unwrap_or_default(),
                logical: solid,
                material,
                colour: None,
                visible: None,
            }
        })
        .collect()
}

/// A distinct, light colour for the `k`-th key: hues a golden angle apart.
pub fn palette(k: usize) -> [f64; 3] {
    let hue = (k as f64 * 0.618_033_988_749_895).fract() * 6.0;
    let (s, v) = (0.55, 0.92);
    let c = v * s;
    let x = c * (1.0 - ((hue % 2.0) - 1.0).abs());
    let m = v - c;
    let rgb = match hue as u32 {
        0 => [c, x, 0.0],
        1 => [x, c, 0.0],
        2 => [0.0, c, x],
        3 => [0.0, x, c],
        4 => [x, 0.0, c],
        _ => [c, 0.0, x],
    };
    // sRGB-encoded values to linear radiance, so the image shows these hues.
    rgb.map(|e| {
        let e: f64 = e + m;
        if e <= 0.04045 {
            e / 12.92
        } else {
            ((e + 0.055) / 1.055).powf(2.4)
        }
    })
}

impl Legend {
    /// The legend as JSON: what the colours tell apart and, per colour, its name, linear
    /// and 8-bit sRGB values and how many drawn placements have it.
    pub fn to_json(&self) -> serde_json::Value {
        let entries: Vec<serde_json::Value> = self
            .entries
            .iter()
            .map(|e| {
                serde_json::json!({
                    "name": e.name,
                    "linear_rgb": e.colour,
                    "srgb8": e.colour.map(|c| super::output::srgb8(c as f32)),
                    "volumes": e.volumes,
                })
            })
            .collect();
        serde_json::json!({ "color_by": self.color_by, "entries": entries })
    }
}

impl DetectorStyle {
    /// The materials and legend of this view of `f`, whose volumes `labels` names (one per
    /// instance). Errors on a pattern that matches nothing, naming the nearest names.
    pub fn apply(
        &self,
        f: &Foundry,
        labels: &[VolumeLabel],
    ) -> Result<DetectorView, DetectorError> {
        let n = f.inst.len();
        if labels.len() != n {
            return Err(DetectorError::NotHierarchical);
        }
        let mother: Vec<Option<usize>> = f
            .inst_mother
            .iter()
            .map(|m| (m.index != UNSET).then_some(m.index as usize))
            .collect();
        // Mothers come before their daughters: one pass down the tree.
        let mut depth = vec![0u32; n];
        for i in 0..n {
            if let Some(m) = mother[i] {
                depth[i] = depth[m] + 1;
            }
        }
        let matches = |option: &'static str, pattern: &str| -> Result<Vec<bool>, DetectorError> {
            let hit: Vec<bool> = labels
                .iter()
                .map(|l| glob_matches(pattern, &l.physical) || glob_matches(pattern, &l.logical))
                .collect();
            if hit.iter().any(|&h| h) {
                return Ok(hit);
            }
            Err(DetectorError::NoMatch {
                option,
                pattern: pattern.to_string(),
                suggestions: nearest_names(pattern, labels),
            })
        };
        let mut hidden = vec![false; n];
        for p in &self.hide {
            for (h, m) in hidden.iter_mut().zip(matches("--hide", p)?) {
                *h |= m;
            }
        }
        // The level each instance is drawn at: its depth below the nearest shown ancestor
        // (itself included), or below the world; `None` outside what is shown.
        let level: Vec<Option<u32>> = if self.show.is_empty() {
            depth.iter().map(|&d| Some(d)).collect()
        } else {
            let mut shown = vec![false; n];
            for p in &self.show {
                for (s, m) in shown.iter_mut().zip(matches("--show", p)?) {
                    *s |= m;
                }
            }
            let mut level = vec![None; n];
            for i in 0..n {
                level[i] = if shown[i] {
                    Some(0)
                } else {
                    mother[i].and_then(|m| level[m]).map(|l: u32| l + 1)
                };
            }
            level
        };
        let only_world = n == 1;
        let drawn: Vec<bool> = (0..n)
            .map(|i| {
                let Some(l) = level[i] else { return false };
                let world = mother[i].is_none() && self.show.is_empty() && !only_world;
                !world
                    && !hidden[i]
                    && labels[i].visible != Some(false)
                    && self.depth.is_none_or(|d| l <= d)
            })
            .collect();
        // Envelopes: drawn volumes with a drawn volume inside (daughters come after mothers).
        let mut holds_drawn = vec![false; n];
        for i in (0..n).rev() {
            if let Some(m) = mother[i] {
                holds_drawn[m] |= drawn[i] || holds_drawn[i];
            }
        }
        // Volumes whose box holds a drawn sibling's (a hollow sphere around another, a tube
        // around a rod) are shells too, so what they enclose shows.
        let encloses = enclosing_siblings(f, &mother, &drawn);
        let by = self.color_by.unwrap_or_default();
        let key = |i: usize| -> String {
            let l = &labels[i];
            match by {
                ColorBy::Material if l.material.is_empty() => "(no material)".into(),
                ColorBy::Material => l.material.clone(),
                ColorBy::Volume => l.logical.clone(),
                ColorBy::Solid => f.solid_names[f.inst[i].solid as usize].clone(),
                ColorBy::Depth => format!("depth {}", depth[i]),
                ColorBy::Boundary => {
                    let outer = mother[i].map_or("(outside)", |m| labels[m].material.as_str());
                    format!("{outer} | {}", l.material)
                }
                ColorBy::Copy => format!("copy {}", f.inst[i].copy_number),
            }
        };
        // The file's colours count unless a colouring was asked for.
        let file_colour = |i: usize| labels[i].colour.filter(|_| self.color_by.is_none());
        let mut keys: BTreeMap<String, usize> = BTreeMap::new();
        for i in (0..n).filter(|&i| drawn[i] && file_colour(i).is_none()) {
            *keys.entry(key(i)).or_default() += 1;
        }
        let colour_of: BTreeMap<&str, [f64; 3]> = keys
            .keys()
            .enumerate()
            .map(|(k, name)| (name.as_str(), palette(k)))
            .collect();
        let mut entries: Vec<LegendEntry> = keys
            .iter()
            .map(|(name, &volumes)| LegendEntry {
                name: name.clone(),
                colour: colour_of[name.as_str()],
                volumes,
            })
            .collect();
        let mut file_entries: BTreeMap<String, LegendEntry> = BTreeMap::new();
        let materials = (0..n)
            .map(|i| {
                if !drawn[i] {
                    return Material::Transparent;
                }
                let colour = match file_colour(i) {
                    Some(c) => {
                        let e =
                            file_entries
                                .entry(labels[i].logical.clone())
                                .or_insert(LegendEntry {
                                    name: labels[i].logical.clone(),
                                    colour: c,
                                    volumes: 0,
                                });
                        e.volumes += 1;
                        c
                    }
                    None => colour_of[key(i).as_str()],
                };
                if holds_drawn[i] || encloses[i] {
                    Material::Shell {
                        colour,
                        opacity: SHELL_OPACITY,
                    }
                } else {
                    Material::Diffuse { colour }
                }
            })
            .collect();
        let mut color_by = format!("{by:?}").to_lowercase();
        if !file_entries.is_empty() {
            color_by.push_str(" (file colours by logical volume)");
            entries.extend(file_entries.into_values());
        }
        Ok(DetectorView {
            materials,
            legend: Legend { color_by, entries },
        })
    }
}

/// Most siblings compared pairwise for enclosure (larger groups are left as they are).
const MAX_ENCLOSURE_GROUP: usize = 4096;

/// Per instance: whether it is drawn and its world box holds the box of a smaller drawn
/// sibling.
fn enclosing_siblings(f: &Foundry, mother: &[Option<usize>], drawn: &[bool]) -> Vec<bool> {
    let boxes: Vec<[f64; 6]> = f
        .inst
        .iter()
        .zip(&f.inst_tran)
        .map(|(inst, tran)| {
            let a = f.solid[inst.solid as usize].aabb.map(f64::from);
            transform_bounds(&a, &tran.to_transform())
        })
        .collect();
    let mut groups: BTreeMap<Option<usize>, Vec<usize>> = BTreeMap::new();
    for i in (0..drawn.len()).filter(|&i| drawn[i]) {
        groups.entry(mother[i]).or_default().push(i);
    }
    let volume = |b: &[f64; 6]| (0..3).map(|k| (b[k + 3] - b[k]).max(0.0)).product::<f64>();
    let holds = |a: &[f64; 6], b: &[f64; 6]| {
        // Within a millionth of the larger box's size: f32 boxes of coincident faces.
        let tol = 1e-6 * (0..3).map(|k| a[k + 3] - a[k]).fold(0.0, f64::max);
        (0..3).all(|k| a[k] <= b[k] + tol && b[k + 3] <= a[k + 3] + tol) && volume(b) < volume(a)
    };
    let mut out = vec![false; drawn.len()];
    for members in groups.values().filter(|m| m.len() <= MAX_ENCLOSURE_GROUP) {
        for &i in members {
            out[i] = members
                .iter()
                .any(|&j| j != i && holds(&boxes[i], &boxes[j]));
        }
    }
    out
}

/// Up to three volume names nearest `pattern` (Jaro-Winkler similarity, ignoring case and
/// the pattern's wildcards).
fn nearest_names(pattern: &str, labels: &[VolumeLabel]) -> Vec<String> {
    let bare: String = pattern
        .chars()
        .filter(|c| !matches!(c, '*' | '?'))
        .collect::<String>()
        .to_lowercase();
    let mut names: Vec<&str> = labels
        .iter()
        .flat_map(|l| [l.physical.as_str(), l.logical.as_str()])
        .filter(|s| !s.is_empty())
        .collect();
    names.sort_unstable();
    names.dedup();
    let mut scored: Vec<(f64, &str)> = names
        .into_iter()
        .map(|s| (strsim::jaro_winkler(&bare, &s.to_lowercase()), s))
        .filter(|(score, _)| *score > 0.6)
        .collect();
    scored.sort_by(|a, b| b.0.total_cmp(&a.0).then(a.1.cmp(b.1)));
    scored
        .into_iter()
        .take(3)
        .map(|(_, s)| s.to_string())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn globs_match_ignoring_case() {
        assert!(glob_matches("cal*", "Calorimeter"));
        assert!(glob_matches("*LAYER?", "gap_layer7"));
        assert!(glob_matches("a*b*c", "aXXbYYc"));
        assert!(!glob_matches("a*b*c", "aXXbYY"));
        assert!(!glob_matches("world", "worlds"));
        assert!(glob_matches("*", ""));
    }

    #[test]
    fn palette_colours_differ_and_are_in_range() {
        let colours: Vec<[f64; 3]> = (0..12).map(palette).collect();
        for (a, ca) in colours.iter().enumerate() {
            assert!(ca.iter().all(|c| (0.0..=1.0).contains(c)));
            for cb in &colours[a + 1..] {
                let d: f64 = (0..3).map(|k| (ca[k] - cb[k]).abs()).sum();
                assert!(d > 0.02, "{ca:?} {cb:?}");
            }
        }
    }
}
