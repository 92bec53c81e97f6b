//! What a photon run gives back: hit rows, step-history labels in Opticks' style, the
//! table of the most frequent histories, and the chi2 comparison of two runs' histories.
//!
//! A history is the sequence of labels of a photon's steps, packed four bits a label,
//! first label in the lowest bits, at most 16 labels (Opticks' `seqhis`; longer histories
//! keep their first 16). Label codes are the bit positions (plus one) of Opticks' photon
//! flags:
//!
//! | code | label | meaning |
//! |---|---|---|
//! | 3 | MI | left the world |
//! | 4 | AB | absorbed in the bulk |
//! | 6 | SC | Rayleigh scattered |
//! | 7 | SD | absorbed at a surface and detected |
//! | 8 | SA | absorbed at a surface (also: killed for want of RINDEX) |
//! | 10 | SR | specular reflection by a surface (dielectric_metal) |
//! | 11 | BR | Fresnel or total internal reflection |
//! | 12 | BT | into the next volume (refracted, or passed straight) |
//! | 13 | TO | emitted by the torch source |
//! | 15 | TR | stopped after the step limit |

use std::collections::HashMap;

use std::path::Path;

use hytrace_foundry::npy::NpyStream;

use super::{Batch, PhotonError, V};

/// A step label.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[repr(u8)]
pub enum Label {
    /// Left the world.
    Mi = 3,
    /// Absorbed in the bulk.
    Ab = 4,
    /// Absorbed by a wavelength shifter and re-emitted.
    Re = 5,
    /// Rayleigh scattered.
    Sc = 6,
    /// Detected at a surface.
    Sd = 7,
    /// Absorbed at a surface.
    Sa = 8,
    /// Reflected diffusely (not specularly) by a rough or painted surface.
    Dr = 9,
    /// Specularly reflected by a surface.
    Sr = 10,
    /// Fresnel or total internal reflection.
    Br = 11,
    /// Transmitted into the next volume.
    Bt = 12,
    /// Emitted by a torch source.
    To = 13,
    /// Stopped after the step limit.
    Tr = 15,
}

/// Every label's code and its two letters (the GPU kernel's `LABEL_*` constants are
/// generated from this table).
pub const LABELS: [(u8, &str); 12] = [
    (3, "MI"),
    (4, "AB"),
    (5, "RE"),
    (6, "SC"),
    (7, "SD"),
    (8, "SA"),
    (9, "DR"),
    (10, "SR"),
    (11, "BR"),
    (12, "BT"),
    (13, "TO"),
    (15, "TR"),
];

/// The two letters of a label code (`??` for an unknown code).
pub fn label_name(code: u8) -> &'static str {
    LABELS
        .iter()
        .find(|(c, _)| *c == code)
        .map_or("??", |(_, n)| n)
}

/// Most labels a packed history holds.
pub const HISTORY_LABELS: usize = 16;

/// A photon's history as it is built.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct History {
    /// Packed labels (see the module doc).
    pub code: u64,
    /// Labels recorded, including those past the first 16.
    pub len: u32,
    /// OR of `1 << (code - 1)` over every label (Opticks' history mask).
    pub mask: u32,
}

impl History {
    /// Appends a label.
    pub fn push(&mut self, label: Label) {
        let c = label as u8;
        if (self.len as usize) < HISTORY_LABELS {
            self.code |= u64::from(c) << (4 * self.len);
        }
        self.len += 1;
        self.mask |= 1 << (c - 1);
    }
}

/// The labels of a packed history, space separated (`TO BT SD`).
pub fn history_string(code: u64) -> String {
    (0..HISTORY_LABELS)
        .map(|k| ((code >> (4 * k)) & 0xf) as u8)
        .take_while(|&c| c != 0)
        .map(label_name)
        .collect::<Vec<_>>()
        .join(" ")
}

/// Columns of a hit row (float64).
pub const HIT_COLUMNS: [&str; 16] = [
    "x",
    "y",
    "z",
    "t",
    "dx",
    "dy",
    "dz",
    "wavelength",
    "px",
    "py",
    "pz",
    "instance",
    "copy",
    "photon",
    "mask",
    "steps",
];

/// One detected photon: where and when, its direction, wavelength and polarization, the
/// instance whose surface detected it, that instance's copy number, the photon's index,
/// its history mask and step count.
#[derive(Clone, Copy, Debug, PartialEq, bytemuck::Pod, bytemuck::Zeroable)]
#[repr(transparent)]
pub struct HitRow(pub [f64; 16]);

/// Columns of a step point of `--records` (float32).
pub const RECORD_COLUMNS: usize = 12;

/// One step point of a photon: `x y z t dx dy dz wavelength px py pz label`, where it is
/// (mm), when (ns), its direction as it leaves the point, its wavelength (nm) and
/// polarization (the first 11 columns of a hit row) and the step's label code (0: no
/// point, past the photon's end).
pub type RecordPoint = [f32; RECORD_COLUMNS];

/// The columns hit rows and step points begin with: `x y z t dx dy dz wavelength px py
/// pz` of a photon at `pos` at time `time` (ns) going along `dir` at `nm` nanometres with
/// polarization `pol`.
pub fn photon_columns(pos: V, time: f64, dir: V, nm: f64, pol: V) -> [f64; 11] {
    [
        pos.x, pos.y, pos.z, time, dir.x, dir.y, dir.z, nm, pol.x, pol.y, pol.z,
    ]
}

/// The step point labelled `label` of a photon at `pos` at time `time` (ns), leaving along
/// `dir` with polarization `pol` at `nm` nanometres.
pub fn record_point(label: Label, pos: V, time: f64, dir: V, pol: V, nm: f64) -> RecordPoint {
    let mut point = [f32::from(label as u8); RECORD_COLUMNS];
    for (p, c) in point
        .iter_mut()
        .zip(photon_columns(pos, time, dir, nm, pol))
    {
        *p = c as f32;
    }
    point
}

/// The files a run streams its results into as its batches finish: hits (float64
/// `(H, 16)`), and when asked for packed histories (uint64 `(N,)`) and step points
/// (float32 `(N, K, 12)`). Each is written where it is created (give temporary paths and
/// rename them when finished, as [`crate::outputs::OutputSet`] does).
pub struct RunFiles {
    hits: NpyStream,
    histories: Option<NpyStream>,
    records: Option<NpyStream>,
}

/// An output error as a photon error.
fn output_error(e: hytrace_foundry::FoundryError) -> PhotonError {
    PhotonError::Output(e.to_string())
}

impl RunFiles {
    /// Creates the files: hits at `hits`, histories at `histories`, and `k` step points a
    /// photon at `records`.
    pub fn create(
        hits: &Path,
        histories: Option<&Path>,
        records: Option<(&Path, u32)>,
    ) -> Result<RunFiles, PhotonError> {
        let f64s = |p: &Path, row: &[u64]| NpyStream::create(p, "<f8", 8, row);
        Ok(RunFiles {
            hits: f64s(hits, &[HIT_COLUMNS.len() as u64]).map_err(output_error)?,
            histories: histories
                .map(|p| NpyStream::create(p, "<u8", 8, &[]))
                .transpose()
                .map_err(output_error)?,
            records: records
                .map(|(p, k)| {
                    NpyStream::create(p, "<f4", 4, &[u64::from(k), RECORD_COLUMNS as u64])
                })
                .transpose()
                .map_err(output_error)?,
        })
    }

    /// Appends a batch.
    pub fn append(&mut self, batch: &Batch) -> Result<(), PhotonError> {
        self.hits
            .append(bytemuck::cast_slice(&batch.hits))
            .map_err(output_error)?;
        if let Some(h) = &mut self.histories {
            h.append(bytemuck::cast_slice(&batch.histories))
                .map_err(output_error)?;
        }
        if let Some(r) = &mut self.records {
            r.append(bytemuck::cast_slice(&batch.records))
                .map_err(output_error)?;
        }
        Ok(())
    }

    /// Writes the final shapes.
    pub fn finish(self) -> Result<(), PhotonError> {
        self.hits.finish().map_err(output_error)?;
        for f in [self.histories, self.records].into_iter().flatten() {
            f.finish().map_err(output_error)?;
        }
        Ok(())
    }
}

/// Counts of each history, most frequent first (ties by history string).
pub fn history_counts(codes: impl IntoIterator<Item = u64>) -> Vec<(String, u64)> {
    let mut counts: HashMap<u64, u64> = HashMap::new();
    for c in codes {
        *counts.entry(c).or_default() += 1;
    }
    sorted_counts(counts)
}

/// Counts of packed histories as [`history_counts`] lists them.
pub fn sorted_counts(counts: HashMap<u64, u64>) -> Vec<(String, u64)> {
    let mut rows: Vec<(String, u64)> = counts
        .into_iter()
        .map(|(c, n)| (history_string(c), n))
        .collect();
    rows.sort_by(|a, b| b.1.cmp(&a.1).then_with(|| a.0.cmp(&b.0)));
    rows
}

/// The table of the `top` most frequent histories: rank, count, fraction, labels.
pub fn history_table(counts: &[(String, u64)], top: usize) -> String {
    let total: u64 = counts.iter().map(|(_, n)| n).sum();
    let mut out = format!("{:>4} {:>10} {:>8}  history\n", "rank", "count", "fraction");
    for (k, (h, n)) in counts.iter().take(top).enumerate() {
        let f = *n as f64 / total.max(1) as f64;
        out += &format!("{:>4} {:>10} {:>8.5}  {h}\n", k + 1, n, f);
    }
    if counts.len() > top {
        let rest: u64 = counts[top..].iter().map(|(_, n)| n).sum();
        out += &format!(
            "     {rest:>10} in {} other histories\n",
            counts.len() - top
        );
    }
    out
}

/// Opticks' comparison of two samples' history frequencies: over the histories seen at
/// least `min_count` times in the two samples together, the sum of
/// `(a - b)^2 / (a + b)`, its degrees of freedom (the number of such histories) and the
/// chi2 distribution's p-value.
#[derive(Clone, Debug, PartialEq)]
pub struct HistoryChi2 {
    /// chi2 sum.
    pub chi2: f64,
    /// Degrees of freedom.
    pub ndf: usize,
    /// Probability of a chi2 at least this large for samples of one distribution.
    pub p_value: f64,
    /// `(history, a, b)` of the compared histories, largest contribution first.
    pub rows: Vec<(String, u64, u64)>,
}

/// Compares history counts of two samples of equal size (see [`HistoryChi2`]).
pub fn compare_histories(a: &[(String, u64)], b: &[(String, u64)], min_count: u64) -> HistoryChi2 {
    let mut both: HashMap<&str, (u64, u64)> = HashMap::new();
    for (h, n) in a {
        both.entry(h).or_default().0 += n;
    }
    for (h, n) in b {
        both.entry(h).or_default().1 += n;
    }
    let mut rows: Vec<(String, u64, u64)> = both
        .into_iter()
        .filter(|(_, (x, y))| x + y >= min_count)
        .map(|(h, (x, y))| (h.to_string(), x, y))
        .collect();
    let term = |x: u64, y: u64| (x as f64 - y as f64).powi(2) / (x + y) as f64;
    rows.sort_by(|p, q| {
        term(q.1, q.2)
            .total_cmp(&term(p.1, p.2))
            .then(p.0.cmp(&q.0))
    });
    let chi2: f64 = rows.iter().map(|&(_, x, y)| term(x, y)).sum();
    let ndf = rows.len();
    HistoryChi2 {
        chi2,
        ndf,
        p_value: if ndf == 0 {
            1.0
        } else {
            chi2_survival(chi2, ndf as f64)
        },
        rows,
    }
}

/// `ln Gamma(x)` for `x > 0` (Lanczos, g = 7, nine terms: relative error below 1e-14).
fn ln_gamma(x: f64) -> f64 {
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let t = x + 7.5;
    let sum = C[1..]
        .iter()
        .enumerate()
        .fold(C[0], |s, (i, c)| s + c / (x + i as f64 + 1.0));
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + sum.ln()
}

/// The regularized upper incomplete gamma function `Q(a, x)`: its series below `a + 1`,
/// its continued fraction (modified Lentz) above.
fn gamma_q(a: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    let front = (-x + a * x.ln() - ln_gamma(a)).exp();
    if x < a + 1.0 {
        let (mut term, mut sum, mut n) = (1.0 / a, 1.0 / a, a);
        for _ in 0..10_000 {
            n += 1.0;
            term *= x / n;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        return (1.0 - front * sum).clamp(0.0, 1.0);
    }
    let tiny = 1e-300;
    let mut b = x + 1.0 - a;
    let mut c = 1.0 / tiny;
    let mut d = 1.0 / b;
    let mut h = d;
    for i in 1..10_000 {
        let an = -(i as f64) * (i as f64 - a);
        b += 2.0;
        d = an * d + b;
        if d.abs() < tiny {
            d = tiny;
        }
        c = b + an / c;
        if c.abs() < tiny {
            c = tiny;
        }
        d = 1.0 / d;
        let delta = d * c;
        h *= delta;
        if (delta - 1.0).abs() < 1e-16 {
            break;
        }
    }
    (front * h).clamp(0.0, 1.0)
}

/// The chi2 distribution's survival function: `P(X >= chi2)` for `ndf` degrees of freedom.
pub fn chi2_survival(chi2: f64, ndf: f64) -> f64 {
    gamma_q(0.5 * ndf, 0.5 * chi2)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chi2_survival_matches_tabulated_quantiles() {
        // Critical values of the chi2 distribution (standard tables).
        for (x, k, p) in [
            (3.841_458_820_694_124, 1.0, 0.05),
            (6.634_896_601_021_213, 1.0, 0.01),
            (18.307_038_053_275_146, 10.0, 0.05),
            (2.705_543_454_095_404, 1.0, 0.10),
            (124.342_113_404_070_4, 100.0, 0.05),
            (0.351_846_317_749_271_2, 3.0, 0.95),
        ] {
            let got = chi2_survival(x, k);
            assert!((got - p).abs() < 1e-9, "chi2 {x} ndf {k}: {got} vs {p}");
        }
        // Two degrees of freedom: exp(-x/2) exactly.
        assert!((chi2_survival(5.0, 2.0) - (-2.5f64).exp()).abs() < 1e-14);
    }

    #[test]
    fn histories_pack_sixteen_labels_and_count() {
        let mut h = History::default();
        h.push(Label::To);
        h.push(Label::Bt);
        h.push(Label::Sd);
        assert_eq!(history_string(h.code), "TO BT SD");
        assert_eq!(h.mask, (1 << 12) | (1 << 11) | (1 << 6));
        let mut long = History::default();
        for _ in 0..20 {
            long.push(Label::Br);
        }
        assert_eq!(long.len, 20);
        assert_eq!(history_string(long.code).split(' ').count(), 16);
        let counts = history_counts([h.code, h.code, long.code]);
        assert_eq!(counts[0], ("TO BT SD".to_string(), 2));
        let c = compare_histories(&counts, &counts, 1);
        assert_eq!((c.chi2, c.ndf, c.p_value), (0.0, 2, 1.0));
        let other = vec![("TO BT SD".to_string(), 50u64), ("TO AB".to_string(), 50)];
        let mine = vec![("TO BT SD".to_string(), 90u64), ("TO AB".to_string(), 10)];
        let c = compare_histories(&mine, &other, 30);
        // (90-50)^2/140 + (10-50)^2/60.
        assert!((c.chi2 - (1600.0 / 140.0 + 1600.0 / 60.0)).abs() < 1e-12);
        assert!(c.p_value < 1e-6);
    }
}
