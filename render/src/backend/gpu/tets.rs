//! The tet kind on the GPU (`tets.wgsl`): one time step's implicit min–max BVH, its tets in
//! leaf order, its 4-D vertices and per-vertex gradients, as the kernel reads them.
//!
//! How it works: the kernel is the single-ray traversal of
//! [`crate::kinds::tets::traverse`] (isorange culling, the slab test within the best hit so
//! far, the nearer child first, ties to the lower tet index) with the isopolygon of each tet
//! extracted on the fly and intersected by the edge-plane test of
//! [`crate::kinds::tets::march`], and the hit record of [`PreparedTets::hit_record`]. The
//! arrays are the CPU's own, copied: nodes (48 bytes, as [`crate::kinds::tets::bvh::Node`]),
//! the vertex indices and mesh indices of the tets in leaf order, the vertices `{x, y, z, v}`
//! in the scene's frame, and the smoothed gradients (one zero element with faceted normals).
//! A new step is a new [`PreparedTets`]: its address and a fingerprint of its vertices and
//! structure key the arrays, so they are rebuilt and uploaded once per step.

use crate::backend::gpu::kind::{GpuKind, KindUpload};
use crate::backend::gpu::tets_layout::{GpuTetNode, GpuTetParams, MAX_DEPTH};
use crate::kinds::tets::prepared::PreparedTets;
use crate::view::View;
use std::sync::Arc;

/// The step `prepared` ready for the GPU, or why the kernel cannot trace it. The view
/// changes nothing: one tree serves every isovalue (the isorange culling is per query).
pub fn upload<'a>(prepared: &'a Arc<PreparedTets>, _view: &View) -> Result<KindUpload<'a>, String> {
    let bvh = prepared.bvh();
    let depth = bvh.stats().max_depth;
    if depth > MAX_DEPTH {
        return Err(format!(
            "tet BVH depth {depth} exceeds the GPU stack of {MAX_DEPTH}"
        ));
    }
    let (color_lo, color_hi) = prepared.scene().color_range();
    let params = GpuTetParams {
        node_count: bvh.nodes().len() as u32,
        smooth_normals: prepared.vertex_gradients().is_some() as u32,
        color_lo,
        color_hi,
    };
    Ok(KindUpload {
        kind: GpuKind::Tets,
        key: (Arc::as_ptr(prepared) as usize, fingerprint(prepared)),
        hold: Arc::clone(prepared) as Arc<dyn std::any::Any + Send + Sync>,
        params: bytemuck::bytes_of(&params).to_vec(),
        arrays: Box::new(move || arrays(prepared)),
    })
}

/// The five arrays of the kernel, each non-empty.
pub fn arrays(prepared: &PreparedTets) -> Vec<Vec<u8>> {
    let bvh = prepared.bvh();
    let nodes: Vec<GpuTetNode> = bvh
        .nodes()
        .iter()
        .map(|n| GpuTetNode {
            lo: n.lo.to_array(),
            hi: n.hi.to_array(),
            first: n.first,
            count: n.count,
            _pad0: 0,
            _pad1: 0,
        })
        .collect();
    let leaf_tets: &[[u32; 4]] = &bvh.leaf_tets;
    let leaf_ids: &[u32] = &bvh.leaf_ids;
    let verts: Vec<[f32; 4]> = prepared.vertices().iter().map(|v| v.to_array()).collect();
    let gradients: Vec<[f32; 4]> = prepared
        .vertex_gradients()
        .map(|g| g.iter().map(|v| v.extend(0.0).to_array()).collect())
        .unwrap_or_default();
    vec![
        non_empty(bytemuck::cast_slice(&nodes), 48),
        non_empty(bytemuck::cast_slice(leaf_tets), 16),
        non_empty(bytemuck::cast_slice(leaf_ids), 4),
        non_empty(bytemuck::cast_slice(&verts), 16),
        non_empty(bytemuck::cast_slice(&gradients), 16),
    ]
}

/// `bytes`, or one zeroed element of `size` bytes when empty.
fn non_empty(bytes: &[u8], size: usize) -> Vec<u8> {
    if bytes.is_empty() {
        vec![0; size]
    } else {
        bytes.to_vec()
    }
}

/// What the arrays depend on besides the step's address (which a later step may reuse): its
/// vertices and scalars bit for bit, the tree's size, root and leaf order, and the normals.
/// A multiply–rotate mix over 64-bit words (FxHash's), about 0.1 ms for 100k vertices.
fn fingerprint(prepared: &PreparedTets) -> u64 {
    let mut h = 0u64;
    let mut mix = |w: u64| h = (h.rotate_left(5) ^ w).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    let bvh = prepared.bvh();
    mix(bvh.nodes().len() as u64);
    mix(bvh.leaf_ids.as_ptr() as u64);
    mix(prepared.vertex_gradients().is_some() as u64);
    if let Some(root) = bvh.nodes().first() {
        for v in root.lo.to_array().into_iter().chain(root.hi.to_array()) {
            mix(v.to_bits() as u64);
        }
    }
    for v in prepared.vertices() {
        let [x, y, z, w] = v.to_array().map(f32::to_bits);
        mix((x as u64) << 32 | y as u64);
        mix((z as u64) << 32 | w as u64);
    }
    h
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::gpu::naga_checks::{assert_layout, constant, module_of};
    use crate::backend::gpu::tets_layout::ARRAYS;
    use crate::kinds::tets::generate;
    use crate::kinds::tets::march::{CASES, EDGES};
    use crate::kinds::tets::mesh::{signed_volume6, TetMesh, TetScene};
    use crate::kinds::tets::prepared::{Normals, TetOptions};
    use glam::Vec3;
    use std::mem::size_of;
    use wgpu::naga;

    fn module() -> naga::Module {
        module_of(GpuKind::Tets)
    }

    fn u32_of(module: &naga::Module, e: naga::Handle<naga::Expression>) -> u32 {
        match module.global_expressions[e] {
            naga::Expression::Literal(naga::Literal::U32(v)) => v,
            ref other => panic!("not a u32 literal: {other:?}"),
        }
    }

    #[test]
    fn shader_structs_match_the_rust_structs_byte_for_byte() {
        let m = module();
        assert_layout!(&m, "TetParams", GpuTetParams; node_count, smooth_normals, color_lo, color_hi);
        assert_layout!(&m, "TetNode", GpuTetNode; lo, hi, first, count, _pad0, _pad1);
        assert_eq!(size_of::<GpuTetNode>(), 48, "the CPU node's size");
        assert_eq!(
            size_of::<GpuTetParams>() % 16,
            0,
            "a uniform of whole vec4s"
        );
    }

    #[test]
    fn the_shader_tables_and_limits_are_the_cpus() {
        let m = module();
        assert_eq!(constant(&m, "TET_STACK_SIZE") as usize, MAX_DEPTH + 1);
        // The edges' corners, one nibble per edge.
        let (a, b) = (constant(&m, "TET_EDGE_A"), constant(&m, "TET_EDGE_B"));
        for (e, &(ca, cb)) in EDGES.iter().enumerate() {
            assert_eq!(((a >> (4 * e)) & 0xf) as usize, ca, "edge {e}");
            assert_eq!(((b >> (4 * e)) & 0xf) as usize, cb, "edge {e}");
        }
        // The marching-tets cases: count, then the edges, one nibble each.
        let cases = m
            .global_variables
            .iter()
            .find(|(_, g)| g.name.as_deref() == Some("tet_cases"))
            .expect("tet_cases in the shader")
            .1;
        let init = cases.init.expect("an initialiser");
        let packed: Vec<u32> = match &m.global_expressions[init] {
            naga::Expression::Compose { components, .. } => {
                components.iter().map(|&c| u32_of(&m, c)).collect()
            }
            other => panic!("tet_cases = {other:?}"),
        };
        assert_eq!(packed.len(), CASES.len());
        for (case, (&p, &(count, edges))) in packed.iter().zip(&CASES).enumerate() {
            assert_eq!(p & 0xf, count as u32, "case {case}");
            for (i, &e) in edges[..count as usize].iter().enumerate() {
                assert_eq!((p >> (4 + 4 * i)) & 0xf, e as u32, "case {case} vertex {i}");
            }
        }
    }

    fn step(time: f32, normals: Normals) -> Arc<PreparedTets> {
        let mesh = Arc::new(generate::box_mesh(
            [4, 3, 5],
            Vec3::splat(-1.0),
            Vec3::splat(1.0),
            0.2,
            9,
        ));
        let scalars: Vec<f32> = mesh.vertices().iter().map(|p| p.length() + time).collect();
        let scene = TetScene::new(mesh, scalars.into())
            .expect("finite")
            .with_color_range(-1.0, 2.0);
        let options = TetOptions {
            normals,
            ..TetOptions::default()
        };
        Arc::new(PreparedTets::new(scene, options))
    }

    fn view() -> View {
        View {
            width: 16,
            height: 12,
            camera: crate::scenes::DemoScene::TetGyroid.default_camera(),
            isovalue: 0.0,
        }
    }

    #[test]
    fn the_upload_copies_the_step_and_keys_it_by_content() {
        let smooth = step(0.0, Normals::Smooth);
        let up = upload(&smooth, &view()).expect("traceable");
        assert_eq!(up.kind, GpuKind::Tets);
        let params: GpuTetParams = bytemuck::pod_read_unaligned(&up.params);
        let bvh = smooth.bvh();
        assert_eq!(params.node_count as usize, bvh.nodes().len());
        assert_eq!(
            (params.smooth_normals, params.color_lo, params.color_hi),
            (1, -1.0, 2.0)
        );
        let key = up.key;
        let arrays = (up.arrays)();
        assert_eq!(arrays.len(), ARRAYS);
        let nodes: &[GpuTetNode] = bytemuck::cast_slice(&arrays[0]);
        for (g, n) in nodes.iter().zip(bvh.nodes()) {
            assert_eq!(
                (g.lo, g.hi, g.first, g.count),
                (n.lo.to_array(), n.hi.to_array(), n.first, n.count)
            );
        }
        assert_eq!(nodes.len(), bvh.nodes().len());
        let tets: &[[u32; 4]] = bytemuck::cast_slice(&arrays[1]);
        let ids: &[u32] = bytemuck::cast_slice(&arrays[2]);
        let mesh_tets = smooth.scene().mesh().tets();
        assert_eq!((tets.len(), ids.len()), (mesh_tets.len(), mesh_tets.len()));
        for (t, &id) in tets.iter().zip(ids) {
            assert_eq!(
                *t, mesh_tets[id as usize],
                "leaf order and mesh index agree"
            );
        }
        let verts: &[[f32; 4]] = bytemuck::cast_slice(&arrays[3]);
        assert_eq!(verts.len(), smooth.vertices().len());
        let gradients: &[[f32; 4]] = bytemuck::cast_slice(&arrays[4]);
        assert_eq!(gradients.len(), smooth.vertices().len());
        // The same step keeps its key; another step (or the same one rebuilt) has another.
        assert_eq!(upload(&smooth, &view()).expect("traceable").key, key);
        let later = step(0.5, Normals::Smooth);
        assert_ne!(upload(&later, &view()).expect("traceable").key.1, key.1);
        let faceted = step(0.0, Normals::Faceted);
        let up = upload(&faceted, &view()).expect("traceable");
        assert_ne!(up.key.1, key.1);
        let params: GpuTetParams = bytemuck::pod_read_unaligned(&up.params);
        assert_eq!(params.smooth_normals, 0);
        assert_eq!((up.arrays)()[4], vec![0u8; 16], "one zeroed gradient");
    }

    #[test]
    fn a_tree_deeper_than_the_kernels_stack_is_refused() {
        // Tets at doubling distances: each midpoint split peels one off, a chain of ~80.
        let mut vertices = Vec::new();
        let mut tets = Vec::new();
        for k in 0..96 {
            let s = 2f32.powi(k);
            let base = vertices.len() as u32;
            let mut p = [
                Vec3::new(1.0, 0.0, 0.0),
                Vec3::new(2.0, 0.0, 0.0),
                Vec3::new(1.0, 1.0, 0.0),
                Vec3::new(1.0, 0.0, 1.0),
            ]
            .map(|v| v * s);
            if signed_volume6(p) < 0.0 {
                p.swap(0, 1);
            }
            vertices.extend(p);
            tets.push([base, base + 1, base + 2, base + 3]);
        }
        let scalars: Vec<f32> = (0..vertices.len()).map(|i| (i % 2) as f32).collect();
        let mesh = Arc::new(TetMesh::new(vertices, tets).expect("valid"));
        let scene = TetScene::new(mesh, scalars.into()).expect("finite");
        let deep = Arc::new(PreparedTets::new(scene, TetOptions::default()));
        assert!(
            deep.bvh().stats().max_depth > MAX_DEPTH,
            "{:?}",
            deep.bvh().stats()
        );
        let why = upload(&deep, &view()).err().expect("refused");
        assert!(why.contains("depth"), "{why}");
    }
}
