// The render kernel (hytrace render --backend gpu): twin of the CPU renderer's geometry
// views and surface light transport (crates/trace/src/render/{views,integrator}.rs),
// compared pixel by pixel in crates/trace/tests/gpu_render.rs. Each dispatch takes one
// sample of every pixel of a batch; a sample is one loop whose every iteration traces one
// ray, the path's or a shadow ray's, and then meets the media along it, so the scene
// traversal and the volume walk are each inlined once. Shading, shadow rays, specular and media code is composed in
// only when the scene calls for it. Media (up to RENDER_MAX_MEDIA placements, their grids
// sharing the volume group's arrays): emission-absorption (twin of
// render::volumes::Media::emission_absorption) or scattering (delta tracking to a real
// collision, ratio tracking for shadow rays: twins of Media::collision and
// Media::transmittance, through the same volume/estimate module as the transmittance
// kernel).
// #import trace_records
// #import trace/scene
// #import volume/rng
// #import render/optics
// #import loop_budget
// #if absorption
// #import volume/walk
// #import volume/grid
// #endif
// #if scattering
// #import volume/estimate
// #endif

@group(2) @binding(0) var<storage, read> rparams: RenderParams;
@group(2) @binding(1) var<storage, read> items: array<RenderItem>;
@group(2) @binding(2) var<storage, read> instances: array<RenderInstance>;
@group(2) @binding(3) var<storage, read_write> image: array<vec4<f32>>;
@group(2) @binding(4) var<storage, read> media: array<RenderMedium>;

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

// `p` moved off the surface with normal `n` to the side `w` leaves toward.
fn spawn(p: vec3<f32>, n: vec3<f32>, w: vec3<f32>) -> vec3<f32> {
    let side = select(-1.0, 1.0, dot(w, n) >= 0.0);
    let scale = 1.0 + max(abs(p.x), max(abs(p.y), abs(p.z)));
    return p + side * (64.0 * 1.1920929e-7 * scale) * n;
}

// The colour of identity `id` (twin of render::views::id_colour).
fn id_colour(id: u32) -> vec3<f32> {
    if id == UNSET {
        return vec3<f32>(0.5);
    }
    let h = pcg4d(vec4<u32>(id, 0x68797472u, 0u, 0u));
    return vec3<f32>(0.15) + 0.85 * vec3<f32>(vec3<u32>(h.x >> 24u, h.y >> 24u, h.z >> 24u)) / 255.0;
}

// The scene's first crossing along a ray from its origin (the one traversal call site).
fn trace_scene(o: vec3<f32>, d: vec3<f32>, tmax: f32) -> Hit {
    var located = UNSET;
    if rparams.hierarchical != 0u {
        var status = 0u;
        located = locate_point(o, vec3<f32>(0.0), &status);
    }
    // Render rays are f32 throughout: their origins have no rest.
    return cross_from(located, o, vec3<f32>(0.0), d, 0.0, tmax);
}

// Geometry views: the colour of the first non-transparent surface.
fn view_step(s: ptr<function, Sample>, h: Hit) {
    if !h.found {
        (*s).mode = MODE_DONE;
        return;
    }
    let inst = instances[h.instance];
    if items[inst.material].kind == RENDER_MATERIAL_TRANSPARENT && (*s).events < MAX_TRANSPARENT {
        let next = spawn((*s).o + h.t * (*s).d, h.normal, (*s).d);
        (*s).travelled += length(next - (*s).o);
        (*s).o = next;
        (*s).events += 1u;
        return;
    }
    (*s).mode = MODE_DONE;
    if items[inst.material].kind == RENDER_MATERIAL_TRANSPARENT {
        return;
    }
    let view = rparams.view;
    var c = vec3<f32>(0.0);
    if view == RENDER_VIEW_DEPTH {
        let range = max(rparams.depth_far - rparams.depth_near, 1e-12);
        c = vec3<f32>(clamp((rparams.depth_far - ((*s).travelled + h.t)) / range, 0.0, 1.0));
    } else if view == RENDER_VIEW_NORMAL {
        c = 0.5 * (h.normal + vec3<f32>(1.0));
    } else if view == RENDER_VIEW_SOLID {
        c = id_colour(inst.solid);
    } else if view == RENDER_VIEW_PRIM {
        c = id_colour(h.prim);
    } else if view == RENDER_VIEW_INSTANCE {
        c = id_colour(h.instance);
    } else {
        c = id_colour(inst.boundary);
    }
    (*s).radiance = c;
}

// #if lights
// The lit point is done: a multiple-scattering path goes on from it in a direction drawn
// from the phase function; any other sample ends.
fn end_lighting(s: ptr<function, Sample>, rng: ptr<function, VolumeRng>) {
    if !(*s).resume {
        (*s).mode = MODE_DONE;
        return;
    }
    let u = vec2<f32>(rng_next(rng), rng_next(rng));
    (*s).d = sample_henyey_greenstein((*s).din, (*s).g, u);
    (*s).o = (*s).p;
    (*s).events += 1u;
    (*s).scatter = false;
    (*s).resume = false;
    (*s).mode = MODE_PATH;
}

// How the lit point answers light arriving from direction `w`: cos / pi on a diffuse
// surface, the phase function in a medium.
fn response(s: ptr<function, Sample>, w: vec3<f32>) -> f32 {
    if (*s).scatter {
        return henyey_greenstein(dot((*s).din, w), (*s).g);
    }
    return dot((*s).facing, w) / RENDER_PI;
}

// Starts the next shadow ray of the lit point (lights in order, then the environment),
// or ends the lighting when none is left.
fn next_shadow(s: ptr<function, Sample>, rng: ptr<function, VolumeRng>) {
    loop {
        let k = (*s).next_light;
        (*s).next_light = k + 1u;
        var w = (*s).env_dir;
        var dist = INF;
        var power = v3a(rparams.environment);
        var f = 1.0;
        if k < rparams.light_count {
            let item = rparams.light_first + k;
            if items[item].kind == RENDER_LIGHT_POINT {
                let to = v3(item_a(item)) - (*s).p;
                let d2 = dot(to, to);
                if d2 == 0.0 {
                    continue;
                }
                dist = sqrt(d2);
                w = to / dist;
                power = v3(item_b(item)) / d2;
            } else {
                w = -normalize(v3(item_a(item)));
                power = v3(item_b(item));
            }
            f = response(s, w);
        } else if k > rparams.light_count || !(*s).use_env || all(power == vec3<f32>(0.0)) {
            end_lighting(s, rng);
            return;
        }
        if f <= 0.0 || all(power == vec3<f32>(0.0)) {
            continue;
        }
        // A point in a medium is on no surface.
        let o = select(spawn((*s).p, (*s).n, w), (*s).p, (*s).scatter);
        var reach = dist;
        if dist < INF {
            reach = max(dist - length(o - (*s).p), 0.0);
        }
        (*s).so = o;
        (*s).sd = w;
        (*s).left = reach;
        (*s).weight = 1.0;
        (*s).sinside = 0.0;
        (*s).crossings = 0u;
        (*s).contribution = (*s).tint * power * f;
        (*s).mode = MODE_SHADOW;
        return;
    }
}

// One crossing of a shadow ray: light arrives, passes a see-through surface, or is blocked.
fn shadow_step(s: ptr<function, Sample>, h: Hit, rng: ptr<function, VolumeRng>) {
    var t = (*s).left;
    if h.found {
        t = h.t;
    }
    if (*s).sinside > 0.0 {
        (*s).weight *= exp(-t / (*s).sinside);
    }
    if !h.found {
        (*s).radiance += (*s).contribution * (*s).weight;
        next_shadow(s, rng);
        return;
    }
    let m = instances[h.instance].material;
    let kind = items[m].kind;
    if kind == RENDER_MATERIAL_DIELECTRIC {
        let entering = dot((*s).sd, h.normal) < 0.0;
        let ior = item_b(m).x;
        let eta = select(1.0 / ior, ior, entering);
        (*s).weight *= 1.0 - fresnel(abs(dot((*s).sd, h.normal)), eta);
        (*s).sinside = select(0.0, item_b(m).y, entering);
    } else if kind != RENDER_MATERIAL_TRANSPARENT {
        next_shadow(s, rng);
        return;
    }
    (*s).crossings += 1u;
    if (*s).weight == 0.0 || (*s).crossings >= MAX_SHADOW_CROSSINGS {
        next_shadow(s, rng);
        return;
    }
    (*s).so = spawn((*s).so + t * (*s).sd, h.normal, (*s).sd);
    (*s).left -= t;
    if (*s).left <= 0.0 {
        (*s).radiance += (*s).contribution * (*s).weight;
        next_shadow(s, rng);
    }
}
// #endif

// What the media do along one piece of a ray.
struct MediumStep {
    // Light they emit toward the piece's start and the fraction they let through.
    radiance: vec3<f32>,
    transmittance: f32,
    // A real collision on a path (scattering media): where, the grid value there, and in
    // which placed medium.
    collided: bool,
    t: f32,
    value: f32,
    medium: u32,
}

fn no_medium() -> MediumStep {
    return MediumStep(vec3<f32>(0.0), 1.0, false, 0.0, 0.0, 0u);
}

// #if media
// A world point (w = 1) or direction (w = 0) in the index space of placed medium `k`
// (translated as its grid's upload).
fn medium_space(k: u32, p: vec3<f32>, w: f32) -> vec3<f32> {
    let m = media[k].rows;
    return vec3<f32>(dot(m[0].xyz, p) + w * m[0].w, dot(m[1].xyz, p) + w * m[1].w, dot(m[2].xyz, p) + w * m[2].w);
}

fn medium_emission(k: u32) -> vec3<f32> {
    let e = media[k].emission;
    return vec3<f32>(e[0], e[1], e[2]);
}
// #endif

// #if absorption
// Emission-absorption of the media over [0, t1] of the world ray o + t d, path and shadow
// pieces alike: midpoint compositing over the union of the ray's parts inside each
// medium's range-mips box, in steps of `medium_step` voxels of the finest medium; at each
// step the media covering it add their extinctions sigma and sources j, the step adds
// T j / sigma (1 - exp(-sigma h)) and multiplies T by exp(-sigma h).
fn emission_absorption(o: vec3<f32>, d: vec3<f32>, t1: f32) -> MediumStep {
    var out = no_medium();
    // Per medium crossed: the ray in its index space and its span there.
    var origin: array<vec3<f32>, RENDER_MAX_MEDIA>;
    var dir: array<vec3<f32>, RENDER_MAX_MEDIA>;
    var span_from: array<f32, RENDER_MAX_MEDIA>;
    var span_to: array<f32, RENDER_MAX_MEDIA>;
    var crossed: array<u32, RENDER_MAX_MEDIA>;
    var count = 0u;
    var a = INF;
    var b = -INF;
    var h = INF;
    for (var k = 0u; k < rparams.media_count; k++) {
        use_volume(media[k].volume);
        let oi = medium_space(k, o, 1.0);
        let di = medium_space(k, d, 0.0);
        var w = walk_start(oi, di, 0.0, t1, true);
        let s0 = w.base;
        let s1 = walk_absolute(&w, w.t_end);
        if s0 < s1 {
            origin[count] = oi;
            dir[count] = di;
            span_from[count] = s0;
            span_to[count] = s1;
            crossed[count] = k;
            count += 1u;
            a = min(a, s0);
            b = max(b, s1);
            h = min(h, rparams.medium_step / length(di));
        }
    }
    if count == 0u {
        return out;
    }
    let n = max(ceil((b - a) / h), 1.0);
    let step = (b - a) / n;
    for (var i = 0u; i < u32(n); i++) {
        let t = a + (f32(i) + 0.5) * step;
        var sigma = 0.0;
        var source = vec3<f32>(0.0);
        for (var c = 0u; c < count; c++) {
            if t >= span_from[c] && t <= span_to[c] {
                let k = crossed[c];
                use_volume(media[k].volume);
                let p = origin[c] + t * dir[c];
                let cell = floor(p);
                let value = trilinear_sum(grid_fetch(vec3<i32>(cell), 8u), p - cell);
                let density = value * vparams.density_scale;
                sigma += density;
                source += density * value * medium_emission(k);
            }
        }
        if sigma > 0.0 {
            let step_t = exp(-sigma * step);
            out.radiance += out.transmittance * source / sigma * (1.0 - step_t);
            out.transmittance *= step_t;
        }
    }
    return out;
}
// #endif

// #if scattering
// The scattering media over [0, t1] of the world ray o + t d, each under the local
// majorants of its range mips, in placement order (twins of Media::collision and
// Media::transmittance): a path piece's first real collision by delta tracking on the
// path's stream (the earliest of the media's collisions); a shadow piece's transmittance
// by ratio tracking, each medium on a stream of its own keyed by one draw of the path's.
fn medium_tracked(o: vec3<f32>, d: vec3<f32>, t1: f32, shadow: bool, rng: ptr<function, VolumeRng>) -> MediumStep {
    var out = no_medium();
    var est = VOLUME_ESTIMATOR_DELTA;
    var key = 0u;
    if shadow {
        est = VOLUME_ESTIMATOR_RATIO;
        key = rng_u32(rng);
    }
    for (var k = 0u; k < rparams.media_count; k++) {
        use_volume(media[k].volume);
        var stream = *rng;
        if shadow {
            stream = rng_new(media[k].seed, key, 0u);
        }
        let e = estimate_sample(medium_space(k, o, 1.0), medium_space(k, d, 0.0), 0.0, t1, est, false, &stream, false);
        if shadow {
            out.transmittance *= e.weight;
        } else {
            *rng = stream;
            if e.collided && (!out.collided || e.t < out.t) {
                out.collided = true;
                out.t = e.t;
                out.value = e.value;
                out.medium = k;
            }
        }
    }
    return out;
}

// The path collided in medium `m.medium` at `m.t`: the medium's emission (the collision
// estimator of j / sigma = value * colour) and its light through the phase function;
// single scattering ends there, multiple scattering goes on from it.
fn scatter_step(s: ptr<function, Sample>, m: MediumStep, rng: ptr<function, VolumeRng>) {
    if (*s).inside > 0.0 {
        (*s).beta *= exp(-m.t / (*s).inside);
    }
    let d = (*s).d;
    let medium = media[m.medium];
    (*s).radiance += (*s).beta * m.value * medium_emission(m.medium);
    (*s).beta *= medium.albedo;
    if all((*s).beta == vec3<f32>(0.0)) {
        (*s).mode = MODE_DONE;
        return;
    }
    let single = rparams.volume_mode == RENDER_VOLUMES_SINGLE;
    if single {
        let u = vec2<f32>(rng_next(rng), rng_next(rng));
        (*s).env_dir = sample_henyey_greenstein(d, medium.g, u);
    }
    (*s).p = (*s).o + m.t * d;
    (*s).scatter = true;
    (*s).din = d;
    (*s).g = medium.g;
    (*s).use_env = single;
    (*s).resume = !single;
    (*s).tint = (*s).beta;
    (*s).next_light = 0u;
    next_shadow(s, rng);
}
// #endif

// One piece of the path (twin of Renderer::radiance): the media along it (`m`), then its
// surface.
fn path_step(s: ptr<function, Sample>, h: Hit, m: MediumStep, rng: ptr<function, VolumeRng>) {
    var t_end = INF;
    if h.found {
        t_end = h.t;
    }
    // #if scattering
    if m.collided {
        scatter_step(s, m, rng);
        return;
    }
    // #endif
    (*s).radiance += (*s).beta * m.radiance;
    (*s).beta *= m.transmittance;
    if (*s).inside > 0.0 {
        (*s).beta *= exp(-t_end / (*s).inside);
    }
    if !h.found {
        (*s).radiance += (*s).beta * v3a(rparams.environment);
        (*s).mode = MODE_DONE;
        return;
    }
    let d = (*s).d;
    let p = (*s).o + t_end * d;
    let n = h.normal;
    let facing = select(-n, n, dot(d, n) < 0.0);
    let mat = instances[h.instance].material;
    let kind = items[mat].kind;
    (*s).events += 1u;
    if kind == RENDER_MATERIAL_EMITTER {
        (*s).radiance += (*s).beta * v3(item_a(mat));
        (*s).mode = MODE_DONE;
        return;
    }
    if kind == RENDER_MATERIAL_TRANSPARENT {
        (*s).o = spawn(p, n, d);
        return;
    }
    // #if specular
    if kind == RENDER_MATERIAL_MIRROR {
        (*s).beta *= v3(item_a(mat));
        (*s).d = mirror(d, facing);
        (*s).o = spawn(p, n, (*s).d);
        return;
    }
    if kind == RENDER_MATERIAL_DIELECTRIC {
        let entering = dot(d, n) < 0.0;
        let ior = item_b(mat).x;
        let eta = select(1.0 / ior, ior, entering);
        let reflectance = fresnel(-dot(d, facing), eta);
        let r = refraction(d, facing, eta);
        var through = false;
        if r.ok {
            through = rng_next(rng) >= reflectance;
        }
        if through {
            (*s).inside = select(0.0, item_b(mat).y, entering);
            (*s).d = r.d;
        } else {
            (*s).d = mirror(d, facing);
        }
        (*s).o = spawn(p, n, (*s).d);
        return;
    }
    // #endif
    var colour = vec3<f32>(1.0);
    if kind == RENDER_MATERIAL_DIFFUSE || kind == RENDER_MATERIAL_MIRROR {
        colour = v3(item_a(mat));
    }
    // #if shading
    let u = vec2<f32>(rng_next(rng), rng_next(rng));
    (*s).env_dir = cosine_direction(facing, u);
    (*s).p = p;
    (*s).n = n;
    (*s).facing = facing;
    (*s).scatter = false;
    (*s).use_env = true;
    (*s).resume = false;
    (*s).tint = (*s).beta * colour;
    (*s).next_light = 0u;
    next_shadow(s, rng);
    return;
    // #endif
    (*s).radiance += (*s).beta * colour;
    (*s).mode = MODE_DONE;
}

// One sample of the pixel's light along the camera ray `o + t d`.
fn radiance_sample(o: vec3<f32>, d: vec3<f32>, rng: ptr<function, VolumeRng>) -> vec3<f32> {
    var s: Sample;
    s.mode = MODE_PATH;
    s.o = o;
    s.d = d;
    s.beta = vec3<f32>(1.0);
    s.radiance = vec3<f32>(0.0);
    s.inside = 0.0;
    s.events = 0u;
    s.travelled = 0.0;
    s.scatter = false;
    s.g = 0.0;
    s.use_env = false;
    s.resume = false;
    let shaded = rparams.view == RENDER_VIEW_SHADED;
    loop {
        if s.mode == MODE_DONE || (shaded && s.mode == MODE_PATH && s.events > rparams.max_bounces) {
            break;
        }
        var ro = s.o;
        var rd = s.d;
        var tmax = INF;
        if s.mode == MODE_SHADOW {
            ro = s.so;
            rd = s.sd;
            tmax = s.left;
        }
        let h = trace_scene(ro, rd, tmax);
        if !shaded {
            view_step(&s, h);
            continue;
        }
        let shadow = s.mode == MODE_SHADOW;
        var m = no_medium();
        // #if media
        // The media along this piece, unless it is a shadow ray's ending at an opaque
        // surface (the CPU draws nothing for those either).
        let end = select(tmax, h.t, h.found);
        var opaque = false;
        if h.found {
            let kind = items[instances[h.instance].material].kind;
            opaque = kind != RENDER_MATERIAL_TRANSPARENT && kind != RENDER_MATERIAL_DIELECTRIC;
        }
        let wanted = !(shadow && (opaque || end <= 0.0));
        // #endif
        // #if absorption
        if wanted {
            m = emission_absorption(ro, rd, end);
        }
        // #endif
        // #if scattering
        if wanted {
            m = medium_tracked(ro, rd, end, shadow, rng);
        }
        // #endif
        if !shadow {
            path_step(&s, h, m, rng);
        } else {
            // #if lights
            s.weight *= m.transmittance;
            shadow_step(&s, h, rng);
            // #endif
        }
    }
    return s.radiance;
}

// The camera ray of pixel (i, j) at sample offset `offset` (render::camera::Camera::ray).
fn camera_origin(i: u32, j: u32, offset: vec2<f32>) -> vec3<f32> {
    let eye = vec3<f32>(rparams.eye[0], rparams.eye[1], rparams.eye[2]);
    if rparams.orthographic == 0u {
        return eye;
    }
    let xy = screen(i, j, offset);
    return eye + rparams.extent * (xy.x * v3a(rparams.u) + xy.y * v3a(rparams.v));
}

fn camera_direction(i: u32, j: u32, offset: vec2<f32>) -> vec3<f32> {
    let w = v3a(rparams.w);
    if rparams.orthographic != 0u {
        return w;
    }
    let xy = screen(i, j, offset);
    return normalize(w + rparams.extent * (xy.x * v3a(rparams.u) + xy.y * v3a(rparams.v)));
}

fn v3a(a: array<f32, 3>) -> vec3<f32> {
    return vec3<f32>(a[0], a[1], a[2]);
}

fn screen(i: u32, j: u32, offset: vec2<f32>) -> vec2<f32> {
    let width = f32(rparams.width);
    let height = f32(rparams.height);
    let x = (2.0 * (f32(i) + offset.x) / width - 1.0) * (width / height);
    let y = 1.0 - 2.0 * (f32(j) + offset.y) / height;
    return vec2<f32>(x, y);
}

@compute @workgroup_size(64)
fn render(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups_: vec3<u32>) {
    let k = gid.y * groups_.x * 64u + gid.x;
    if k >= rparams.width * rparams.row_count {
        return;
    }
    let i = k % rparams.width;
    let j = rparams.row_offset + k / rparams.width;
    let pixel = j * rparams.width + i;
    // One sample per dispatch (long paths stay within one invocation's budget): the
    // image holds the running sum, in sample order, until the last sample divides it.
    let s = rparams.sample;
    var rng = rng_new(rparams.seed, pixel, s);
    var offset = vec2<f32>(0.5);
    if rparams.spp != 1u {
        offset.x = rng_next(&rng);
        offset.y = rng_next(&rng);
    }
    var sum = radiance_sample(camera_origin(i, j, offset), camera_direction(i, j, offset), &rng);
    // w: 1 once any sample of the pixel ran out of the driver's loop budget.
    var cut = select(0.0, 1.0, loops_cut_short(rparams.probe_trips));
    if s > 0u {
        sum = image[k].xyz + sum;
        cut = max(cut, image[k].w);
    }
    if s + 1u == rparams.spp {
        sum /= f32(rparams.spp);
    }
    image[k] = vec4<f32>(sum, cut);
}
