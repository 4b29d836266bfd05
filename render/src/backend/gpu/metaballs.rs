//! The metaball kind on the GPU: the Fitted BVH the kernel walks (flattened nodes and
//! leaf-ball indices), the balls, and the kind's uniform (kernel, tolerance, step, finder).
//! The kernel finds roots with the CPU state's finder (Bézier clipping, marching or the
//! secant method, metaball_finders.wgsl); sphere tracing is marched at the default step.

use crate::backend::gpu::kind::{GpuKind, KindUpload};
use crate::backend::gpu::layout::{finder, GpuBall, GpuMetaballParams, GpuNode};
use crate::effects::plan::EffectsPlan;
use crate::kinds::metaballs::engine::PreparedMetaballs;
use crate::kinds::metaballs::roots::RootFinder;
use crate::kinds::metaballs::scene::{MetaballScene, Shape};
use crate::kinds::metaballs::tree::{Tree, TreeKind};
use crate::view::View;
use std::sync::Arc;

/// Most balls the kernel gathers from one leaf (`MAX_GATHER` in the shader).
pub const MAX_GATHER: usize = 192;
/// Deepest tree the kernel's traversal stack holds (`STACK_SIZE` in the shader).
pub const MAX_DEPTH: usize = 63;

/// What the GPU needs of `metaballs` for a frame of `view` with `plan`, or why it cannot
/// trace it: the kernel walks a Fitted BVH with the state's root finder.
pub fn upload<'a>(
    metaballs: &'a Arc<PreparedMetaballs>,
    view: &View,
    plan: Option<&EffectsPlan>,
) -> Result<KindUpload<'a>, String> {
    let isovalue = view.isovalue;
    if !(isovalue > 0.0) || !isovalue.is_finite() {
        return Err(format!("isovalue {isovalue} has no surface"));
    }
    let options = metaballs.options();
    let (finder, step) = gpu_finder(options.finder, options.step);
    // A volume integrates the field through the tree whose leaves hold whole supports.
    let volume = plan.is_some_and(|p| p.volume);
    let tree = if volume {
        metaballs.optical_depth_tree()
    } else {
        metaballs.tree_for(isovalue)
    }
    .ok_or("the GPU walks a Fitted BVH; this state has none")?;
    if tree.kind != TreeKind::Fitted {
        return Err("the GPU walks a Fitted BVH, not the BVH with split metaballs".into());
    }
    check_tree(tree)?;
    let c = metaballs.scene().kernel.w_coefficients();
    let params = GpuMetaballParams {
        kernel: [c[0] as f32, c[1] as f32, c[2] as f32, c[3] as f32],
        kernel_c4: c[4] as f32,
        kernel_degree: metaballs.scene().kernel.w_degree() as u32,
        tolerance: options.tolerance,
        step,
        node_count: tree.nodes.len() as u32,
        finder,
        ..GpuMetaballParams::default()
    };
    let key = (
        Arc::as_ptr(metaballs) as usize,
        tree as *const Tree as usize as u64,
    );
    Ok(KindUpload {
        kind: GpuKind::Metaballs,
        key,
        hold: Arc::clone(metaballs) as Arc<dyn std::any::Any + Send + Sync>,
        params: bytemuck::bytes_of(&params).to_vec(),
        arrays: Box::new(move || {
            let (nodes, leaf_balls) = nodes(tree);
            let balls = balls(metaballs.scene());
            vec![
                bytemuck::cast_slice(&nodes).to_vec(),
                bytemuck::cast_slice(&non_empty(leaf_balls)).to_vec(),
                bytemuck::cast_slice(&non_empty(balls)).to_vec(),
            ]
        }),
    })
}

/// The kernel's finder ([`finder`]) and step for a state prepared with `cpu` at `step`: the
/// same finder, except sphere tracing, which the kernel does not have: it marches (then
/// bisects to the tolerance) at marching's default step, which loses no silhouette pixel
/// against Bézier clipping (docs/accuracy.md). The secant method's infinite step (centre
/// projections only) goes as 0, which the kernel reads as no gap limit.
pub fn gpu_finder(cpu: RootFinder, step: f32) -> (u32, f32) {
    match cpu {
        // Bézier clipping takes no step.
        RootFinder::BezierClipping => (finder::BEZIER, 0.0),
        RootFinder::March => (finder::MARCH, step),
        RootFinder::Secant => (finder::SECANT, if step.is_finite() { step } else { 0.0 }),
        RootFinder::SphereTracing => (finder::MARCH, RootFinder::March.default_step()),
    }
}

fn non_empty<T: Default>(mut v: Vec<T>) -> Vec<T> {
    if v.is_empty() {
        v.push(T::default());
    }
    v
}

/// Checks that the kernel can hold the tree (leaf size, depth).
pub fn check_tree(tree: &Tree) -> Result<(), String> {
    let stats = tree.stats();
    if stats.max_depth > MAX_DEPTH {
        return Err(format!(
            "tree depth {} exceeds the GPU stack of {MAX_DEPTH}",
            stats.max_depth
        ));
    }
    if let Some(n) = tree.nodes.iter().map(|n| n.count as usize).max() {
        if n > MAX_GATHER {
            return Err(format!(
                "a leaf of {n} balls exceeds the GPU's {MAX_GATHER}"
            ));
        }
    }
    Ok(())
}

/// The tree's nodes and leaf-ball indices, as the GPU reads them.
pub fn nodes(tree: &Tree) -> (Vec<GpuNode>, Vec<u32>) {
    let mut nodes: Vec<GpuNode> = tree
        .nodes
        .iter()
        .map(|n| GpuNode {
            min: n.bounds.min.to_array(),
            first: n.first,
            max: n.bounds.max.to_array(),
            count: n.count,
        })
        .collect();
    if nodes.is_empty() {
        nodes.push(GpuNode::default());
    }
    (nodes, tree.balls.clone())
}

/// Every ball of `scene`, as the GPU reads it.
pub fn balls(scene: &MetaballScene) -> Vec<GpuBall> {
    scene
        .balls
        .iter()
        .map(|b| {
            let min_radius = b.min_semi_axis();
            let (m0, m1, m2) = match b.shape {
                Shape::Sphere => (
                    [1.0 / b.radius, 0.0, 0.0, min_radius],
                    [0.0, 1.0 / b.radius, 0.0, 0.0],
                    [0.0, 0.0, 1.0 / b.radius, 0.0],
                ),
                Shape::Ellipsoid { .. } => {
                    // Rows of M (glam stores columns).
                    let m = b.normalizing().transpose();
                    (
                        m.x_axis.extend(min_radius).to_array(),
                        m.y_axis.extend(1.0).to_array(),
                        m.z_axis.extend(0.0).to_array(),
                    )
                }
            };
            GpuBall {
                center: b.center.to_array(),
                strength: b.strength,
                m0,
                m1,
                m2,
                color: b.color.extend(0.0).to_array(),
            }
        })
        .collect()
}
