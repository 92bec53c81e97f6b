// Geometry views: twin of crates/trace/src/render/views.rs (id_colour and
// Renderer::geometry_view, one surface per step): the colour of the first surface drawn
// solid, else of the first shell passed.
// #import generated/trace_records
// #import trace/scene
// #import volume/rng
// #import render/bindings
// #import render/integrator

// The colour of identity `id` (twin of render::views::id_colour).
fn id_colour(id: u32) -> vec3<f32> {
    if id == UNSET {
        return vec3<f32>(0.5);
    }
    let h = pcg4d(vec4<u32>(id, 0x68797472u, 0u, 0u));
    return vec3<f32>(0.15) + 0.85 * vec3<f32>(vec3<u32>(h.x >> 24u, h.y >> 24u, h.z >> 24u)) / 255.0;
}

// The geometry view's colour of `h`, `distance` from the camera (twin of
// Renderer::view_colour).
fn view_colour(h: Hit, distance: f32) -> vec3<f32> {
    let inst = instances[h.instance];
    let view = rparams.view;
    if view == RENDER_VIEW_DEPTH {
        let range = max(rparams.depth_far - rparams.depth_near, 1e-12);
        return vec3<f32>(clamp((rparams.depth_far - distance) / range, 0.0, 1.0));
    } else if view == RENDER_VIEW_NORMAL {
        return 0.5 * (h.normal + vec3<f32>(1.0));
    } else if view == RENDER_VIEW_SOLID {
        return id_colour(inst.solid);
    } else if view == RENDER_VIEW_PRIM {
        return id_colour(h.prim);
    } else if view == RENDER_VIEW_INSTANCE {
        return id_colour(h.instance);
    }
    return id_colour(inst.boundary);
}

// The view ray ends without a surface drawn solid: the first shell it passed, else black.
fn view_end(s: ptr<function, Sample>) {
    (*s).mode = MODE_DONE;
    if (*s).shell_found {
        (*s).radiance = view_colour((*s).shell, (*s).shell_dist);
    }
}

// Geometry views, one surface per step: the colour of the first surface drawn solid
// (transparent surfaces and shells passed; the first shell shows where nothing solid lies
// behind it).
fn view_step(s: ptr<function, Sample>, h: Hit) {
    if !h.found {
        view_end(s);
        return;
    }
    let kind = items[instances[h.instance].material].kind;
    if kind == RENDER_MATERIAL_TRANSPARENT || kind == RENDER_MATERIAL_SHELL {
        if kind == RENDER_MATERIAL_SHELL && !(*s).shell_found {
            (*s).shell_found = true;
            (*s).shell = h;
            (*s).shell_dist = (*s).travelled + h.t;
        }
        if (*s).events >= MAX_TRANSPARENT {
            view_end(s);
            return;
        }
        let p = (*s).o + h.t * (*s).d;
        let o = (*s).o;
        pass_surface(s, p, h.normal);
        (*s).travelled += length((*s).o - o);
        (*s).events += 1u;
        return;
    }
    (*s).mode = MODE_DONE;
    (*s).radiance = view_colour(h, (*s).travelled + h.t);
}
