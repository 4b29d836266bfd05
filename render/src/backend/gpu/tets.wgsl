// The tets part of the trace kernel (appended to common.wgsl). Not traced on the GPU yet:
// the upload refuses tets states, so these queries never run; they only let the kernel
// compile until the kind's traversal lands.

struct TetsParams {
    unused: vec4<f32>,
}

@group(1) @binding(0) var<uniform> tet_params: TetsParams;

fn kind_first_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32) -> KHit {
    if (tet_params.unused.x > 0.0) {
        return no_hit();
    }
    return no_hit();
}

fn kind_exit_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32) -> KHit {
    return no_hit();
}

fn kind_any_hit(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32, iso: f32) -> f32 {
    return -1.0;
}

fn kind_optical_depth(o: vec3<f32>, d: vec3<f32>, lo: f32, hi: f32) -> f32 {
    return 0.0;
}
