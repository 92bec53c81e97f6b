// Light transport for the shaded view: twin of crates/trace/src/render/integrator.rs
// (Renderer::trace, spawn, the shadow rays of Renderer::direct and Renderer::shadow, the
// path pieces of Renderer::radiance). Shading, shadow rays, specular and scattering code
// is composed in only when the scene calls for it.
// #import generated/trace_records
// #import trace/scene
// #import volume/rng
// #import render/bindings
// #import render/optics
// #import render/media

// `p` moved off the surface with normal `n` to the side `w` leaves toward.
fn spawn(p: vec3<f32>, n: vec3<f32>, w: vec3<f32>) -> vec3<f32> {
    let side = select(-1.0, 1.0, dot(w, n) >= 0.0);
    let scale = 1.0 + max(abs(p.x), max(abs(p.y), abs(p.z)));
    return p + side * (64.0 * 1.1920929e-7 * scale) * n;
}

// The instance the last traced ray's origin was located in (UNSET: none, or a flat scene).
var<private> traced_from: u32;

// The scene's first crossing along a ray from its origin (the one traversal call site).
fn trace_scene(o: vec3<f32>, d: vec3<f32>, tmax: f32) -> Hit {
    var located = UNSET;
    if rparams.hierarchical != 0u {
        var status = 0u;
        located = locate_point(o, vec3<f32>(0.0), &status);
    }
    traced_from = located;
    // Render rays are f32 throughout: their origins have no rest.
    return cross_from(located, o, vec3<f32>(0.0), d, 0.0, tmax);
}

// The path (or view ray) has just passed a see-through surface: if its origin lies in an
// instance drawn solid, that instance is hit where the surface was passed (twin of
// Renderer::trace_after); otherwise `h`, the crossing traced.
fn after_crossing(s: ptr<function, Sample>, h: Hit) -> Hit {
    if !(*s).crossed {
        return h;
    }
    (*s).crossed = false;
    if traced_from == UNSET {
        return h;
    }
    let cover = instances[traced_from].covering;
    if cover == UNSET {
        return h;
    }
    (*s).o = (*s).cross_p;
    return Hit(true, 0.0, (*s).cross_n, cover, UNSET);
}

// The path passes the see-through surface of `h` at `p` (normal `n`).
fn pass_surface(s: ptr<function, Sample>, p: vec3<f32>, n: vec3<f32>) {
    (*s).o = spawn(p, n, (*s).d);
    (*s).crossed = true;
    (*s).cross_p = p;
    (*s).cross_n = n;
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
    } else if kind != RENDER_MATERIAL_TRANSPARENT && kind != RENDER_MATERIAL_SHELL {
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

// #if scattering
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
    if kind == RENDER_MATERIAL_SHELL {
        // Unlit: the colour by the cosine to the view, then the light behind.
        let opacity = item_b(mat).x;
        (*s).radiance += (*s).beta * opacity * abs(dot(d, n)) * v3(item_a(mat));
        (*s).beta *= 1.0 - opacity;
    }
    if kind == RENDER_MATERIAL_TRANSPARENT || kind == RENDER_MATERIAL_SHELL {
        pass_surface(s, p, n);
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
