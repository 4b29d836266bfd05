//! The trace kernels' entry point, checked by naga in unit tests (no device needed): every
//! kind's kernel (common.wgsl + the kind's part, [`GpuKind::kernel`]) parses and validates,
//! and the structs have the sizes and member offsets of the Rust structs in
//! [`crate::backend::gpu::layout`].
//!
//! [`GpuKind::kernel`]: crate::backend::gpu::kind::GpuKind::kernel

/// The kernel's entry point.
pub const ENTRY: &str = "trace";

/// Pixels per workgroup along x and y (`@workgroup_size(8, 8, 1)` in the source).
pub const WORKGROUP: u32 = 8;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::gpu::kind::GpuKind;
    use crate::backend::gpu::layout::{
        GpuBall, GpuFrame, GpuGroup, GpuIsoSurface, GpuLight, GpuMaterial, GpuMetaballParams,
        GpuNode,
    };
    use crate::backend::gpu::naga_checks::{assert_layout, constant, module_of};
    use wgpu::naga;

    fn module() -> naga::Module {
        module_of(GpuKind::Metaballs)
    }

    #[test]
    fn every_kind_kernel_parses_and_validates() {
        for kind in GpuKind::ALL {
            let module = module_of(kind);
            let source = kind.kernel();
            naga::valid::Validator::new(
                naga::valid::ValidationFlags::all(),
                naga::valid::Capabilities::empty(),
            )
            .validate(&module)
            .unwrap_or_else(|e| panic!("{}: {}", kind.name(), e.emit_to_string(&source)));
            let entry = module
                .entry_points
                .iter()
                .find(|e| e.name == ENTRY)
                .expect("the entry point");
            assert_eq!(entry.stage, naga::ShaderStage::Compute);
            assert_eq!(entry.workgroup_size, [WORKGROUP, WORKGROUP, 1]);
        }
    }

    #[test]
    fn shader_limits_are_the_ones_the_upload_checks() {
        use crate::backend::gpu::upload::{MAX_DEPTH, MAX_GATHER, RAY_STACK};
        use crate::kinds::metaballs::bezier::ITERATION_CAP;
        let m = module();
        assert_eq!(constant(&m, "MAX_GATHER") as usize, MAX_GATHER);
        assert_eq!(constant(&m, "STACK_SIZE") as usize, MAX_DEPTH + 1);
        assert_eq!(constant(&m, "ITERATION_CAP"), ITERATION_CAP);
        assert_eq!(constant(&m, "RAY_STACK") as usize, RAY_STACK);
        use crate::backend::gpu::layout::finder;
        assert_eq!(constant(&m, "FINDER_MARCH"), finder::MARCH);
        assert_eq!(constant(&m, "FINDER_SECANT"), finder::SECANT);
        assert_eq!(constant(&m, "FINDER_BEZIER"), finder::BEZIER);
        use crate::kinds::metaballs::bezier::{MAX_DEGREE, MAX_PENDING_HALVES};
        assert_eq!(constant(&m, "CONTROL_POINTS") as usize, MAX_DEGREE + 1);
        assert_eq!(
            constant(&m, "MAX_PENDING_HALVES") as usize,
            MAX_PENDING_HALVES
        );
    }

    #[test]
    fn shader_structs_match_the_rust_structs_byte_for_byte() {
        let m = module();
        assert_layout!(&m, "Frame", GpuFrame; eye, top_left, right_step, down_step, forward, background_top, background_bottom, ambient, mapped_albedo, floor_color0, floor_color1, floor_origin, volume, clip_min, clip_max, isovalue, width, height, flags, t_max, light_count, group_count, material_count, floor_height, floor_checker, floor_material, pass_index, reflection_depth, refraction_depth, layers, ao_samples, light_samples, occlusion_distance, isosurface_count, _pad);
        assert_layout!(&m, "Light", GpuLight; position, color);
        assert_layout!(&m, "Material", GpuMaterial; diffuse, emission, extra);
        assert_layout!(&m, "Group", GpuGroup; first, count, material, _pad);
        assert_layout!(&m, "Node", GpuNode; min, first, max, count);
        assert_layout!(&m, "Ball", GpuBall; center, strength, m0, m1, m2, color);
        assert_layout!(&m, "IsoSurface", GpuIsoSurface; color, isovalue, material, _pad0, _pad1);
        assert_layout!(&m, "MbParams", GpuMetaballParams; kernel, kernel_c4, kernel_degree, tolerance, step, node_count, finder, _pad1, _pad2);
    }
}
