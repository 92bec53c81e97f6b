//! Shared helpers of the csg tests: a deterministic random generator and a triangle grid
//! (the integration tests include it as a module, the crate's unit tests by path).

/// A deterministic generator (xorshift64*), so failures reproduce from the seed.
pub struct Rng(pub u64);

#[allow(dead_code)] // each test file uses its own subset
impl Rng {
    /// Uniform in [0, 1).
    pub fn next(&mut self) -> f64 {
        self.0 ^= self.0 >> 12;
        self.0 ^= self.0 << 25;
        self.0 ^= self.0 >> 27;
        (self.0.wrapping_mul(0x2545_f491_4f6c_dd1d) >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next()
    }

    /// A uniformly distributed unit vector.
    pub fn unit(&mut self) -> [f64; 3] {
        loop {
            let v = [0, 1, 2].map(|_| self.range(-1., 1.));
            let l = (v[0] * v[0] + v[1] * v[1] + v[2] * v[2]).sqrt();
            if l > 0.1 && l <= 1.0 {
                return v.map(|c| c / l);
            }
        }
    }

    /// A ray from a uniform point of the cube of half side `origin_half` aimed at a uniform
    /// point of the cube of half side `target_half` (both centred on the origin): origin
    /// and unit direction.
    pub fn aimed(&mut self, origin_half: f64, target_half: f64) -> ([f64; 3], [f64; 3]) {
        let o = [0, 1, 2].map(|_| self.range(-origin_half, origin_half));
        let t = [0, 1, 2].map(|_| self.range(-target_half, target_half));
        let d = [t[0] - o[0], t[1] - o[1], t[2] - o[2]];
        let l = (d[0] * d[0] + d[1] * d[1] + d[2] * d[2]).sqrt();
        (o, d.map(|c| c / l))
    }
}

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

/// `a - b`.
#[allow(dead_code)] // not every test file uses it
pub fn sub(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [a[0] - b[0], a[1] - b[1], a[2] - b[2]]
}

/// The cross product `a x b`.
#[allow(dead_code)] // not every test file uses it
pub fn cross(a: [f64; 3], b: [f64; 3]) -> [f64; 3] {
    [
        a[1] * b[2] - a[2] * b[1],
        a[2] * b[0] - a[0] * b[2],
        a[0] * b[1] - a[1] * b[0],
    ]
}
