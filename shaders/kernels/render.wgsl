// The render kernel (hytrace render --backend gpu): twin of crates/trace/src/render/mod.rs
// (one sample of a pixel, the geometry views or the shaded view), compared pixel by pixel
// in crates/trace/tests/gpu_render.rs. The rest is split by concern as the Rust modules are:
// render/camera (camera.rs), render/views (views.rs), render/integrator (integrator.rs),
// render/media (media.rs), render/optics (optics.rs), and render/bindings (the kernel's
// records and the state of a sample). Each dispatch takes one sample of every pixel of a
// batch; a sample is one loop whose every iteration traces one ray, the path's or a shadow
// ray's, and then meets the media along it, so the scene traversal and the volume walk are
// each inlined once. Shading, shadow rays, specular and media code is composed in only when
// the scene calls for it. Media: emission-absorption (twin of
// render::media::Media::emission_absorption) or scattering (delta tracking to a real
// collision, ratio tracking for shadow rays: twins of Media::collision and
// Media::transmittance).
// #import generated/trace_records
// #import trace/scene
// #import volume/rng
// #import loop_budget
// #import render/bindings
// #import render/camera
// #import render/views
// #import render/integrator
// #import render/media

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
    s.crossed = false;
    s.shell_found = false;
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
        var h = trace_scene(ro, rd, tmax);
        if s.mode != MODE_SHADOW {
            h = after_crossing(&s, h);
        }
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
            opaque = kind != RENDER_MATERIAL_TRANSPARENT && kind != RENDER_MATERIAL_SHELL && kind != RENDER_MATERIAL_DIELECTRIC;
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

@compute @workgroup_size(64)
fn render(@builtin(global_invocation_id) gid: vec3<u32>, @builtin(num_workgroups) groups_: vec3<u32>) {
    let k = gid.y * groups_.x * 64u + gid.x;
    // A batch of rows, or of the pixels listed (a streamed render's pending ones).
    let count = select(rparams.width * rparams.row_count, rparams.listed, rparams.listed > 0u);
    if k >= count {
        return;
    }
    var pixel = rparams.row_offset * rparams.width + k;
    // #if streamed
    if rparams.listed > 0u {
        pixel = pixel_ids[k];
    }
    // #endif
    let i = pixel % rparams.width;
    let j = pixel / rparams.width;
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
    // #if streamed
    // w: 2 once a sample of the pixel read a brick the pool lacked: the host discards the
    // pixel and renders it again once the brick is resident.
    if stream_missing {
        cut = 2.0;
    }
    // #endif
    if s + 1u == rparams.spp {
        sum /= f32(rparams.spp);
    }
    image[k] = vec4<f32>(sum, cut);
}
