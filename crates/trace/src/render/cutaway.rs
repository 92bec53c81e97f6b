//! Cutaways and sections, as Geant4's cutaway planes: up to three planes, each removing
//! what lies on the side its normal points to; in `union` mode a point is drawn when any
//! plane keeps it, in `intersection` mode only when every plane does. A ray meets the
//! geometry only over the stretches of its path that are kept; where it enters a kept
//! stretch through a plane inside a volume drawn solid, that volume's section shows there
//! (the renderer locates the point as the navigator does).

use std::str::FromStr;

use glam::DVec3;

/// Most cut planes.
pub const MAX_CUTS: usize = 3;

/// A cut plane `normal . p = offset`, removing the side `normal . p > offset`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct CutPlane {
    /// Unit normal, pointing into the removed side.
    pub normal: [f64; 3],
    /// The plane's signed distance from the origin along the normal.
    pub offset: f64,
}

/// How the kept sides of several planes combine (Geant4's cutaway modes).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum CutMode {
    /// A point is drawn when any plane keeps it (the planes remove only what all remove).
    #[default]
    Union,
    /// A point is drawn only when every plane keeps it.
    Intersection,
}

crate::choice::named!(CutMode {
    (CutMode::Union, "union", [], "A point is drawn when any plane keeps it"),
    (CutMode::Intersection, "intersection", [], "A point is drawn only when every plane keeps it"),
});

/// The cut planes of a render (none: nothing is cut).
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Cutaway {
    /// At most [`MAX_CUTS`] planes.
    pub planes: Vec<CutPlane>,
    /// How their kept sides combine.
    pub mode: CutMode,
}

/// A kept stretch `[start, end]` of a ray's path, and the plane it enters through (`None`
/// when it starts at the ray's origin).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct KeptPiece {
    /// Where it starts (>= 0).
    pub start: f64,
    /// Where it ends (may be infinite).
    pub end: f64,
    /// The plane crossed at `start`.
    pub entry: Option<usize>,
}

impl FromStr for CutPlane {
    type Err = String;

    /// `x=C`, `y=C`, `z=C` (removing the side above C; `-x=C` the side below), or
    /// `NX,NY,NZ:D` (the plane `n . p = D`, removing the side `n` points to; `n` need not
    /// be a unit vector).
    fn from_str(text: &str) -> Result<Self, String> {
        let bad = |why: &str| {
            format!("`{text}`: {why}; expected AXIS=VALUE (x=0, -z=10) or NX,NY,NZ:D (1,1,0:0)")
        };
        let number = |s: &str| -> Result<f64, String> {
            s.trim()
                .parse::<f64>()
                .ok()
                .filter(|v| v.is_finite())
                .ok_or_else(|| bad(&format!("`{}` is not a finite number", s.trim())))
        };
        let (normal, offset) = if let Some((axis, value)) = text.split_once('=') {
            let axis = axis.trim().to_lowercase();
            let (sign, name) = match axis.strip_prefix('-') {
                Some(rest) => (-1.0, rest.trim()),
                None => (1.0, axis.trim_start_matches('+').trim()),
            };
            let k = match name {
                "x" => 0,
                "y" => 1,
                "z" => 2,
                _ => return Err(bad(&format!("unknown axis `{name}`"))),
            };
            let mut n = [0.0; 3];
            n[k] = sign;
            (n, sign * number(value)?)
        } else if let Some((n, d)) = text.split_once(':') {
            let parts: Vec<&str> = n.split(',').collect();
            if parts.len() != 3 {
                return Err(bad("the normal needs three components"));
            }
            let n: Vec<f64> = parts.iter().map(|s| number(s)).collect::<Result<_, _>>()?;
            let len = (n[0] * n[0] + n[1] * n[1] + n[2] * n[2]).sqrt();
            if len == 0.0 {
                return Err(bad("the normal is zero"));
            }
            ([n[0] / len, n[1] / len, n[2] / len], number(d)? / len)
        } else {
            return Err(bad("no `=` or `:`"));
        };
        Ok(CutPlane { normal, offset })
    }
}

impl CutPlane {
    /// `normal . p - offset`: positive on the removed side.
    fn signed(&self, p: DVec3) -> f64 {
        DVec3::from(self.normal).dot(p) - self.offset
    }

    /// The stretch `[lo, hi]` of the ray `o + t d` (any real `t`) that the plane keeps
    /// (empty: `lo > hi`).
    fn kept(&self, o: DVec3, d: DVec3) -> [f64; 2] {
        let (s0, nd) = (self.signed(o), DVec3::from(self.normal).dot(d));
        let inf = f64::INFINITY;
        if nd == 0.0 {
            return if s0 <= 0.0 { [-inf, inf] } else { [inf, -inf] };
        }
        let t = -s0 / nd;
        if nd > 0.0 {
            [-inf, t]
        } else {
            [t, inf]
        }
    }
}

impl Cutaway {
    /// Whether anything is cut.
    pub fn is_empty(&self) -> bool {
        self.planes.is_empty()
    }

    /// Refuses more than [`MAX_CUTS`] planes.
    pub fn validate(&self) -> Result<(), String> {
        if self.planes.len() > MAX_CUTS {
            return Err(format!(
                "--cut given {} times: at most {MAX_CUTS} planes",
                self.planes.len()
            ));
        }
        Ok(())
    }

    /// Whether the point `p` is drawn.
    pub fn keeps(&self, p: DVec3) -> bool {
        let mut kept = self.planes.iter().map(|c| c.signed(p) <= 0.0);
        match self.mode {
            _ if self.planes.is_empty() => true,
            CutMode::Union => kept.any(|k| k),
            CutMode::Intersection => kept.all(|k| k),
        }
    }

    /// The kept stretches of the ray `o + t d` at `t >= 0`, in order (at most two).
    pub fn pieces(&self, o: DVec3, d: DVec3) -> Vec<KeptPiece> {
        let inf = f64::INFINITY;
        if self.planes.is_empty() {
            return vec![KeptPiece {
                start: 0.0,
                end: inf,
                entry: None,
            }];
        }
        let kept: Vec<[f64; 2]> = self.planes.iter().map(|c| c.kept(o, d)).collect();
        // (start, entry plane, end) of the stretches before clipping to t >= 0.
        let mut raw: Vec<(f64, Option<usize>, f64)> = Vec::with_capacity(2);
        match self.mode {
            CutMode::Intersection => {
                let (mut lo, mut entry, mut hi) = (-inf, None, inf);
                for (k, &[l, h]) in kept.iter().enumerate() {
                    if l > lo {
                        (lo, entry) = (l, Some(k));
                    }
                    hi = hi.min(h);
                }
                raw.push((lo, entry, hi));
            }
            CutMode::Union => {
                // Every plane removes one stretch (the complement of what it keeps); what
                // all remove is their intersection (removed_lo, removed_hi).
                let (mut rlo, mut rhi, mut exit) = (-inf, inf, None);
                for (k, &[l, h]) in kept.iter().enumerate() {
                    let [a, b] = if l > h {
                        [-inf, inf]
                    } else if l == -inf && h == inf {
                        [inf, -inf]
                    } else if l == -inf {
                        [h, inf]
                    } else {
                        [-inf, l]
                    };
                    rlo = rlo.max(a);
                    if b < rhi {
                        (rhi, exit) = (b, Some(k));
                    }
                }
                if rlo >= rhi {
                    raw.push((-inf, None, inf));
                } else {
                    raw.push((-inf, None, rlo));
                    raw.push((rhi, exit, inf));
                }
            }
        }
        raw.into_iter()
            .filter(|&(lo, _, hi)| hi >= 0.0 && lo <= hi)
            .map(|(lo, entry, hi)| KeptPiece {
                start: lo.max(0.0),
                end: hi,
                entry: entry.filter(|_| lo > 0.0),
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn cut(text: &str) -> CutPlane {
        text.parse().unwrap()
    }

    #[test]
    fn planes_parse_and_bad_ones_are_refused() {
        assert_eq!(
            cut("x=2"),
            CutPlane {
                normal: [1.0, 0.0, 0.0],
                offset: 2.0
            }
        );
        assert_eq!(
            cut("-z=3"),
            CutPlane {
                normal: [0.0, 0.0, -1.0],
                offset: -3.0
            }
        );
        let c = cut("0,3,4:10");
        assert!((c.normal[1] - 0.6).abs() < 1e-15 && (c.offset - 2.0).abs() < 1e-15);
        for bad in ["w=1", "x=", "x=nan", "1,2:3", "0,0,0:1", "x", "1,a,2:0"] {
            assert!(bad.parse::<CutPlane>().is_err(), "{bad}");
        }
    }

    /// Every piece's points are kept and the points between pieces are not, checked by
    /// sampling the ray against `keeps`.
    #[test]
    fn pieces_agree_with_the_point_test() {
        let planes = [cut("x=0"), cut("y=0.5"), cut("1,1,1:0.2")];
        let mut rng = hytrace_volume::Rng::new(7, 0, 0);
        let mut u = || 2.0 * rng.next_f64() - 1.0;
        for mode in [CutMode::Union, CutMode::Intersection] {
            for n in 1..=3 {
                let c = Cutaway {
                    planes: planes[..n].to_vec(),
                    mode,
                };
                for _ in 0..200 {
                    let o = 3.0 * DVec3::new(u(), u(), u());
                    let d = DVec3::new(u(), u(), u()).normalize();
                    let pieces = c.pieces(o, d);
                    for k in 0..400 {
                        let t = 0.013 + k as f64 * 0.02;
                        let inside = pieces.iter().any(|p| p.start <= t && t <= p.end);
                        let near = pieces
                            .iter()
                            .any(|p| (p.start - t).abs() < 1e-9 || (p.end - t).abs() < 1e-9);
                        assert!(
                            near || inside == c.keeps(o + t * d),
                            "{mode:?} {n} {o} {d} {t}"
                        );
                    }
                    for p in &pieces {
                        if let Some(e) = p.entry {
                            assert!(p.start > 0.0);
                            assert!(planes[e].signed(o + p.start * d).abs() < 1e-9);
                        }
                    }
                }
            }
        }
    }
}
