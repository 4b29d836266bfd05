//! The data the GPU reads, as `#[repr(C)]` plain-old-data structs: the same bytes on both
//! sides. Each struct here has a twin in `common.wgsl` or `metaballs.wgsl`; every field is a
//! `vec4`-sized group or a 4-byte scalar, so WGSL's uniform and storage layout rules place
//! them exactly where `repr(C)` does (the tests compare sizes and every member offset with
//! what naga computes for the shader).

use bytemuck::{Pod, Zeroable};

/// Mode bits of [`GpuFrame::flags`].
pub mod flags {
    /// One pass of the integrator with the frame's plan, rather than ray casting's
    /// `Lighting::shade`.
    pub const PASS: u32 = 1;
    /// Shadow rays towards every light.
    pub const SHADOWS: u32 = 2;
    /// The scene has a floor.
    pub const FLOOR: u32 = 4;
    /// `mapped_albedo` replaces the kind's colours (a session's colour map).
    pub const COLOR_MAP: u32 = 8;
    /// Sphere lights sampled over their visible cap.
    pub const SOFT_SHADOWS: u32 = 16;
    /// The field is an absorbing volume (`volume`: colour, density).
    pub const VOLUME: u32 = 32;
    /// The clip box cuts the geometry.
    pub const CLIP: u32 = 64;
    /// The scene's further isosurfaces are drawn.
    pub const ISOSURFACES: u32 = 128;
    /// A pixel the driver cut short is written with depth `CUT` (retrace.rs `CUT_DEPTH`) for
    /// the backend to trace again on the CPU; without it such a pixel keeps what it reached.
    pub const MARK_CUT: u32 = 256;
    /// Soft shadows and occlusion take their points from the pixel's rotated R2 sequence
    /// (`geom::rng::Sampling::Stratified`); without it, independent points from its stream.
    pub const STRATIFIED: u32 = 512;
}

/// Light kinds of [`GpuLight::position`]'s `w`.
pub mod light_kind {
    pub const DIRECTIONAL: f32 = 0.0;
    pub const POINT: f32 = 1.0;
    pub const SPHERE: f32 = 2.0;
}

/// [`GpuMetaballParams::finder`]: the metaball root finders the kernel has
/// (`FINDER_*` in metaball_finders.wgsl).
pub mod finder {
    pub const MARCH: u32 = 0;
    pub const SECANT: u32 = 1;
    pub const BEZIER: u32 = 2;
}

/// What one frame needs besides the arrays: camera, background, floor, the plan's effects and
/// counts. The uniform of the kind-independent kernel (`Frame` in common.wgsl).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuFrame {
    /// The camera (`PrimaryRays`, in the scene's local frame): eye, the direction of the
    /// top-left corner, the steps of one pixel right and down, and the view axis (for depth).
    pub eye: [f32; 4],
    pub top_left: [f32; 4],
    pub right_step: [f32; 4],
    pub down_step: [f32; 4],
    pub forward: [f32; 4],
    pub background_top: [f32; 4],
    pub background_bottom: [f32; 4],
    pub ambient: [f32; 4],
    /// The colour map's albedo of the isovalue (with [`flags::COLOR_MAP`]).
    pub mapped_albedo: [f32; 4],
    pub floor_color0: [f32; 4],
    pub floor_color1: [f32; 4],
    /// Where the local frame's origin lies in the world (the floor's checker is the world's).
    pub floor_origin: [f32; 4],
    /// The volume's in-scattered colour (xyz) and density (w).
    pub volume: [f32; 4],
    pub clip_min: [f32; 4],
    pub clip_max: [f32; 4],
    pub isovalue: f32,
    pub width: u32,
    pub height: u32,
    pub flags: u32,
    pub t_max: f32,
    pub light_count: u32,
    pub group_count: u32,
    /// Materials uploaded, the last being the fallback for an index past the scene's.
    pub material_count: u32,
    pub floor_height: f32,
    pub floor_checker: f32,
    pub floor_material: u32,
    /// The refinement pass (seeds the random streams as `PixelRng::new(x, y, pass)`).
    pub pass_index: u32,
    pub reflection_depth: u32,
    pub refraction_depth: u32,
    pub layers: u32,
    pub ao_samples: u32,
    pub light_samples: u32,
    pub occlusion_distance: f32,
    pub isosurface_count: u32,
    pub _pad: u32,
}

/// One further isosurface: its isovalue and material, and `color` (xyz) when its own colour
/// (or the colour map's) replaces the kind's (w = 1).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuIsoSurface {
    pub color: [f32; 4],
    pub isovalue: f32,
    pub material: u32,
    pub _pad0: u32,
    pub _pad1: u32,
}

/// The metaball kind's uniform (`MbParams` in metaballs.wgsl): the kernel as `Σ c_k w^k`
/// (`c_0..c_3` in `kernel`, `c_4` in `kernel_c4`), the root finder's tolerance on hit
/// distances, its step (marching's, or the secant method's largest gap between samples, a
/// fraction of the smallest radius; 0: no gap limit) and which finder it is ([`finder`]).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuMetaballParams {
    pub kernel: [f32; 4],
    pub kernel_c4: f32,
    pub kernel_degree: u32,
    pub tolerance: f32,
    pub step: f32,
    pub node_count: u32,
    pub finder: u32,
    pub _pad1: u32,
    pub _pad2: u32,
}

/// One light: `position` is the direction towards a directional light or the position of a
/// point or sphere light, its `w` the kind ([`light_kind`]); `color`'s `w` a sphere's radius.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuLight {
    pub position: [f32; 4],
    pub color: [f32; 4],
}

/// One material: `diffuse.w` is the specular weight, `emission.w` the shininess,
/// `extra` = (opacity, reflectivity, ior, 0).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuMaterial {
    pub diffuse: [f32; 4],
    pub emission: [f32; 4],
    pub extra: [f32; 4],
}

/// Primitives `first .. first + count` use material `material`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Pod, Zeroable)]
pub struct GpuGroup {
    pub first: u32,
    pub count: u32,
    pub material: u32,
    pub _pad: u32,
}

/// One node of the flattened Fitted BVH, as `tree::flat::Node`: interior nodes point at
/// their first child (the second follows it), leaves at their balls in the leaf-ball array.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuNode {
    pub min: [f32; 3],
    pub first: u32,
    pub max: [f32; 3],
    /// Balls in the leaf (owned then split); 0 for an interior node or an empty leaf.
    pub count: u32,
}

/// One ball: centre and strength; `m0..m2` the rows of the matrix `M` that maps its support
/// to the unit sphere (`s = |M (p - c)|²`), `m0.w` the smallest semi-axis, `m1.w` 1 for an
/// ellipsoid (0: a sphere, `m0.x` = 1/R, traced as the CPU does without the matrix);
/// `color` linear light.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuBall {
    pub center: [f32; 3],
    pub strength: f32,
    pub m0: [f32; 4],
    pub m1: [f32; 4],
    pub m2: [f32; 4],
    pub color: [f32; 4],
}

#[cfg(test)]
mod tests {
    use super::*;
    use std::mem::{align_of, offset_of, size_of};

    #[test]
    fn sizes_and_alignments_are_those_the_shader_expects() {
        assert_eq!(size_of::<GpuFrame>(), 15 * 16 + 20 * 4);
        assert_eq!(size_of::<GpuIsoSurface>(), 32);
        assert_eq!(size_of::<GpuMetaballParams>(), 48);
        assert_eq!(size_of::<GpuLight>(), 32);
        assert_eq!(size_of::<GpuMaterial>(), 48);
        assert_eq!(size_of::<GpuGroup>(), 16);
        assert_eq!(size_of::<GpuNode>(), 32);
        assert_eq!(size_of::<GpuBall>(), 80);
        for (name, size, align) in [
            ("frame", size_of::<GpuFrame>(), align_of::<GpuFrame>()),
            ("light", size_of::<GpuLight>(), align_of::<GpuLight>()),
            (
                "material",
                size_of::<GpuMaterial>(),
                align_of::<GpuMaterial>(),
            ),
            ("group", size_of::<GpuGroup>(), align_of::<GpuGroup>()),
            ("node", size_of::<GpuNode>(), align_of::<GpuNode>()),
            ("ball", size_of::<GpuBall>(), align_of::<GpuBall>()),
            (
                "isosurface",
                size_of::<GpuIsoSurface>(),
                align_of::<GpuIsoSurface>(),
            ),
            (
                "metaball params",
                size_of::<GpuMetaballParams>(),
                align_of::<GpuMetaballParams>(),
            ),
        ] {
            assert_eq!(align, 4, "{name}: plain 4-byte fields, no Rust padding");
            assert_eq!(
                size % 16,
                0,
                "{name}: arrays of it keep WGSL's 16-byte stride"
            );
        }
        // The vec3 + scalar pairs WGSL packs into 16 bytes.
        assert_eq!(offset_of!(GpuNode, first), 12);
        assert_eq!(offset_of!(GpuNode, max), 16);
        assert_eq!(offset_of!(GpuBall, strength), 12);
        assert_eq!(offset_of!(GpuFrame, isovalue), 15 * 16);
    }
}
