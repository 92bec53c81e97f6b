//! Contacts: rays that run along a surface (in a face, along a wall's generator) instead of
//! crossing it. Geant4's convention is the reference: a solid's surface is not its interior
//! (`Inside()` is `kSurface` there), so a ray lying in a face never enters the solid and has
//! no boundary there, while a face that two operands of a union share lies inside the union
//! (G4UnionSolid::Inside is `kInside` where both operands are `kSurface` with opposite
//! normals). The expected answers are computed here from the geometry in f64: which plane a
//! ray lies in is exact for these rays (their coordinates and zero direction components are
//! exact in f32).

use hytrace_csg::{box3, cylinder, PrimTree, Ray, Real, Shape};

/// First crossing after `tmin`: (t, inside before).
fn cross<T: Real>(tree: &PrimTree<T>, o: [f64; 3], d: [f64; 3], tmin: f64) -> (f64, bool) {
    let s = tree.first_crossing(&Ray::from_f64(o, d), T::from_f64(tmin));
    (s.t.to_f64(), s.inside_before)
}

fn prepared<T: Real>(shape: &Shape) -> PrimTree<T> {
    PrimTree::from_shape(shape).unwrap()
}

/// Where a ray is inside the open box `|x_k| < h_k` (its interior): `(t0, t1)`, or `None`
/// when it never enters the interior (it misses, or lies in the plane of a face or outside
/// one).
fn open_box_span(h: [f64; 3], o: [f64; 3], d: [f64; 3]) -> Option<(f64, f64)> {
    let (mut t0, mut t1) = (f64::NEG_INFINITY, f64::INFINITY);
    for k in 0..3 {
        if d[k] == 0.0 {
            // Parallel to the faces of axis k: inside their open slab everywhere or nowhere.
            if o[k].abs() >= h[k] {
                return None;
            }
            continue;
        }
        let (a, b) = ((-h[k] - o[k]) / d[k], (h[k] - o[k]) / d[k]);
        t0 = t0.max(a.min(b));
        t1 = t1.min(a.max(b));
    }
    (t0 < t1).then_some((t0, t1))
}

/// The first boundary after 0 of the open box: its entry if ahead, else its exit if ahead,
/// else `inf`.
fn open_box_reference(h: [f64; 3], o: [f64; 3], d: [f64; 3]) -> f64 {
    match open_box_span(h, o, d) {
        Some((t0, _)) if t0 > 0.0 => t0,
        Some((_, t1)) if t1 > 0.0 => t1,
        _ => f64::INFINITY,
    }
}

fn lone_face_case<T: Real>() {
    let h = [20.0, 30.0, 40.0];
    let bx = prepared::<T>(&box3(2.0 * h[0], 2.0 * h[1], 2.0 * h[2]).unwrap());
    let (x, y, z) = ([1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    let neg = |v: [f64; 3]| v.map(|c: f64| -c);
    let cases: [([f64; 3], [f64; 3]); 10] = [
        // Starting on the +x face and running along it (Geant4's testG4Box and the boolean
        // tests' box: the ray from (20, 0, 0) along y).
        ([20.0, 0.0, 0.0], y),
        ([20.0, 0.0, 0.0], neg(z)),
        ([-20.0, 5.0, -7.0], y),
        // From outside, in the plane of a face: reaching the face and running along it.
        ([20.0, -100.0, 3.0], y),
        ([-7.0, 2.0, 40.0], x),
        ([-100.0, -30.0, 12.0], x),
        // Along an edge, from outside and from a corner.
        ([20.0, 30.0, -100.0], z),
        ([-20.0, -30.0, -40.0], y),
        // Parallel to a face, just inside and just outside it: an exit, a miss.
        ([19.5, -100.0, 0.0], y),
        ([20.5, -100.0, 0.0], y),
    ];
    for (o, d) in cases {
        let want = open_box_reference(h, o, d);
        let (t, _) = cross(&bx, o, d, 0.0);
        let ok = (t.is_infinite() && want.is_infinite()) || (t - want).abs() <= 1e-4;
        assert!(ok, "{}: box ray {o:?} {d:?}: {t}, want {want}", T::NAME);
    }
    // A lone cylinder (Geant4's testG4Tubs: a ray along the outer wall of a tube): along z
    // on the wall, no boundary; just inside it, the far cap.
    let rod = prepared::<T>(&cylinder(50.0, -50.0, 50.0).unwrap());
    let (t, _) = cross(&rod, [50.0, 0.0, 0.0], z, 0.0);
    assert!(t.is_infinite(), "{}: along the wall: {t}", T::NAME);
    let (t, _) = cross(&rod, [0.0, -50.0, -100.0], z, 0.0);
    assert!(
        t.is_infinite(),
        "{}: along the wall from outside: {t}",
        T::NAME
    );
    let (t, inside) = cross(&rod, [49.0, 0.0, 0.0], z, 0.0);
    assert!(
        (t - 50.0).abs() <= 1e-4 && inside,
        "{}: inside: {t}",
        T::NAME
    );
}

#[test]
fn rays_along_a_face_answer_as_geant4_f32() {
    lone_face_case::<f32>();
}

#[test]
fn rays_along_a_face_answer_as_geant4_f64() {
    lone_face_case::<f64>();
}

fn shared_face_case<T: Real>() {
    // Two boxes sharing the face x = 0: their union is the box |x| <= 10, |y| <= 5,
    // |z| <= 5, and the shared face is inside it. Rays in the plane x = 0 cross the union as
    // the open box [-10, 10] x [-5, 5] x [-5, 5] says.
    let h = [10.0, 5.0, 5.0];
    let half = || box3(10.0, 10.0, 10.0).unwrap();
    let pair = prepared::<T>(&(half().translate(-5.0, 0.0, 0.0) + half().translate(5.0, 0.0, 0.0)));
    let cases: [([f64; 3], [f64; 3]); 5] = [
        ([0.0, 0.0, 0.0], [0.0, 1.0, 0.0]),
        ([0.0, 1.0, -2.0], [0.0, 0.0, -1.0]),
        ([0.0, -50.0, 2.0], [0.0, 1.0, 0.0]),
        ([0.0, 3.0, 50.0], [0.0, 0.0, -1.0]),
        ([0.0, -20.0, -20.0], [0.0, 0.6, 0.8]),
    ];
    for (o, d) in cases {
        let want = open_box_reference(h, o, d);
        let (t, _) = cross(&pair, o, d, 0.0);
        assert!(
            (t - want).abs() <= 1e-4,
            "{}: shared face ray {o:?} {d:?}: {t}, want {want}",
            T::NAME
        );
        // From the entry on, the ray is inside until the union's far face.
        let starts_outside = o[1].abs() > 5.0 || o[2].abs() > 5.0;
        if starts_outside {
            let (exit, inside) = cross(&pair, o, d, t);
            let far = open_box_span(h, o, d).unwrap().1;
            assert!(
                inside && (exit - far).abs() <= 1e-4,
                "{}: {o:?} {d:?}: exit {exit} inside {inside}, want {far}",
                T::NAME
            );
        }
    }
}

#[test]
fn rays_along_faces_two_union_operands_share_stay_inside_f32() {
    shared_face_case::<f32>();
}

#[test]
fn rays_along_faces_two_union_operands_share_stay_inside_f64() {
    shared_face_case::<f64>();
}

fn boolean_case<T: Real>() {
    let (y, z) = ([0.0, 1.0, 0.0], [0.0, 0.0, 1.0]);
    // Geant4's testG4IntersectionSolid: the box |x| <= 20, |y| <= 30, |z| <= 40 and a cube of
    // side 20 centred on (0, 10, 0): the intersection is the open box [-10, 10] x [0, 20] x
    // [-10, 10]. Rays in its faces (the cube's faces, inside the first box) never enter it.
    let cut = prepared::<T>(
        &(box3(40.0, 60.0, 80.0).unwrap()
            * box3(20.0, 20.0, 20.0).unwrap().translate(0.0, 10.0, 0.0)),
    );
    let h = [10.0, 10.0, 10.0];
    let centred = |o: [f64; 3]| [o[0], o[1] - 10.0, o[2]];
    for (o, d) in [
        ([0.0, 0.0, 100.0], z.map(|c: f64| -c)),
        ([0.0, 0.0, -100.0], z),
        ([10.0, 0.0, 0.0], y),
        ([10.0, 0.0, 0.0], [-1.0, 0.0, 0.0]),
        // Inside, parallel to the faces: the exit.
        ([5.0, 5.0, -100.0], z),
    ] {
        let want = open_box_reference(h, centred(o), d);
        let (t, _) = cross(&cut, o, d, 0.0);
        let ok = (t.is_infinite() && want.is_infinite()) || (t - want).abs() <= 1e-4;
        assert!(
            ok,
            "{}: intersection ray {o:?} {d:?}: {t}, want {want}",
            T::NAME
        );
    }
    // A slot cut into the top of a box: |x| <= 20, |y| <= 20, |z| <= 20 minus |x| <= 5,
    // |y| <= 5, z >= 0. A ray down the slot's wall x = 5 runs along the surface of the
    // difference (the subtracted box's face, inside the first box) and enters the
    // difference's interior where the slot ends, at z = 0.
    let slot = prepared::<T>(
        &(box3(40.0, 40.0, 40.0).unwrap()
            - box3(10.0, 10.0, 40.0).unwrap().translate(0.0, 0.0, 20.0)),
    );
    let (t, inside) = cross(&slot, [5.0, 0.0, 10.0], [0.0, 0.0, -1.0], 0.0);
    assert!(
        (t - 10.0).abs() <= 1e-4 && !inside,
        "{}: down the slot's wall: {t}",
        T::NAME
    );
    let (t, inside) = cross(&slot, [5.0, 0.0, 10.0], [0.0, 0.0, -1.0], 10.0);
    assert!(
        (t - 30.0).abs() <= 1e-4 && inside,
        "{}: then the bottom: {t}",
        T::NAME
    );
}

#[test]
fn rays_along_faces_of_intersections_and_differences_answer_as_geant4_f32() {
    boolean_case::<f32>();
}

#[test]
fn rays_along_faces_of_intersections_and_differences_answer_as_geant4_f64() {
    boolean_case::<f64>();
}
