// The f32 helpers every module shares: twin of hytrace_csg::real (V3's dot, cross, length
// and max_abs; two_product and two_sum), one copy for every kernel.
//
// Vector arithmetic is written out term by term in the CPU's order (x, then y, then z,
// summed left to right) rather than with WGSL's built-ins (`dot`, `length`, `cross`), whose
// order of operations and fusing the specification leaves to the implementation: written
// out, the GPU's values are the CPU's to the last bit (f32 arithmetic is not associative).
//
// The error-free transformations are written so that neither fma contraction nor a shader
// compiler's inexact algebraic rewrites ((a + b) - a -> b, which Mesa's NIR applies, also
// across inlined functions, for operations WGSL cannot mark exact) change their values:
// products are split on the bits (Dekker), and the error terms of sums use s * one - a
// with `one` a run-time 1.0 no constant folding can see (opaque_one). A pair hi + lo is a
// vec2<f32> (x = hi, y = lo).

// The CPU's V3::dot.
fn v3_dot(a: vec3<f32>, b: vec3<f32>) -> f32 {
    return a.x * b.x + a.y * b.y + a.z * b.z;
}

// The CPU's V3::cross.
fn v3_cross(a: vec3<f32>, b: vec3<f32>) -> vec3<f32> {
    return vec3<f32>(a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x);
}

// The CPU's V3::length.
fn v3_length(a: vec3<f32>) -> f32 {
    return sqrt(v3_dot(a, a));
}

// The CPU's V3::max_abs.
fn v3_max_abs(v: vec3<f32>) -> f32 {
    return max(max(abs(v.x), abs(v.y)), abs(v.z));
}

// 1.0, unless x is a NaN (then 2.0; a NaN input gives a NaN or no result either way): a
// run-time 1 that no constant folding can see, for two_sum and for products that must be
// rounded before a following sum (a compiler that contracts x * one + c into an fma still
// rounds x first).
fn opaque_one(x: f32) -> f32 {
    return select(1.0, 2.0, (bitcast<u32>(x) & 0x7fffffffu) > 0x7f800000u);
}

// The top 12 significant bits of x, rounded to nearest at bit 12 of the significand (the
// carry may move into the exponent, which is the correctly rounded value); the rest,
// x - split_hi(x), is exact in f32. Done on the bits, so no algebraic simplification of a
// float expression can undo it.
fn split_hi(x: f32) -> f32 {
    return bitcast<f32>((bitcast<u32>(x) + 0x800u) & 0xfffff000u);
}

// a * b as hi + lo, exactly (Dekker's product; the CPU's two_product). All four partial
// products are exact, so a compiler that contracts one of them with the following addition
// into an fma gets the same values; the rounded product p is used twice, so it is not fused
// away.
fn two_product(a: f32, b: f32) -> vec2<f32> {
    let ah = split_hi(a);
    let al = a - ah;
    let bh = split_hi(b);
    let bl = b - bh;
    let p = a * b;
    return vec2<f32>(p, ((ah * bh - p) + ah * bl + al * bh) + al * bl);
}

// a + b as hi + lo, exactly (Knuth's two-sum; the CPU's two_sum). `one` must be
// opaque_one's 1.0: s * one - a matches no simplification rule and equals the rounded
// s - a, also when fused into fma(s, one, -a).
fn two_sum(a: f32, b: f32, one: f32) -> vec2<f32> {
    let s = a + b;
    let bb = s * one - a;
    return vec2<f32>(s, (a - (s - bb)) + (b - bb));
}
