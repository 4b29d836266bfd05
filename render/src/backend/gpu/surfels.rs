//! The surfel kind on the GPU (`surfels.wgsl`): what a deformed step uploads.
//!
//! How it works: the GPU does no lazy updates. On upload the CPU brings the whole step up to
//! date — every surfel by eq. 1 and every sphere fitted to the deformed surfels below it, the
//! eager refit of [`PreparedSurfels::eager_spheres`] (a step prepared eagerly or rebuilt already
//! has them) — and uploads the spheres with the tree topology, the deformed surfels with
//! what their MLS intersection reads (support, rest radius and colour), the fixed
//! neighbourhoods and the clipping pairs. The kernel walks the spheres and runs the CPU's
//! intersection on them, so it finds the CPU's hits.
//!
//! Cost per step on the CPU (release, this shared 2-core AMD EPYC at load average 4–5.5,
//! so upper bounds; measured with a throwaway program over 9 steps of `surfel-impact`,
//! 153k surfels, 306k spheres): the eager update (eqs. 1, 4, 9, 11 then, in the step's prepare
//! when the auto mode picks eager, else in [`arrays`]) 41–83 ms (the refit now fits spheres
//! to their surfels: 20–40 ms in `isoray-bench surfels`), packing the 34.3 MB of
//! arrays 36–47 ms; the upload stage of a debug build on lavapipe (update, packing and
//! `write_buffer` together) 149 ms. A step is packed once: later passes and frames of the
//! same step reuse what is on the GPU (the key). After a GPU upload has deformed every
//! surfel, the auto mode's heuristic sees a fully touched step and prepares the next
//! steps eagerly (until its share decays below 0.3, one lazy step in about twelve).

use crate::backend::gpu::kind::{GpuKind, KindUpload};
use crate::kinds::surfels::prepared::PreparedSurfels;
use crate::view::View;
use bytemuck::{Pod, Zeroable};
use rayon::prelude::*;
use std::mem::size_of;
use std::sync::Arc;

/// Storage arrays of the surfel kernel: nodes, surfels, neighbours, clip pairs.
pub const ARRAYS: usize = 4;
/// Entries of the kernel's traversal stack (`SURFEL_STACK` in the shader).
pub const STACK: usize = 64;
/// The largest array handed to the kernel: wgpu's default storage binding limit.
pub const MAX_ARRAY_BYTES: usize = 128 << 20;

/// The surfel kernel's uniform (group 1, binding 0).
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuSurfelParams {
    pub node_count: u32,
    pub surfel_count: u32,
    pub mls_iterations: u32,
    pub mls_epsilon: f32,
}

/// One updated sphere of the hierarchy; a leaf has `kids = [LEAF, surfel]`.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuSurfelNode {
    pub centre: [f32; 3],
    pub radius: f32,
    pub kids: [u32; 2],
    pub _pad: [u32; 2],
}

/// One deformed surfel and what its intersection reads.
#[repr(C)]
#[derive(Clone, Copy, Debug, Default, PartialEq, Pod, Zeroable)]
pub struct GpuSurfel {
    pub centre: [f32; 3],
    pub leaf_radius: f32,
    pub t1: [f32; 3],
    /// The rest radius of the disc in tangent coordinates.
    pub radius: f32,
    pub t2: [f32; 3],
    /// The MLS support `h`, grown by the step's stretch as on the CPU.
    pub support: f32,
    pub normal: [f32; 3],
    pub neighbours_first: u32,
    /// Rest colour, linear.
    pub colour: [f32; 3],
    pub clips_first: u32,
    pub neighbours_count: u32,
    pub clips_count: u32,
    /// `1 / h²`, as the CPU computes it.
    pub inv_support2: f32,
    pub _pad: u32,
}

/// What the GPU needs of `prepared`, or why it cannot trace it. The key is the step's
/// address and [`PreparedSurfels::id`], so the arrays are built (and the eager update run)
/// once per step, not per frame or pass.
pub fn upload<'a>(
    prepared: &'a Arc<PreparedSurfels>,
    _view: &View,
) -> Result<KindUpload<'a>, String> {
    let p = prepared;
    let surfels = p.model.len();
    // Every tree of a step (the model's, or one rebuilt over the same surfels) splits at the
    // median, so its depth is the model tree's: ceil(log2 n).
    let levels = p.model.tree.levels();
    if levels + 1 > STACK {
        return Err(format!(
            "a sphere tree of {levels} levels exceeds the GPU stack of {STACK}"
        ));
    }
    let nodes = 2 * surfels.max(1) - 1;
    for (what, bytes) in [
        ("nodes", nodes * size_of::<GpuSurfelNode>()),
        ("surfels", surfels * size_of::<GpuSurfel>()),
        ("neighbours", p.model.neighbours.items.len() * 4),
        ("clip pairs", p.model.clip.items.len() * 8),
    ] {
        if bytes > MAX_ARRAY_BYTES {
            return Err(format!(
                "the surfel {what} take {bytes} bytes, over the GPU's {MAX_ARRAY_BYTES} per array"
            ));
        }
    }
    let params = GpuSurfelParams {
        node_count: if surfels == 0 { 0 } else { nodes as u32 },
        surfel_count: surfels as u32,
        mls_iterations: p.options.mls_iterations,
        mls_epsilon: p.options.mls_epsilon,
    };
    Ok(KindUpload {
        kind: GpuKind::Surfels,
        key: (Arc::as_ptr(prepared) as usize, p.id()),
        hold: Arc::clone(prepared) as Arc<dyn std::any::Any + Send + Sync>,
        params: bytemuck::bytes_of(&params).to_vec(),
        arrays: Box::new(move || arrays(p)),
    })
}

/// The kernel's arrays of step `p`: every sphere and surfel brought up to date first (the
/// eager update), then the neighbour and clip rows as they are (the model's own `u32`s).
pub fn arrays(p: &PreparedSurfels) -> Vec<Vec<u8>> {
    let spheres = p.eager_spheres();
    let nodes = packed(&spheres, |n| GpuSurfelNode {
        centre: n.centre.to_array(),
        radius: n.radius,
        kids: n.kids,
        _pad: [0; 2],
    });
    let ids: Vec<usize> = (0..p.model.len()).collect();
    let surfels = packed(&ids, |&s| gpu_surfel(p, s));
    vec![
        nodes,
        surfels,
        bytes(&p.model.neighbours.items),
        bytes(&p.model.clip.items),
    ]
}

/// `f` of every item, written in parallel straight into one byte array (no intermediate
/// array of structs to copy again).
fn packed<I: Sync, T: Pod>(items: &[I], f: impl Fn(&I) -> T + Sync) -> Vec<u8> {
    let size = size_of::<T>();
    let mut out = vec![0u8; items.len().max(1) * size];
    out.par_chunks_mut(size)
        .zip(items.par_iter())
        .for_each(|(chunk, item)| chunk.copy_from_slice(bytemuck::bytes_of(&f(item))));
    out
}

/// Surfel `s` deformed, with its MLS support grown by the step's stretch exactly as
/// `intersect_leaf` grows it.
fn gpu_surfel(p: &PreparedSurfels, s: usize) -> GpuSurfel {
    let mut fresh = false;
    let d = *p.surfel(s, &mut fresh);
    let m = &p.model;
    let stretch = d.leaf_radius / m.leaf_radius[s].max(1e-20);
    let h = m.support[s] * stretch.max(1e-3);
    let (nb, clip) = (&m.neighbours.start, &m.clip.start);
    GpuSurfel {
        centre: d.centre.to_array(),
        leaf_radius: d.leaf_radius,
        t1: d.t1.to_array(),
        radius: m.surfels[s].radius,
        t2: d.t2.to_array(),
        support: h,
        normal: d.normal.to_array(),
        neighbours_first: nb[s],
        colour: m.surfels[s].colour.to_array(),
        clips_first: clip[s],
        neighbours_count: nb[s + 1] - nb[s],
        clips_count: clip[s + 1] - clip[s],
        inv_support2: 1.0 / (h * h),
        _pad: 0,
    }
}

/// The bytes of `items`, or one zeroed item's if there are none (a binding is never empty).
fn bytes<T: Pod>(items: &[T]) -> Vec<u8> {
    if items.is_empty() {
        return vec![0; size_of::<T>()];
    }
    bytemuck::cast_slice(items).to_vec()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::backend::gpu::kind::GpuKind;

    #[test]
    fn the_seam_binds_as_many_arrays_as_the_upload_makes() {
        assert_eq!(GpuKind::Surfels.arrays(), ARRAYS);
    }
    use crate::backend::gpu::naga_checks::{assert_layout, constant, constant_f32, module_of};
    use crate::kinds::surfels::deform::deform_surfel;
    use crate::kinds::surfels::demo::{self, SurfelDemoKind};
    use crate::kinds::surfels::intersect::{DEFER, OUTWARD, RESCUE_DISC, RESCUE_REACH, ROAM, WIDE};
    use crate::kinds::surfels::prepared::Accel;
    use crate::kinds::surfels::scene::{SurfelOptions, SurfelRuntime, UpdateMode};
    use crate::kinds::surfels::tree::LEAF;
    use wgpu::naga;

    fn module() -> naga::Module {
        module_of(GpuKind::Surfels)
    }

    #[test]
    fn surfel_structs_and_limits_match_the_shader() {
        let m = module();
        assert_layout!(&m, "SurfelParams", GpuSurfelParams; node_count, surfel_count, mls_iterations, mls_epsilon);
        assert_layout!(&m, "SurfelNode", GpuSurfelNode; centre, radius, kids, _pad);
        assert_layout!(&m, "SurfelData", GpuSurfel; centre, leaf_radius, t1, radius, t2, support, normal, neighbours_first, colour, clips_first, neighbours_count, clips_count, inv_support2, _pad);
        assert_eq!(constant(&m, "SURFEL_STACK") as usize, STACK);
        assert_eq!(constant(&m, "SURFEL_LEAF"), LEAF);
        assert_eq!(constant_f32(&m, "SURFEL_WIDE"), WIDE);
        assert_eq!(constant_f32(&m, "SURFEL_DEFER"), DEFER);
        assert_eq!(constant_f32(&m, "SURFEL_ROAM"), ROAM);
        assert_eq!(constant_f32(&m, "SURFEL_OUTWARD"), OUTWARD);
        assert_eq!(constant_f32(&m, "SURFEL_RESCUE_REACH"), RESCUE_REACH);
        assert_eq!(constant_f32(&m, "SURFEL_RESCUE_DISC"), RESCUE_DISC);
        assert_eq!(GpuKind::Surfels.arrays(), ARRAYS);
        for binding in 0..=ARRAYS as u32 {
            let bound = m
                .global_variables
                .iter()
                .any(|(_, v)| v.binding == Some(naga::ResourceBinding { group: 1, binding }));
            assert!(bound, "group 1 binding {binding} in the shader");
        }
    }

    #[test]
    fn a_step_uploads_its_eager_spheres_and_deformed_surfels_once() {
        let d = demo::build(SurfelDemoKind::Heads, 0.03, 4).expect("demo");
        let rt = Arc::new(SurfelRuntime::default());
        let step = |k, mode| {
            let options = SurfelOptions::new(mode, false);
            Arc::new(PreparedSurfels::new(d.scene(k, options, rt.clone())))
        };
        let view = View {
            width: 16,
            height: 12,
            camera: d.camera,
            isovalue: 0.0,
        };
        let (lazy, again, eager) = (
            step(2, UpdateMode::Lazy),
            step(3, UpdateMode::Lazy),
            step(2, UpdateMode::Eager),
        );
        assert_eq!(lazy.used, UpdateMode::Lazy);
        let up = upload(&lazy, &view).expect("traceable");
        assert_eq!(up.kind, GpuKind::Surfels);
        assert_eq!(up.key, upload(&lazy, &view).expect("traceable").key);
        assert_ne!(up.key, upload(&again, &view).expect("traceable").key);
        assert_ne!(up.key, upload(&eager, &view).expect("traceable").key);
        let params: GpuSurfelParams = bytemuck::pod_read_unaligned(&up.params);
        let n = d.model.len();
        assert_eq!(
            (params.node_count, params.surfel_count),
            ((2 * n - 1) as u32, n as u32)
        );
        let arrays = (up.arrays)();
        assert_eq!(arrays.len(), ARRAYS);
        // The lazy step's spheres are the eager step's refit, sphere for sphere.
        let nodes: Vec<GpuSurfelNode> = bytemuck::pod_collect_to_vec(&arrays[0]);
        let Accel::Fixed(tree) = &eager.accel else {
            panic!("an eager step has a fixed tree")
        };
        assert_eq!(nodes.len(), tree.len());
        for (g, t) in nodes.iter().zip(tree) {
            assert_eq!(
                (g.centre, g.radius, g.kids),
                (t.centre.to_array(), t.radius, t.kids)
            );
        }
        // Each surfel as eq. 1 moves it, with its rows of the model's neighbour and clip lists.
        let surfels: Vec<GpuSurfel> = bytemuck::pod_collect_to_vec(&arrays[1]);
        assert_eq!(surfels.len(), n);
        let mut clipped = 0;
        for (s, g) in surfels.iter().enumerate() {
            let want = deform_surfel(&d.model, &lazy.u, &lazy.g, s);
            assert_eq!(
                (g.centre, g.normal),
                (want.centre.to_array(), want.normal.to_array())
            );
            assert_eq!(g.leaf_radius, want.leaf_radius);
            let first = g.neighbours_first as usize;
            let row = &d.model.neighbours.items[first..first + g.neighbours_count as usize];
            assert_eq!(row, d.model.neighbours.row(s));
            assert_eq!(row[0] as usize, s, "a neighbourhood starts with its surfel");
            assert!(g.support > 0.0 && g.inv_support2 == 1.0 / (g.support * g.support));
            clipped += (g.clips_count > 0) as usize;
        }
        assert!(clipped > 0, "the clipped cubes have clipping relations");
        let neighbours: Vec<u32> = bytemuck::pod_collect_to_vec(&arrays[2]);
        assert_eq!(neighbours, d.model.neighbours.items);
        let clips: Vec<[u32; 2]> = bytemuck::pod_collect_to_vec(&arrays[3]);
        assert_eq!(clips, d.model.clip.items);
    }
}
