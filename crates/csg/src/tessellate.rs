//! Closed triangle meshes for solids with no analytic form here: stacks of cross-sections
//! (extrusions, twisted and generic trapezoids), refined until the mesh is within a stated
//! distance of the true surface.

use std::collections::HashMap;

use crate::shape::CsgError;

/// A triangle, vertices counter-clockwise seen from outside.
pub type Tri = [[f64; 3]; 3];

fn err(problem: String) -> CsgError {
    CsgError {
        primitive: "tessellation",
        problem,
    }
}

fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}

fn dot(a: [f64; 3], b: [f64; 3]) -> f64 {
    a[0] * b[0] + a[1] * b[1] + a[2] * b[2]
}

/// The point at `s` of the segment from `a` to `b`: exactly `a` at 0, `b` at 1 and `a` all
/// along when `a == b`, and bit for bit `along(b, a, 1 - s)` when `1 - s` is exact, so that
/// coincident corners and edges run both ways get identical points.
fn along(a: [f64; 3], b: [f64; 3], s: f64) -> [f64; 3] {
    std::array::from_fn(|k| {
        if s < 0.5 {
            a[k] + s * (b[k] - a[k])
        } else if s > 0.5 {
            b[k] + (1.0 - s) * (a[k] - b[k])
        } else {
            0.5 * (a[k] + b[k])
        }
    })
}

fn lerp(a: [f64; 3], b: [f64; 3], s: f64) -> [f64; 3] {
    [
        a[0] + s * (b[0] - a[0]),
        a[1] + s * (b[1] - a[1]),
        a[2] + s * (b[2] - a[2]),
    ]
}

/// Twice the signed area of a polygon in xy (positive when counter-clockwise).
pub fn signed_area2(poly: &[[f64; 2]]) -> f64 {
    (0..poly.len())
        .map(|i| {
            let (a, b) = (poly[i], poly[(i + 1) % poly.len()]);
            a[0] * b[1] - a[1] * b[0]
        })
        .sum()
}

/// Triangles (index triples, counter-clockwise) of a simple polygon given counter-clockwise,
/// by ear clipping.
pub fn triangulate(poly: &[[f64; 2]]) -> Result<Vec<[usize; 3]>, CsgError> {
    ear_clip(poly, false)
}

/// Ear clipping: the first ear found, or (`sharpest`) the ear of smallest angle.
fn ear_clip(poly: &[[f64; 2]], sharpest: bool) -> Result<Vec<[usize; 3]>, CsgError> {
    let n = poly.len();
    if n < 3 {
        return Err(err(format!("a polygon needs 3 vertices, got {n}")));
    }
    let area = signed_area2(poly);
    if area.is_nan() || area <= 0.0 {
        return Err(err(format!(
            "the polygon must be counter-clockwise with non-zero area (twice the area {area})"
        )));
    }
    let eps = 1e-12 * area.abs();
    let mut idx: Vec<usize> = (0..n).collect();
    let mut out = Vec::with_capacity(n - 2);
    while idx.len() > 3 {
        let m = idx.len();
        let is_ear = |k: usize| {
            let (a, b, c) = (idx[(k + m - 1) % m], idx[k], idx[(k + 1) % m]);
            if orient(poly[a], poly[b], poly[c]) <= eps {
                return false;
            }
            // No other vertex inside (or on) the candidate ear.
            idx.iter().all(|&p| {
                p == a
                    || p == b
                    || p == c
                    || orient(poly[a], poly[b], poly[p]) < -eps
                    || orient(poly[b], poly[c], poly[p]) < -eps
                    || orient(poly[c], poly[a], poly[p]) < -eps
            })
        };
        let ear = if sharpest {
            // The cosine of the ear's angle at its tip: largest for the sharpest.
            let cos = |k: usize| {
                let (a, b, c) = (
                    poly[idx[(k + m - 1) % m]],
                    poly[idx[k]],
                    poly[idx[(k + 1) % m]],
                );
                ((a[0] - b[0]) * (c[0] - b[0]) + (a[1] - b[1]) * (c[1] - b[1]))
                    / (dist(a, b) * dist(c, b))
            };
            (0..m)
                .filter(|&k| is_ear(k))
                .max_by(|&x, &y| cos(x).total_cmp(&cos(y)))
        } else {
            (0..m).find(|&k| is_ear(k))
        };
        let Some(k) = ear else {
            return Err(err("the polygon is not simple (no ear to clip)".into()));
        };
        out.push([idx[(k + m - 1) % m], idx[k], idx[(k + 1) % m]]);
        idx.remove(k);
    }
    out.push([idx[0], idx[1], idx[2]]);
    Ok(out)
}

/// Twice the signed area of the triangle `(a, b, c)`: positive when counter-clockwise.
fn orient(a: [f64; 2], b: [f64; 2], c: [f64; 2]) -> f64 {
    (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
}

fn dist(a: [f64; 2], b: [f64; 2]) -> f64 {
    (a[0] - b[0]).hypot(a[1] - b[1])
}

/// Whether the closed segments `[p, q]` and `[r, s]` share a point.
fn segments_meet(p: [f64; 2], q: [f64; 2], r: [f64; 2], s: [f64; 2]) -> bool {
    let (d1, d2) = (orient(p, q, r), orient(p, q, s));
    let (d3, d4) = (orient(r, s, p), orient(r, s, q));
    let apart = |x: f64, y: f64| (x > 0.0 && y < 0.0) || (x < 0.0 && y > 0.0);
    if apart(d1, d2) && apart(d3, d4) {
        return true;
    }
    // A collinear endpoint meets the other segment when it lies within its box.
    let on = |a: [f64; 2], b: [f64; 2], c: [f64; 2], d: f64| {
        d == 0.0
            && c[0] >= a[0].min(b[0])
            && c[0] <= a[0].max(b[0])
            && c[1] >= a[1].min(b[1])
            && c[1] <= a[1].max(b[1])
    };
    on(p, q, r, d1) || on(p, q, s, d2) || on(r, s, p, d3) || on(r, s, q, d4)
}

/// A simple polygon (corners in either orientation) counter-clockwise, without repeated
/// corners and without corners on the line through their neighbours (within `1e-12` of
/// the polygon's size; G4ExtrudedSolid drops those too). Errors when a corner is not
/// finite, fewer than three corners remain, the polygon has no area, or two of its edges
/// cross or touch.
pub fn simple_polygon(poly: &[[f64; 2]]) -> Result<Vec<[f64; 2]>, CsgError> {
    if poly.len() < 3 || !poly.iter().flatten().all(|v| v.is_finite()) {
        return Err(err(format!(
            "a polygon needs 3 or more finite corners, got {poly:?}"
        )));
    }
    let (lo, hi) = poly.iter().fold(
        ([f64::INFINITY; 2], [f64::NEG_INFINITY; 2]),
        |(lo, hi), p| {
            (
                [lo[0].min(p[0]), lo[1].min(p[1])],
                [hi[0].max(p[0]), hi[1].max(p[1])],
            )
        },
    );
    let eps = 1e-12 * dist(lo, hi);
    let mut v = poly.to_vec();
    // Drop repeated corners, then corners in line with their neighbours (a spike going
    // straight back is in line too), until none is left.
    'clean: while v.len() >= 3 {
        let n = v.len();
        for k in 0..n {
            let (a, b, c) = (v[(k + n - 1) % n], v[k], v[(k + 1) % n]);
            let base = dist(a, c);
            if dist(a, b) <= eps || base <= eps || orient(a, b, c).abs() <= eps * base {
                v.remove(k);
                continue 'clean;
            }
        }
        break;
    }
    let area = if v.len() >= 3 { signed_area2(&v) } else { 0.0 };
    // (NaN cannot remain: the corners are finite.)
    if area.abs() <= eps * eps {
        return Err(err(format!("the polygon {poly:?} has no area")));
    }
    if area < 0.0 {
        v.reverse();
    }
    let n = v.len();
    for i in 0..n {
        // Non-adjacent edges must not meet (adjacent ones share only their corner: the
        // corners in line with their neighbours are gone).
        for j in i + 2..n {
            if i == 0 && j == n - 1 {
                continue;
            }
            if segments_meet(v[i], v[(i + 1) % n], v[j], v[(j + 1) % n]) {
                return Err(err(format!(
                    "the polygon {poly:?} is not simple: edges {i} and {j} meet"
                )));
            }
        }
    }
    Ok(v)
}

/// Convex pieces of a simple counter-clockwise polygon (as from [`simple_polygon`]): each
/// piece lists polygon corner indices counter-clockwise, every corner strictly convex, at
/// most `max_corners` (>= 3) of them. The pieces tile the polygon edge to edge: two pieces
/// share a whole edge (a diagonal between two polygon corners) or at most a corner.
///
/// An ear-clipping triangulation is merged across its diagonals while the union stays
/// convex (Hertel and Mehlhorn: at most four times the fewest convex pieces). The result
/// depends on the triangulation and on the order of the merges, so a few of each (ear
/// clipping started at up to 8 corners or clipping the sharpest ears first; longest or
/// shortest diagonals first) are tried
/// and the fewest pieces kept.
pub fn convex_pieces(poly: &[[f64; 2]], max_corners: usize) -> Result<Vec<Vec<usize>>, CsgError> {
    let n = poly.len();
    let starts: Vec<usize> = if n > 400 {
        vec![0]
    } else {
        let mut s: Vec<usize> = (0..8).map(|k| k * n / 8).collect();
        s.dedup();
        s
    };
    let mut best: Option<Vec<Vec<usize>>> = None;
    let trials = starts
        .into_iter()
        .map(|s| (s, false))
        .chain((n <= 400).then_some((0, true)));
    for (start, sharpest) in trials {
        // Ear clipping from another corner: the polygon rotated, indices mapped back.
        let rotated: Vec<[f64; 2]> = (0..n).map(|i| poly[(i + start) % n]).collect();
        let tris: Vec<[usize; 3]> = ear_clip(&rotated, sharpest)?
            .into_iter()
            .map(|t| t.map(|i| (i + start) % n))
            .collect();
        for longest_first in [true, false] {
            let pieces = merge_convex(poly, &tris, longest_first, max_corners);
            if best.as_ref().is_none_or(|b| pieces.len() < b.len()) {
                best = Some(pieces);
            }
        }
    }
    Ok(best.expect("at least one trial"))
}

/// Hertel-Mehlhorn: merges the triangles `tris` of `poly` across their diagonals (by
/// length, longest or shortest first) wherever the union stays strictly convex and has at
/// most `max_corners` corners.
fn merge_convex(
    poly: &[[f64; 2]],
    tris: &[[usize; 3]],
    longest_first: bool,
    max_corners: usize,
) -> Vec<Vec<usize>> {
    let n = poly.len();
    let mut pieces: Vec<Vec<usize>> = tris.iter().map(|t| t.to_vec()).collect();
    let mut alive = vec![true; pieces.len()];
    // Which piece holds each directed edge (a diagonal is held in both senses).
    let mut owner: std::collections::HashMap<(usize, usize), usize> = tris
        .iter()
        .enumerate()
        .flat_map(|(i, t)| (0..3).map(move |k| ((t[k], t[(k + 1) % 3]), i)))
        .collect();
    let mut diagonals: Vec<(usize, usize)> = owner
        .keys()
        .copied()
        .filter(|&(a, b)| a < b && b != a + 1 && !(a == 0 && b == n - 1))
        .collect();
    diagonals.sort_by(|x, y| {
        let len = |d: &(usize, usize)| dist(poly[d.0], poly[d.1]);
        let by_length = if longest_first {
            len(y).total_cmp(&len(x))
        } else {
            len(x).total_cmp(&len(y))
        };
        by_length.then(x.cmp(y))
    });
    // Strictly convex at corner k: turning left by more than about 1e-9 rad.
    let convex_at = |p: &[usize], k: usize| {
        let m = p.len();
        let (a, b, c) = (poly[p[(k + m - 1) % m]], poly[p[k]], poly[p[(k + 1) % m]]);
        orient(a, b, c) > 1e-9 * dist(a, b) * dist(b, c)
    };
    for (a, b) in diagonals {
        let (Some(&p), Some(&q)) = (owner.get(&(a, b)), owner.get(&(b, a))) else {
            continue;
        };
        let (pp, qq) = (&pieces[p], &pieces[q]);
        if pp.len() + qq.len() - 2 > max_corners {
            continue;
        }
        let at = |piece: &[usize], from: usize| {
            (0..piece.len())
                .find(|&k| piece[k] == from)
                .expect("the owner holds the edge")
        };
        let (kp, kq) = (at(pp, a), at(qq, b));
        // p runs ..., a, b, ... and q ..., b, a, ...: p from b round to a, then q strictly
        // between a and b.
        let mut merged: Vec<usize> = (0..pp.len()).map(|i| pp[(kp + 1 + i) % pp.len()]).collect();
        merged.extend((1..qq.len() - 1).map(|i| qq[(kq + 1 + i) % qq.len()]));
        if convex_at(&merged, 0) && convex_at(&merged, pp.len() - 1) {
            owner.remove(&(a, b));
            owner.remove(&(b, a));
            let m = merged.len();
            for k in 0..m {
                owner.insert((merged[k], merged[(k + 1) % m]), p);
            }
            pieces[p] = merged;
            alive[q] = false;
        }
    }
    debug_assert!(alive.iter().any(|&a| a));
    pieces
        .into_iter()
        .zip(alive)
        .filter_map(|(p, keep)| keep.then_some(p))
        .collect()
}

/// Twice the area (mm^2) per mm of size below which an end section counts as having no area
/// (a point or a segment): Geant4's kCarTolerance, the bound G4GenericTrap applies to its
/// faces.
const NO_AREA: f64 = 1e-9;

/// The closed mesh of a stack of cross-sections: `levels[i]` are the polygon's vertices at
/// the i-th level (same count everywhere, ascending z, counter-clockwise seen from +z);
/// consecutive levels are joined by quads split into two triangles, and the first and last
/// levels are capped with the triangulation of `cap` (a subset of the level's vertices:
/// the indices of the polygon's corners, ascending, so that collinear edge points do not
/// upset ear clipping; the cap's triangles are then refined by longest-edge bisection
/// until they meet the side triangles vertex to vertex, growing away from the edges).
///
/// Vertices may coincide (collapsed corners of a G4GenericTrap): triangles with two equal
/// vertices are left out, repeated corners count once, and an end level with no area (a
/// point or a segment: twice its area under 1e-9 mm times its size) gets no cap, its side
/// triangles being split at every point of that level between their ends, so that the
/// side faces meeting there share their edges. The mesh stays closed: every edge is shared
/// by two triangles, in opposite directions.
pub fn section_stack(levels: &[Vec<[f64; 3]>], corners: &[usize]) -> Result<Vec<Tri>, CsgError> {
    let n = levels.first().map_or(0, Vec::len);
    if levels.len() < 2 || n < 3 || levels.iter().any(|l| l.len() != n) {
        return Err(err(
            "a section stack needs 2 levels of the same polygon".into()
        ));
    }
    if !levels.iter().flatten().flatten().all(|c| c.is_finite()) {
        return Err(err("a section stack needs finite vertices".into()));
    }
    if corners.len() < 3
        || corners.windows(2).any(|w| w[0] >= w[1])
        || corners.last().is_some_and(|&c| c >= n)
    {
        return Err(err(format!(
            "a section stack needs 3 or more ascending corner indices below {n}, got {corners:?}"
        )));
    }
    let last = levels.len() - 1;
    let mut out = Vec::new();
    let bottom = end_cap(&levels[0], corners, false, &mut out)?;
    let top = end_cap(&levels[last], corners, true, &mut out)?;
    for (i, pair) in levels.windows(2).enumerate() {
        let (lo, hi) = (&pair[0], &pair[1]);
        let lo_line = if i == 0 { bottom.as_ref() } else { None };
        let hi_line = if i + 1 == last { top.as_ref() } else { None };
        for k in 0..n {
            let j = (k + 1) % n;
            // Counter-clockwise polygon: outward is to the right of the edge k -> j seen
            // from +z, so (lo k, lo j, hi j) runs counter-clockwise seen from outside. The
            // first edge of each triangle lies in a level.
            side_triangle(&mut out, [lo[k], lo[j], hi[j]], lo_line);
            side_triangle(&mut out, [hi[j], hi[k], lo[k]], hi_line);
        }
    }
    Ok(out)
}

/// Adds the triangle unless two of its vertices coincide.
fn push_proper(out: &mut Vec<Tri>, t: Tri) {
    if t[0] != t[1] && t[1] != t[2] && t[2] != t[0] {
        out.push(t);
    }
}

/// Adds the triangle `t`, counter-clockwise seen from outside, split into fans at the
/// points `paths[e]` (in order) lying on its edge `t[e] -> t[e + 1]`; `flip` reverses the
/// triangles added.
fn split_triangle(out: &mut Vec<Tri>, t: Tri, paths: [&[[f64; 3]]; 3], flip: bool) {
    let Some(e) = (0..3).find(|&e| !paths[e].is_empty()) else {
        push_proper(out, if flip { [t[0], t[2], t[1]] } else { t });
        return;
    };
    let (a, b, c) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
    let (bc, ca) = (paths[(e + 1) % 3], paths[(e + 2) % 3]);
    let q: Vec<[f64; 3]> = std::iter::once(a)
        .chain(paths[e].iter().copied())
        .chain(std::iter::once(b))
        .collect();
    let end = q.len() - 2;
    for i in 0..=end {
        let rest: [&[[f64; 3]]; 3] = [
            &[],
            if i == end { bc } else { &[] },
            if i == 0 { ca } else { &[] },
        ];
        split_triangle(out, [q[i], q[i + 1], c], rest, flip);
    }
}

/// Adds a side triangle whose first edge lies in a level: split at the level's points
/// between the edge's ends when the level has no area (`line`).
fn side_triangle(out: &mut Vec<Tri>, t: Tri, line: Option<&Line>) {
    match line {
        Some(line) => split_triangle(out, t, [&line.between(t[0], t[1]), &[], &[]], false),
        None => push_proper(out, t),
    }
}

/// The distinct points of a level with no area (a segment or a point), in order along it.
struct Line {
    origin: [f64; 3],
    direction: [f64; 3],
    points: Vec<[f64; 3]>,
}

impl Line {
    fn new(level: &[[f64; 3]]) -> Line {
        let origin = level[0];
        let far = level
            .iter()
            .map(|&p| sub(p, origin))
            .fold([0.0; 3], |a, d| if dot(d, d) > dot(a, a) { d } else { a });
        let l = dot(far, far).sqrt();
        let direction = if l > 0.0 { far.map(|c| c / l) } else { far };
        let mut line = Line {
            origin,
            direction,
            points: Vec::new(),
        };
        let mut points = level.to_vec();
        points.sort_by(|&p, &q| line.order(p, q));
        points.dedup();
        line.points = points;
        line
    }

    /// Position along the line, then coordinates (equal only for equal points).
    fn order(&self, p: [f64; 3], q: [f64; 3]) -> std::cmp::Ordering {
        let cmp = |a: f64, b: f64| a.partial_cmp(&b).unwrap_or(std::cmp::Ordering::Equal);
        let t = |p: [f64; 3]| dot(sub(p, self.origin), self.direction);
        cmp(t(p), t(q))
            .then(cmp(p[0], q[0]))
            .then(cmp(p[1], q[1]))
            .then(cmp(p[2], q[2]))
    }

    /// The points strictly between `a` and `b`, in order from `a` to `b`.
    fn between(&self, a: [f64; 3], b: [f64; 3]) -> Vec<[f64; 3]> {
        use std::cmp::Ordering::{Greater, Less};
        let forward = self.order(a, b) == Less;
        let (lo, hi) = if forward { (a, b) } else { (b, a) };
        let i = self
            .points
            .partition_point(|&p| self.order(p, lo) != Greater);
        let j = self.points.partition_point(|&p| self.order(p, hi) == Less);
        let mut mid = self.points[i..j.max(i)].to_vec();
        if !forward {
            mid.reverse();
        }
        mid
    }
}

/// Points strictly inside each edge of a triangulation, by the edge's ends (the lower
/// index first), in order from the lower index.
type Pending = HashMap<(usize, usize), Vec<usize>>;

/// Records `between` (points in order from `from` to `to`) as inside the edge `from`-`to`,
/// with those recorded there already, in order along it.
fn set_pending(
    pending: &mut Pending,
    points: &[[f64; 3]],
    from: usize,
    to: usize,
    between: Vec<usize>,
) {
    if between.is_empty() {
        return;
    }
    let (lo, hi) = (from.min(to), from.max(to));
    let list = pending.entry((lo, hi)).or_default();
    for p in between {
        if !list.contains(&p) {
            list.push(p);
        }
    }
    let from_lo = |p: usize| {
        let d = sub(points[p], points[lo]);
        dot(d, d)
    };
    list.sort_by(|&x, &y| from_lo(x).total_cmp(&from_lo(y)));
}

/// The points of `pending` inside the edge `a`-`b`, in order from `a`.
fn pending_on(pending: &Pending, points: &[[f64; 3]], a: usize, b: usize) -> Vec<[f64; 3]> {
    let mut list: Vec<[f64; 3]> = pending
        .get(&(a.min(b), a.max(b)))
        .map_or_else(Vec::new, |l| l.iter().map(|&p| points[p]).collect());
    if a > b {
        list.reverse();
    }
    list
}

/// The triangles of a cap: `tris` (indices into `points`, whose points run round the cap,
/// counter-clockwise seen from +z) refined by longest-edge bisection (Rivara) until no
/// edge has a point of `pending` inside it: a triangle with such a point is split across
/// its longest edge (not a piece of the cap's edge: those take no new points), at the
/// pending point nearest the edge's middle or at a new middle point (recorded for the
/// triangle on the other side, which then splits there too). The triangles stay about as
/// well shaped as the first ones and grow away from the pending points, so that a cap
/// meets finely divided sides vertex to vertex with few triangles. (Past a generous
/// number of splits, which rounding on degenerate input could cause, the rest are split
/// into fans at their pending points instead.)
fn refine_cap(
    points: &mut Vec<[f64; 3]>,
    tris: Vec<[usize; 3]>,
    mut pending: Pending,
    flip: bool,
    out: &mut Vec<Tri>,
) {
    // Points below `boundary` run round the cap; consecutive ones make its edge.
    let boundary = points.len();
    let mut splits_left = 64 * (points.len() + 16);
    let mut work = tris;
    // Finished triangles, and which holds each directed edge: a new middle point on an
    // edge sends the triangle on its other side back to work.
    let mut done: Vec<Option<[usize; 3]>> = Vec::new();
    let mut holder: HashMap<(usize, usize), usize> = HashMap::new();
    while let Some(t) = work.pop() {
        let edge_pending = |e: usize, pending: &Pending| {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            pending
                .get(&(a.min(b), a.max(b)))
                .is_some_and(|l| !l.is_empty())
        };
        if splits_left == 0 || !(0..3).any(|e| edge_pending(e, &pending)) {
            for e in 0..3 {
                holder.insert((t[e], t[(e + 1) % 3]), done.len());
            }
            done.push(Some(t));
            continue;
        }
        splits_left -= 1;
        // The longest edge, except a piece of the boundary, which takes no new points.
        let length2 = |e: usize| {
            let (a, b) = (t[e], t[(e + 1) % 3]);
            let piece = a < boundary
                && b < boundary
                && (b == (a + 1) % boundary || a == (b + 1) % boundary);
            if edge_pending(e, &pending) || !piece {
                let d = sub(points[b], points[a]);
                dot(d, d)
            } else {
                -1.0
            }
        };
        let e = (0..3)
            .max_by(|&x, &y| length2(x).total_cmp(&length2(y)))
            .unwrap_or(0);
        let (a, b, c) = (t[e], t[(e + 1) % 3], t[(e + 2) % 3]);
        let (lo, hi) = (a.min(b), a.max(b));
        let list = pending.get(&(lo, hi)).cloned().unwrap_or_default();
        let middle = lerp(points[lo], points[hi], 0.5);
        let off = |p: usize| {
            let d = sub(points[p], middle);
            dot(d, d)
        };
        let nearest = (0..list.len()).min_by(|&x, &y| off(list[x]).total_cmp(&off(list[y])));
        let m = match nearest {
            Some(k) => {
                set_pending(&mut pending, points, lo, list[k], list[..k].to_vec());
                set_pending(&mut pending, points, list[k], hi, list[k + 1..].to_vec());
                list[k]
            }
            None => {
                points.push(middle);
                let m = points.len() - 1;
                pending.insert((lo, hi), vec![m]);
                if let Some(other) = holder.get(&(b, a)).and_then(|&k| done[k].take()) {
                    work.push(other);
                }
                m
            }
        };
        work.push([a, m, c]);
        work.push([m, b, c]);
    }
    for t in done.into_iter().flatten() {
        let paths = [0, 1, 2].map(|e| pending_on(&pending, points, t[e], t[(e + 1) % 3]));
        split_triangle(
            out,
            t.map(|i| points[i]),
            [&paths[0], &paths[1], &paths[2]],
            flip,
        );
    }
}

/// Adds the cap of an end level (seen from +z when `up`, else from -z), or returns the
/// level as a [`Line`] when it has no area.
fn end_cap(
    level: &[[f64; 3]],
    corners: &[usize],
    up: bool,
    out: &mut Vec<Tri>,
) -> Result<Option<Line>, CsgError> {
    let xy = |i: usize| [level[i][0], level[i][1]];
    // Corners once each, and without those exactly in line with their neighbours (the
    // cap's split at edge points puts them back).
    let mut kept = corners.to_vec();
    'clean: while kept.len() >= 3 {
        let m = kept.len();
        for k in 0..m {
            let (a, b, c) = (kept[(k + m - 1) % m], kept[k], kept[(k + 1) % m]);
            if level[a] == level[b] || orient(xy(a), xy(b), xy(c)) == 0.0 {
                kept.remove(k);
                continue 'clean;
            }
        }
        break;
    }
    let size = level
        .iter()
        .map(|&p| dist(xy(0), [p[0], p[1]]))
        .fold(0.0, f64::max);
    let poly: Vec<[f64; 2]> = kept.iter().map(|&c| xy(c)).collect();
    if kept.len() < 3 || signed_area2(&poly).abs() <= NO_AREA * size {
        return Ok(Some(Line::new(level)));
    }
    // The level's points once each (consecutive repeats dropped), the kept corners'
    // places among them, and the points between consecutive kept corners.
    let mut points: Vec<[f64; 3]> = Vec::with_capacity(level.len());
    let mut place = vec![0; level.len()];
    for (i, &p) in level.iter().enumerate() {
        if points.last() != Some(&p) {
            points.push(p);
        }
        place[i] = points.len() - 1;
    }
    if points.len() > 1 && points.first() == points.last() {
        points.pop();
        for i in place.iter_mut().filter(|i| **i == points.len()) {
            *i = 0;
        }
    }
    let corner_at: Vec<usize> = kept.iter().map(|&c| place[c]).collect();
    let m = kept.len();
    let mut pending = HashMap::new();
    for x in 0..m {
        let (from, to) = (corner_at[x], corner_at[(x + 1) % m]);
        let mut between = Vec::new();
        let mut i = (from + 1) % points.len();
        while i != to {
            between.push(i);
            i = (i + 1) % points.len();
        }
        set_pending(&mut pending, &points, from, to, between);
    }
    let tris: Vec<[usize; 3]> = triangulate(&poly)?
        .into_iter()
        .map(|t| t.map(|x| corner_at[x]))
        .collect();
    // Counter-clockwise from +z faces up: right for the top cap, flipped at the bottom.
    refine_cap(&mut points, tris, pending, !up, out);
    Ok(None)
}

/// Distance from `p` to the plane of triangle `t`.
fn plane_distance(p: [f64; 3], t: &Tri) -> f64 {
    let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
    let l = dot(n, n).sqrt();
    if l == 0.0 {
        return 0.0;
    }
    (dot(sub(p, t[0]), n) / l).abs()
}

/// The closed mesh of a solid whose cross-section at height `z` is the polygon
/// `section(z)` (corners counter-clockwise seen from +z) from `z1` to `z2`, with side faces
/// ruled by the straight segments between consecutive corners at every height. Levels and
/// edge subdivisions are doubled until every patch centre and every corner path lies within
/// `tolerance` of the mesh (a patch too far off is split across its longer side, so
/// triangles stay well shaped). Fails when that needs more than about 2^20 triangles.
/// Corners may coincide, at one end or all along (collapsed G4GenericTrap vertices): their
/// edge points coincide too, and [`section_stack`] leaves out what has no area. A face that
/// one patch a level follows within `tolerance` (a planar one, such as any face with a
/// collapsed end) keeps its full subdivision only where it is widest: where it narrows,
/// its edge points are repeated, so that its patches stay about as wide and no fan of
/// slivers converges on a collapsed corner (which also made BVHs too deep).
pub fn ruled_solid(
    section: &dyn Fn(f64) -> Vec<[f64; 3]>,
    z1: f64,
    z2: f64,
    tolerance: f64,
) -> Result<Vec<Tri>, CsgError> {
    if tolerance.is_nan()
        || tolerance <= 0.0
        || z1.partial_cmp(&z2) != Some(std::cmp::Ordering::Less)
    {
        return Err(err(format!(
            "needs tolerance > 0 and z1 < z2, got {tolerance}, {z1}..{z2}"
        )));
    }
    let corners = section(z1).len();
    let (mut nz, mut nu) = (2usize, 1usize);
    loop {
        let z_at = |i: usize| {
            if i == nz {
                z2
            } else {
                z1 + (z2 - z1) * i as f64 / nz as f64
            }
        };
        let point = |z: f64, edge: usize, s: f64| {
            let p = section(z);
            along(p[edge], p[(edge + 1) % corners], s)
        };
        let levels: Vec<Vec<[f64; 3]>> = (0..=nz)
            .map(|i| {
                let z = z_at(i);
                (0..corners)
                    .flat_map(|e| (0..nu).map(move |k| (e, k as f64 / nu as f64)))
                    .map(|(e, s)| point(z, e, s))
                    .collect()
            })
            .collect();
        // Distance from the mesh of the centre of the patch of edge `e` between levels `i`
        // and `i + 1` and between `s0` and `s1` along the edge.
        let patch_deviation = |i: usize, e: usize, s0: f64, s1: f64| {
            let zm = 0.5 * (z_at(i) + z_at(i + 1));
            let centre = point(zm, e, 0.5 * (s0 + s1));
            let (a, b) = (point(z_at(i), e, s0), point(z_at(i), e, s1));
            let (c2, d2) = (point(z_at(i + 1), e, s1), point(z_at(i + 1), e, s0));
            plane_distance(centre, &[a, b, c2]).min(plane_distance(centre, &[a, c2, d2]))
        };
        // Deviation along the corner paths (levels) and across patches (subdivisions).
        let (mut dev_z, mut dev_u) = (0.0f64, 0.0f64);
        for i in 0..nz {
            let zm = 0.5 * (z_at(i) + z_at(i + 1));
            for e in 0..corners {
                let c = point(zm, e, 0.0);
                let chord = lerp(point(z_at(i), e, 0.0), point(z_at(i + 1), e, 0.0), 0.5);
                dev_z = dev_z.max(dot(sub(c, chord), sub(c, chord)).sqrt());
                for k in 0..nu {
                    let (s0, s1) = (k as f64 / nu as f64, (k + 1) as f64 / nu as f64);
                    dev_u = dev_u.max(patch_deviation(i, e, s0, s1));
                }
            }
        }
        if dev_z <= tolerance && dev_u <= tolerance {
            // A face within the tolerance of one patch a level (a planar one: any face
            // with a collapsed end) needs no division across; where it narrows, its
            // levels get fewer distinct points (the others repeated), keeping its patches
            // about as wide as at its widest, so that no fan of slivers converges on a
            // collapsed corner.
            let flat: Vec<bool> = (0..corners)
                .map(|e| (0..nz).all(|i| patch_deviation(i, e, 0.0, 1.0) <= tolerance))
                .collect();
            let sections: Vec<Vec<[f64; 3]>> = (0..=nz).map(|i| section(z_at(i))).collect();
            let width = |i: usize, e: usize| {
                let d = sub(sections[i][(e + 1) % corners], sections[i][e]);
                dot(d, d).sqrt()
            };
            let widest: Vec<f64> = (0..corners)
                .map(|e| (0..=nz).map(|i| width(i, e)).fold(0.0, f64::max))
                .collect();
            // Distinct points of edge `e` at level `i`: a power of two, nu where widest.
            let columns = |i: usize, e: usize| {
                let mut c = if flat[e] { 1 } else { nu };
                while c < nu && (c as f64) * widest[e] < (nu as f64) * width(i, e) {
                    c *= 2;
                }
                c
            };
            let levels: Vec<Vec<[f64; 3]>> = (0..=nz)
                .map(|i| {
                    let p = &sections[i];
                    (0..corners)
                        .flat_map(|e| {
                            let c = columns(i, e);
                            (0..nu).map(move |k| (e, (k * c / nu) as f64 / c as f64))
                        })
                        .map(|(e, s)| along(p[e], p[(e + 1) % corners], s))
                        .collect()
                })
                .collect();
            let corner_index: Vec<usize> = (0..corners).map(|e| e * nu).collect();
            return section_stack(&levels, &corner_index);
        }
        // A twisted patch's centre deviates by about (twist) x width x height, so either
        // split reduces it: split the patch's longer side, which keeps triangles from
        // becoming slivers (a twisted face split only across made 500 mm x 30 µm ones,
        // which also made BVH builds crawl).
        let patch_height = (z2 - z1) / nz as f64;
        let patch_width = levels
            .iter()
            .flat_map(|l| (0..l.len()).map(move |k| sub(l[(k + 1) % l.len()], l[k])))
            .map(|d| dot(d, d).sqrt())
            .fold(0.0, f64::max);
        let mut split_z = dev_z > tolerance;
        let mut split_u = false;
        if dev_u > tolerance {
            if patch_width > patch_height {
                split_u = true;
            } else {
                split_z = true;
            }
        }
        if split_z {
            nz *= 2;
        }
        if split_u {
            nu *= 2;
        }
        if nz * nu * corners > 1 << 19 {
            return Err(err(format!(
                "more than 2^20 triangles needed for tolerance {tolerance} mm"
            )));
        }
    }
}

/// A unit icosphere: the regular icosahedron with each triangle split in four `levels`
/// times, new vertices projected onto the sphere. Triangles index the vertices,
/// counter-clockwise seen from outside; neighbours share vertices exactly (test meshes for
/// watertightness, rays through shared edges and vertices).
pub fn icosphere(levels: usize) -> (Vec<[f64; 3]>, Vec<[usize; 3]>) {
    let unit = |a: [f64; 3]| {
        let l = dot(a, a).sqrt();
        a.map(|c| c / l)
    };
    let g = (1.0 + 5f64.sqrt()) / 2.0;
    let mut verts: Vec<[f64; 3]> = [
        [-1.0, g, 0.0],
        [1.0, g, 0.0],
        [-1.0, -g, 0.0],
        [1.0, -g, 0.0],
        [0.0, -1.0, g],
        [0.0, 1.0, g],
        [0.0, -1.0, -g],
        [0.0, 1.0, -g],
        [g, 0.0, -1.0],
        [g, 0.0, 1.0],
        [-g, 0.0, -1.0],
        [-g, 0.0, 1.0],
    ]
    .map(unit)
    .to_vec();
    let mut faces: Vec<[usize; 3]> = vec![
        [0, 11, 5],
        [0, 5, 1],
        [0, 1, 7],
        [0, 7, 10],
        [0, 10, 11],
        [1, 5, 9],
        [5, 11, 4],
        [11, 10, 2],
        [10, 7, 6],
        [7, 1, 8],
        [3, 9, 4],
        [3, 4, 2],
        [3, 2, 6],
        [3, 6, 8],
        [3, 8, 9],
        [4, 9, 5],
        [2, 4, 11],
        [6, 2, 10],
        [8, 6, 7],
        [9, 8, 1],
    ];
    for _ in 0..levels {
        let mut middle: std::collections::HashMap<(usize, usize), usize> = Default::default();
        let mut next = Vec::with_capacity(4 * faces.len());
        for [a, b, c] in faces {
            let mut mid = |i: usize, j: usize| {
                *middle.entry((i.min(j), i.max(j))).or_insert_with(|| {
                    let (p, q) = (verts[i], verts[j]);
                    verts.push(unit([0, 1, 2].map(|k| p[k] + q[k])));
                    verts.len() - 1
                })
            };
            let (ab, bc, ca) = (mid(a, b), mid(b, c), mid(c, a));
            next.extend([[a, ab, ca], [b, bc, ab], [c, ca, bc], [ab, bc, ca]]);
        }
        faces = next;
    }
    (verts, faces)
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Signed volume of a closed mesh (divergence theorem): positive when outward-facing.
    fn volume(mesh: &[Tri]) -> f64 {
        mesh.iter()
            .map(|t| dot(t[0], cross(t[1], t[2])) / 6.0)
            .sum()
    }

    #[test]
    fn ear_clipping_handles_non_convex_polygons() {
        // An L shape of area 3.
        let l = [
            [0.0, 0.0],
            [2.0, 0.0],
            [2.0, 1.0],
            [1.0, 1.0],
            [1.0, 2.0],
            [0.0, 2.0],
        ];
        let tris = triangulate(&l).unwrap();
        assert_eq!(tris.len(), 4);
        let area: f64 = tris
            .iter()
            .map(|t| 0.5 * signed_area2(&[l[t[0]], l[t[1]], l[t[2]]]))
            .sum();
        assert!((area - 3.0).abs() < 1e-12);
        assert!(tris
            .iter()
            .all(|t| signed_area2(&[l[t[0]], l[t[1]], l[t[2]]]) > 0.0));
        let mut cw = l;
        cw.reverse();
        assert!(triangulate(&cw).is_err());
        assert!(triangulate(&[[0.0, 0.0], [1.0, 0.0]]).is_err());
    }

    /// Checks that `pieces` tile `poly` edge to edge with strictly convex pieces; returns
    /// their count.
    fn check_tiling(poly: &[[f64; 2]], pieces: &[Vec<usize>]) -> usize {
        let n = poly.len();
        let area: f64 = pieces
            .iter()
            .map(|p| signed_area2(&p.iter().map(|&i| poly[i]).collect::<Vec<_>>()))
            .sum();
        assert!(
            (area - signed_area2(poly)).abs() <= 1e-9 * area.abs(),
            "{area}"
        );
        let mut edges = std::collections::HashMap::new();
        for p in pieces {
            let m = p.len();
            for k in 0..m {
                let (a, b, c) = (poly[p[k]], poly[p[(k + 1) % m]], poly[p[(k + 2) % m]]);
                assert!(orient(a, b, c) > 0.0, "{p:?} not convex at {b:?}");
                *edges.entry((p[k], p[(k + 1) % m])).or_insert(0) += 1;
            }
        }
        for (&(a, b), &count) in &edges {
            assert_eq!(count, 1);
            // A polygon edge belongs to one piece; a diagonal to two, in opposite senses.
            let side = b == (a + 1) % n;
            assert_eq!(edges.contains_key(&(b, a)), !side, "edge {a} {b}");
        }
        assert!((0..n).all(|i| edges.contains_key(&(i, (i + 1) % n))));
        pieces.len()
    }

    #[test]
    fn convex_pieces_tile_non_convex_polygons() {
        let l = [
            [0.0, 0.0],
            [2.0, 0.0],
            [2.0, 1.0],
            [1.0, 1.0],
            [1.0, 2.0],
            [0.0, 2.0],
        ];
        assert_eq!(check_tiling(&l, &convex_pieces(&l, 32).unwrap()), 2);
        // A comb: four teeth on a base; the corners along the base line are collinear.
        let mut comb = vec![[0.0, 0.0], [7.0, 0.0]];
        for t in (0..4).rev() {
            let x = 2.0 * t as f64;
            comb.extend([[x + 1.0, 3.0], [x, 3.0], [x, 1.0]]);
            if t > 0 {
                comb.push([x - 1.0, 1.0]);
            }
        }
        comb.retain(|p| *p != [0.0, 1.0]);
        let comb = simple_polygon(&comb).unwrap();
        let pieces = convex_pieces(&comb, 32).unwrap();
        // Pieces may not have corners in line: every gap between the corners on y = 1
        // is its own piece (2 end pieces, 5 gaps, 2 middle teeth).
        assert_eq!(check_tiling(&comb, &pieces), 9);
        // A convex polygon stays whole unless it has too many corners.
        let circle: Vec<[f64; 2]> = (0..100)
            .map(|k| {
                let a = k as f64 * 0.0628318;
                [3.0 * a.cos(), 2.0 * a.sin()]
            })
            .collect();
        assert_eq!(
            check_tiling(&circle, &convex_pieces(&circle, 200).unwrap()),
            1
        );
        let split = convex_pieces(&circle, 32).unwrap();
        assert!(split.iter().all(|p| p.len() <= 32));
        assert!(check_tiling(&circle, &split) <= 5);
        // Stars: one piece per spike at most, plus the core.
        let star: Vec<[f64; 2]> = (0..16)
            .map(|k| {
                let a = k as f64 * std::f64::consts::PI / 8.0;
                let r = if k % 2 == 0 { 5.0 } else { 2.0 };
                [r * a.cos(), r * a.sin()]
            })
            .collect();
        let pieces = convex_pieces(&star, 32).unwrap();
        eprintln!("star: {} pieces", pieces.len());
        assert!(check_tiling(&star, &pieces) <= 9);
    }

    #[test]
    fn simple_polygon_orients_cleans_and_rejects() {
        // Clockwise with a repeated corner and a corner in the middle of an edge.
        let p = simple_polygon(&[
            [0.0, 0.0],
            [0.0, 2.0],
            [0.0, 2.0],
            [2.0, 2.0],
            [2.0, 1.0],
            [2.0, 0.0],
            [0.0, 0.0],
        ])
        .unwrap();
        assert_eq!(p.len(), 4);
        assert!(signed_area2(&p) > 0.0);
        for bad in [
            vec![[0.0, 0.0], [1.0, 1.0], [1.0, 0.0], [0.0, 1.0]], // bow tie
            vec![[0.0, 0.0], [1.0, 0.0], [2.0, 0.0]],             // no area
            vec![[0.0, 0.0], [1.0, 0.0]],
            vec![[0.0, 0.0], [1.0, f64::NAN], [0.0, 1.0]],
            // Touching itself: the corner (2, 2) is visited twice.
            vec![
                [0.0, 0.0],
                [4.0, 0.0],
                [4.0, 2.0],
                [2.0, 2.0],
                [3.0, 3.0],
                [1.0, 3.0],
                [2.0, 2.0],
                [0.0, 2.0],
            ],
        ] {
            assert!(simple_polygon(&bad).is_err(), "{bad:?}");
        }
    }

    #[test]
    fn a_prism_stack_is_closed_with_the_right_volume() {
        let sq = |z: f64| vec![[0.0, 0.0, z], [2.0, 0.0, z], [2.0, 3.0, z], [0.0, 3.0, z]];
        let mesh = section_stack(&[sq(0.0), sq(5.0)], &[0, 1, 2, 3]).unwrap();
        assert!((volume(&mesh) - 30.0).abs() < 1e-9, "{}", volume(&mesh));
    }

    #[test]
    fn twisted_prisms_converge_to_the_analytic_volume() {
        // A square rotated linearly with z keeps its area at every height: volume = area * h.
        let twist = 1.2f64;
        let section = |z: f64| {
            let a = twist * z / 10.0;
            let (s, c) = a.sin_cos();
            [[-3.0, -2.0], [3.0, -2.0], [3.0, 2.0], [-3.0, 2.0]]
                .map(|p| [c * p[0] - s * p[1], s * p[0] + c * p[1], z])
                .to_vec()
        };
        for tol in [1e-1, 1e-2, 1e-3] {
            let mesh = ruled_solid(&section, -5.0, 5.0, tol).unwrap();
            let v = volume(&mesh);
            // The mesh is within tol of the surface everywhere: the volume error is at most
            // tol times the side area (and the mesh chords cut inside the twisted faces).
            let side_area = 2.0 * (6.0 + 4.0) * 10.0 * 1.2;
            assert!(
                (v - 240.0).abs() <= tol * side_area,
                "tol {tol}: volume {v}"
            );
        }
        assert!(ruled_solid(&section, -5.0, 5.0, 0.0).is_err());
    }

    /// A generic trap whose top face has one corner moved (celeritas/solids.gdml's arb8):
    /// its twisted side faces must become well-shaped triangles within the tolerance, not
    /// face-high slivers (refining across only once gave 500 mm x 30 µm triangles).
    #[test]
    fn twisted_faces_tessellate_into_well_shaped_triangles() {
        let bottom = [
            [-450.0, -450.0],
            [450.0, -450.0],
            [450.0, 450.0],
            [-450.0, 450.0],
        ];
        let top = [
            [-350.0, -350.0],
            [350.0, -550.0],
            [350.0, 350.0],
            [-350.0, 350.0],
        ];
        let dz = 500.0;
        let section = |z: f64| {
            let f = (z + dz) / (2.0 * dz);
            (0..4)
                .map(|k| {
                    let (b, t): ([f64; 2], [f64; 2]) = (bottom[k], top[k]);
                    [b[0] + f * (t[0] - b[0]), b[1] + f * (t[1] - b[1]), z]
                })
                .collect()
        };
        let tol = 1e-2;
        let mesh = ruled_solid(&section, -dz, dz, tol).unwrap();
        // Longest edge squared over twice the area: about 1 for a right isosceles triangle.
        let worst = mesh
            .iter()
            .map(|t| {
                let longest = (0..3)
                    .map(|k| dot(sub(t[(k + 1) % 3], t[k]), sub(t[(k + 1) % 3], t[k])))
                    .fold(0.0, f64::max);
                let n = cross(sub(t[1], t[0]), sub(t[2], t[0]));
                longest / dot(n, n).sqrt()
            })
            .fold(0.0, f64::max);
        assert!(
            worst < 8.0,
            "{} triangles, worst aspect {worst}",
            mesh.len()
        );
        // Still within the tolerance: the twisted faces' volume (the exact volume of a
        // ruled solid with bilinear sides, by the prismoid formula) within tol x side area.
        let area = |p: &[[f64; 3]]| {
            signed_area2(&p.iter().map(|v| [v[0], v[1]]).collect::<Vec<_>>()) / 2.0
        };
        let exact =
            2.0 * dz / 6.0 * (area(&section(-dz)) + 4.0 * area(&section(0.0)) + area(&section(dz)));
        let side_area = 4.0 * 900.0 * 1000.0;
        assert!(
            (volume(&mesh) - exact).abs() <= tol * side_area,
            "{} vs {exact}",
            volume(&mesh)
        );
    }
}
