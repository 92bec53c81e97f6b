//! Shared helpers of the csg tests: the test kit's generator and vector helpers, and a
//! triangle grid (the integration tests include it as a module, the crate's unit tests by
//! path).

/// The tests' deterministic generator (xorshift64*), so failures reproduce from the seed.
#[allow(unused_imports)] // each test file uses its own subset
pub use hytrace_testkit::{Random, XorShift64Star as Rng};

/// An `n x n` grid of unit quads over `[0, n]^2` with heights `z(x, y)`, two triangles per
/// quad, counter-clockwise seen from above. With integer vertex coordinates, the BVH node
/// boxes have their faces in the planes `x = i` and `y = j`.
#[allow(dead_code)] // not every test file uses it
pub fn grid(n: usize, z: impl Fn(f64, f64) -> f64) -> Vec<[[f64; 3]; 3]> {
    let p = |i: usize, j: usize| [i as f64, j as f64, z(i as f64, j as f64)];
    let mut tris = Vec::new();
    for i in 0..n {
        for j in 0..n {
            let (a, b, c, d) = (p(i, j), p(i + 1, j), p(i + 1, j + 1), p(i, j + 1));
            tris.push([a, b, c]);
            tris.push([a, c, d]);
        }
    }
    tris
}

#[allow(unused_imports)] // not every test file uses them
pub use hytrace_testkit::vec3::{cross, sub};
