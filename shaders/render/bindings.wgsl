// The render kernel's own bindings (group 2), the state of one sample, and small readers
// of its records (crates/trace/src/gpu/records.rs: RenderParams, RenderItem, RenderInstance,
// RenderMedium), shared by the render modules.
// #import generated/trace_records
// #import trace/scene

@group(2) @binding(0) var<storage, read> rparams: RenderParams;
@group(2) @binding(1) var<storage, read> items: array<RenderItem>;
@group(2) @binding(2) var<storage, read> instances: array<RenderInstance>;
@group(2) @binding(3) var<storage, read_write> image: array<vec4<f32>>;
@group(2) @binding(4) var<storage, read> media: array<RenderMedium>;
// #if streamed
// The pixels of a streamed batch (row-major indices), when `rparams.listed` > 0.
@group(2) @binding(5) var<storage, read> pixel_ids: array<u32>;
// #endif

const MODE_PATH: u32 = 0u;
const MODE_SHADOW: u32 = 1u;
const MODE_DONE: u32 = 2u;
// Most transparent surfaces a geometry view passes, crossings of a shadow ray.
const MAX_TRANSPARENT: u32 = 256u;
const MAX_SHADOW_CROSSINGS: u32 = 64u;

struct Sample {
    mode: u32,
    // The path.
    o: vec3<f32>,
    d: vec3<f32>,
    beta: vec3<f32>,
    radiance: vec3<f32>,
    inside: f32,
    events: u32,
    travelled: f32,
    // The see-through surface the path has just passed (point, normal), when `crossed`
    // (twin of render::integrator::Crossed).
    crossed: bool,
    cross_p: vec3<f32>,
    cross_n: vec3<f32>,
    // Geometry views: the first shell passed and its distance, when `shell_found`.
    shell_found: bool,
    shell: Hit,
    shell_dist: f32,
    // The point being lit (a diffuse surface's, or a collision in a medium: `scatter`,
    // lit through the phase function of asymmetry `g` around the travel direction `din`),
    // its lights'
    // cursor, its environment direction (when `use_env`), and whether the path goes on
    // from it afterwards (multiple scattering: `resume`).
    p: vec3<f32>,
    n: vec3<f32>,
    facing: vec3<f32>,
    tint: vec3<f32>,
    env_dir: vec3<f32>,
    next_light: u32,
    scatter: bool,
    din: vec3<f32>,
    g: f32,
    use_env: bool,
    resume: bool,
    // The shadow ray.
    so: vec3<f32>,
    sd: vec3<f32>,
    left: f32,
    weight: f32,
    sinside: f32,
    crossings: u32,
    contribution: vec3<f32>,
}

fn v3(a: vec4<f32>) -> vec3<f32> {
    return vec3<f32>(a.x, a.y, a.z);
}

fn item_a(i: u32) -> vec4<f32> {
    let a = items[i].a;
    return vec4<f32>(a[0], a[1], a[2], a[3]);
}

fn item_b(i: u32) -> vec4<f32> {
    let b = items[i].b;
    return vec4<f32>(b[0], b[1], b[2], b[3]);
}

fn v3a(a: array<f32, 3>) -> vec3<f32> {
    return vec3<f32>(a[0], a[1], a[2]);
}
