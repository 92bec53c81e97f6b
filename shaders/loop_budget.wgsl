// Whether this invocation's loops were cut short by the driver. Mesa's llvmpipe (lavapipe,
// the CPU Vulkan driver CI runs on) gives all the loops of one shader invocation, per SIMD
// vector of 8 lanes, 65535 iterations together; past that every loop leaves at its first
// test, silently. The probe is a loop of `two` iterations (2, passed in at run time so no
// compiler can fold it): it takes one iteration only when that budget is spent. Real GPUs
// have no such budget and always answer false.
fn loops_cut_short(two: u32) -> bool {
    var trips = 0u;
    loop {
        trips += 1u;
        if trips >= two {
            break;
        }
    }
    return trips < two;
}
