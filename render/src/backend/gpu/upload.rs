//! From engine values to the GPU's structs: what a frame can be traced with on the GPU (a
//! metaball state with a Fitted BVH, primary rays and hard shadows), the flattened tree and
//! balls, the lights and materials, and the per-frame uniform.

use crate::backend::gpu::layout::{
    flags, light_kind, GpuBall, GpuFrame, GpuGroup, GpuLight, GpuMaterial, GpuNode,
};
use crate::effects::plan::EffectsPlan;
use crate::integrator::T_MAX;
use crate::kinds::dispatch::PreparedGeometry;
use crate::kinds::metaballs::engine::PreparedMetaballs;
use crate::kinds::metaballs::scene::{MetaballScene, Shape};
use crate::kinds::metaballs::tree::{Tree, TreeKind};
use crate::scene::PreparedScene;
use crate::shade::{Light, Lighting, Material};
use crate::view::View;
use glam::Vec3;
use std::sync::Arc;

/// Most balls the kernel gathers from one leaf (`MAX_GATHER` in the shader).
pub const MAX_GATHER: usize = 192;
/// Deepest tree the kernel's traversal stack holds (`STACK_SIZE` in the shader).
pub const MAX_DEPTH: usize = 63;

/// The metaball state of `scene` and the tree a query at `isovalue` walks, if the GPU can
/// trace them; otherwise why not.
pub fn traceable(
    scene: &PreparedScene,
    isovalue: f32,
) -> Result<(&Arc<PreparedMetaballs>, &Tree), String> {
    let metaballs = match scene.geometry() {
        PreparedGeometry::Metaballs(m) => m,
        PreparedGeometry::Tets(_) => return Err("tetrahedral meshes are traced on the CPU".into()),
        PreparedGeometry::Surfels(_) => return Err("surfels are traced on the CPU".into()),
    };
    if !(isovalue > 0.0) || !isovalue.is_finite() {
        return Err(format!("isovalue {isovalue} has no surface"));
    }
    let tree = metaballs
        .tree_for(isovalue)
        .ok_or("the GPU walks a Fitted BVH; this state has none")?;
    if tree.kind != TreeKind::Fitted {
        return Err("the GPU walks a Fitted BVH, not the BVH with split metaballs".into());
    }
    Ok((metaballs, tree))
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

/// The effects the kernel traces: primary rays, and hard shadows. Anything else in `plan`
/// (reflections, refraction, transparency, occlusion, soft shadows, volumes, the clip box,
/// further isosurfaces) is traced on the CPU for now.
pub fn check_plan(plan: &EffectsPlan) -> Result<(), String> {
    let unsupported = [
        (plan.soft_shadows, "soft shadows"),
        (plan.reflection_depth > 0, "reflections"),
        (plan.refraction_depth > 0, "refraction"),
        (plan.layers > 0, "transparency layers"),
        (plan.ao_samples > 0, "ambient occlusion"),
        (plan.volume, "volumes"),
        (plan.clip_box.is_some(), "the clip box"),
        (plan.isosurfaces, "further isosurfaces"),
    ];
    match unsupported.iter().find(|(on, _)| *on) {
        Some((_, name)) => Err(format!("{name} are not traced on the GPU yet")),
        None => Ok(()),
    }
}

/// The tree's nodes and leaf-ball indices, as the GPU reads them.
pub fn nodes(tree: &Tree) -> (Vec<GpuNode>, Vec<u32>) {
    let nodes = tree
        .nodes
        .iter()
        .map(|n| GpuNode {
            min: n.bounds.min.to_array(),
            first: n.first,
            max: n.bounds.max.to_array(),
            count: n.count,
        })
        .collect();
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

fn material(m: &Material) -> GpuMaterial {
    GpuMaterial {
        diffuse: m.diffuse.extend(m.specular).to_array(),
        emission: m.emission.extend(m.shininess).to_array(),
        extra: [m.opacity, m.reflectivity, m.ior, 0.0],
    }
}

/// Lights, materials (the scene's, then the fallback for an index past them) and groups.
pub fn lighting(l: &Lighting) -> (Vec<GpuLight>, Vec<GpuMaterial>, Vec<GpuGroup>) {
    let lights = l
        .lights
        .iter()
        .map(|light| match *light {
            Light::Directional { to_light, color } => GpuLight {
                position: to_light.extend(light_kind::DIRECTIONAL).to_array(),
                color: color.extend(0.0).to_array(),
            },
            Light::Point { position, color } => GpuLight {
                position: position.extend(light_kind::POINT).to_array(),
                color: color.extend(0.0).to_array(),
            },
            Light::Sphere {
                center,
                radius,
                color,
            } => GpuLight {
                position: center.extend(light_kind::SPHERE).to_array(),
                color: color.extend(radius).to_array(),
            },
        })
        .collect();
    let mut materials: Vec<GpuMaterial> = l.materials.iter().map(material).collect();
    materials.push(material(&Material::default()));
    let groups = l
        .groups
        .iter()
        .map(|g| GpuGroup {
            first: g.first,
            count: g.count,
            material: g.material as u32,
            _pad: 0,
        })
        .collect();
    (lights, materials, groups)
}

/// The frame's uniform. `plan`: `None` for ray casting (`Lighting::shade`), else one pass
/// of the integrator with that plan (already checked by [`check_plan`]).
pub fn frame(
    view: &View,
    lighting: &Lighting,
    metaballs: &PreparedMetaballs,
    node_count: usize,
    plan: Option<&EffectsPlan>,
) -> GpuFrame {
    let [eye, top_left, right_step, down_step, forward] =
        view.camera.rays(view.width, view.height).parts();
    let v4 = |v: Vec3| v.extend(0.0).to_array();
    let c = metaballs.scene().kernel.w_coefficients();
    let mut bits = 0;
    if let Some(plan) = plan {
        bits |= flags::PASS;
        if plan.shadows {
            bits |= flags::SHADOWS;
        }
        if lighting.floor.is_some() {
            bits |= flags::FLOOR;
        }
    }
    let mapped = match &lighting.color_map {
        Some(map) => {
            bits |= flags::COLOR_MAP;
            map.albedo(view.isovalue)
        }
        None => Vec3::ZERO,
    };
    let floor = lighting.floor;
    GpuFrame {
        eye: v4(eye),
        top_left: v4(top_left),
        right_step: v4(right_step),
        down_step: v4(down_step),
        forward: v4(forward),
        background_top: v4(lighting.background_top),
        background_bottom: v4(lighting.background_bottom),
        ambient: v4(lighting.ambient),
        mapped_albedo: v4(mapped),
        kernel: [c[0] as f32, c[1] as f32, c[2] as f32, c[3] as f32],
        floor_color0: v4(floor.map_or(Vec3::ZERO, |f| f.colors[0])),
        floor_color1: v4(floor.map_or(Vec3::ZERO, |f| f.colors[1])),
        kernel_c4: c[4] as f32,
        kernel_degree: metaballs.scene().kernel.w_degree() as u32,
        isovalue: view.isovalue,
        tolerance: metaballs.options().tolerance,
        width: view.width,
        height: view.height,
        flags: bits,
        t_max: T_MAX,
        light_count: lighting.lights.len() as u32,
        group_count: lighting.groups.len() as u32,
        material_count: lighting.materials.len() as u32 + 1,
        node_count: node_count as u32,
        floor_height: floor.map_or(0.0, |f| f.height),
        floor_checker: floor.map_or(0.0, |f| f.checker),
        floor_material: floor.map_or(0, |f| f.material as u32),
        _pad: 0,
    }
}
