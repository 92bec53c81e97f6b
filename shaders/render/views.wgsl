// Geometry views: twin of crates/trace/src/render/views.rs (id_colour and
// Renderer::geometry_view, one surface per step): the colour of the first non-transparent
// surface.
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
