//! From engine values to the GPU's structs, for every kind: what a frame can be traced with
//! on the GPU (the kind's data through [`kind_upload`], a plan whose rays fit the kernel's
//! stack), the lights, materials and isosurfaces, and the per-frame uniform.

use crate::backend::gpu::kind::KindUpload;
use crate::backend::gpu::layout::{
    flags, light_kind, GpuFrame, GpuGroup, GpuIsoSurface, GpuLight, GpuMaterial,
};
use crate::backend::gpu::{metaballs, surfels, tets};
use crate::effects::plan::EffectsPlan;
use crate::geom::rng::Sampling;
use crate::integrator::T_MAX;
use crate::kinds::dispatch::PreparedGeometry;
use crate::scene::PreparedScene;
use crate::shade::{Light, Lighting, Material};
use crate::view::View;
use glam::Vec3;

pub use crate::backend::gpu::metaballs::{MAX_DEPTH, MAX_GATHER};

/// Rays the kernel's integrator keeps waiting (`RAY_STACK` in common.wgsl).
pub const RAY_STACK: usize = 24;

/// The kind's data of `scene` for a frame of `view` (`plan`: `None` for ray casting), or why
/// the GPU cannot trace it.
pub fn kind_upload<'a>(
    scene: &'a PreparedScene,
    view: &View,
    plan: Option<&EffectsPlan>,
) -> Result<KindUpload<'a>, String> {
    match scene.geometry() {
        PreparedGeometry::Metaballs(m) => metaballs::upload(m, view, plan),
        PreparedGeometry::Tets(t) => tets::upload(t, view),
        PreparedGeometry::Surfels(s) => surfels::upload(s, view),
    }
}

/// Whether the kernel traces `plan`: its ray stack must hold every ray the plan can have
/// waiting (a path of `d` bounces and `l` layers leaves at most two siblings per step on
/// the stack), and the plan must avoid the combinations where the GPU and the CPU images
/// still disagree on the demos (issue 12): none now. Refraction with shadows through
/// transparent layers (Glass) and occlusion with further isosurfaces through layers (the tet
/// gyroid) disagreed because lavapipe's shared loop budget ended the loops of heavy 8-pixel
/// groups early; the kernel marks those pixels (`flags::MARK_CUT`) and the backend traces
/// them again on the CPU ([`crate::backend::gpu::retrace`]).
/// The clip box is traced on the GPU: its disagreement on Shells was the finders' (the
/// kernel marched where the CPU clips), gone since the kernel uses the CPU state's finder.
pub fn check_plan(plan: &EffectsPlan) -> Result<(), String> {
    let path = plan.reflection_depth.max(plan.refraction_depth) as usize + plan.layers as usize;
    if 2 * path + 1 > RAY_STACK {
        return Err(format!(
            "{} bounces and {} layers can leave more rays waiting than the GPU's {RAY_STACK}",
            plan.reflection_depth.max(plan.refraction_depth),
            plan.layers
        ));
    }
    Ok(())
}

fn material(m: &Material) -> GpuMaterial {
    GpuMaterial {
        diffuse: m.diffuse.extend(m.specular).to_array(),
        emission: m.emission.extend(m.shininess).to_array(),
        extra: [m.opacity, m.reflectivity, m.ior, 0.0],
    }
}

/// The arrays of bind group 0 besides the output: lights, materials (the scene's, then the
/// fallback for an index past them), groups and further isosurfaces (each with its own
/// colour, or the colour map's of its isovalue, when one replaces the kind's).
pub struct LightingArrays {
    pub lights: Vec<GpuLight>,
    pub materials: Vec<GpuMaterial>,
    pub groups: Vec<GpuGroup>,
    pub isosurfaces: Vec<GpuIsoSurface>,
}

pub fn lighting(l: &Lighting) -> LightingArrays {
    let mut lights: Vec<GpuLight> = l
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
    let mut groups: Vec<GpuGroup> = l
        .groups
        .iter()
        .map(|g| GpuGroup {
            first: g.first,
            count: g.count,
            material: g.material as u32,
            _pad: 0,
        })
        .collect();
    let mut isosurfaces: Vec<GpuIsoSurface> = l
        .isosurfaces
        .iter()
        .map(|s| {
            let color = match &l.color_map {
                Some(map) => Some(map.albedo(s.isovalue)),
                None => s.color,
            };
            GpuIsoSurface {
                color: color.map_or([0.0; 4], |c| c.extend(1.0).to_array()),
                isovalue: s.isovalue,
                material: s.material as u32,
                ..GpuIsoSurface::default()
            }
        })
        .collect();
    // Storage bindings may not be empty.
    if lights.is_empty() {
        lights.push(GpuLight::default());
    }
    if groups.is_empty() {
        groups.push(GpuGroup::default());
    }
    if isosurfaces.is_empty() {
        isosurfaces.push(GpuIsoSurface::default());
    }
    LightingArrays {
        lights,
        materials,
        groups,
        isosurfaces,
    }
}

/// The frame's uniform. `plan`: `None` for ray casting (`Lighting::shade`), else pass `pass`
/// of the integrator with that plan (already checked by [`check_plan`]).
pub fn frame(
    scene: &PreparedScene,
    view: &View,
    plan: Option<&EffectsPlan>,
    pass: u32,
) -> GpuFrame {
    let lighting = scene.lighting_in_frame();
    let [eye, top_left, right_step, down_step, forward] = scene
        .primary_rays(&view.camera, view.width, view.height)
        .parts();
    let v4 = |v: Vec3| v.extend(0.0).to_array();
    let mut bits = 0;
    let mut effects = GpuFrame::default();
    if let Some(plan) = plan {
        // The backend traces the pixels the driver cut short again (retrace.rs).
        bits |= flags::PASS | flags::MARK_CUT;
        if plan.shadows {
            bits |= flags::SHADOWS;
        }
        if plan.soft_shadows {
            bits |= flags::SOFT_SHADOWS;
        }
        if plan.sampling == Sampling::Stratified {
            bits |= flags::STRATIFIED;
        }
        if plan.isosurfaces {
            bits |= flags::ISOSURFACES;
        }
        if let (true, Some(volume)) = (plan.volume, lighting.volume) {
            bits |= flags::VOLUME;
            effects.volume = volume.color.extend(volume.density).to_array();
        }
        if let Some(clip) = &plan.clip_box {
            bits |= flags::CLIP;
            effects.clip_min = v4(clip.min);
            effects.clip_max = v4(clip.max);
        }
        effects.reflection_depth = plan.reflection_depth;
        effects.refraction_depth = plan.refraction_depth;
        effects.layers = plan.layers;
        effects.ao_samples = plan.ao_samples;
        effects.light_samples = plan.light_samples;
    }
    // Scene geometry, drawn by ray casting too.
    if lighting.floor.is_some() {
        bits |= flags::FLOOR;
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
        floor_color0: v4(floor.map_or(Vec3::ZERO, |f| f.colors[0])),
        floor_color1: v4(floor.map_or(Vec3::ZERO, |f| f.colors[1])),
        floor_origin: v4(scene.frame().origin.as_vec3()),
        isovalue: view.isovalue,
        width: view.width,
        height: view.height,
        flags: bits,
        t_max: T_MAX,
        light_count: lighting.lights.len() as u32,
        group_count: lighting.groups.len() as u32,
        material_count: lighting.materials.len() as u32 + 1,
        floor_height: floor.map_or(0.0, |f| f.height),
        floor_checker: floor.map_or(0.0, |f| f.checker),
        floor_material: floor.map_or(0, |f| f.material as u32),
        pass_index: pass,
        occlusion_distance: lighting.occlusion_distance,
        isosurface_count: lighting.isosurfaces.len() as u32,
        ..effects
    }
}
