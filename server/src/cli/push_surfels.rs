//! `isoray push` of a point cloud or triangle mesh: a surfel scene. The file is read here
//! (`surfel_files`), simulation nodes are laid on a lattice around the object, and the
//! server gets the points (normals estimated there when the file has none) or the mesh (it
//! samples it into surfels), checks them and builds the hierarchy; then step 0, the nodes at
//! rest, is pushed so the scene shows the object. Later steps are node positions, pushed as
//! `.npy` or raw files with `--scene`.

use super::push_args::{create_scene, put_step, step_path, PushArgs};
use super::surfel_files::{read, SurfelInput};
use glam::Vec3;
use isoray_render::kinds::surfels::input::{nodes_for, sample_mesh};
use isoray_server::api::client::{Body, Client};
use serde_json::{json, Value};

/// Simulation nodes laid around a pushed object (the paper's Armadillo has about 450).
const NODES: usize = 450;

fn vec(p: &[f64; 3]) -> Vec3 {
    Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32)
}

/// Runs the command for one point cloud or mesh file.
pub fn run(args: &PushArgs) -> Result<(), String> {
    let [file] = &args.files[..] else {
        return Err("push one point cloud or mesh at a time".into());
    };
    if args.scene.is_some() {
        return Err("a point cloud or mesh creates a new surfel scene; leave out --scene".into());
    }
    let input = read(file)?;
    // The points the nodes are laid around: the cloud, or samples of the mesh (its vertices
    // where it cannot be sampled: the server then names what is wrong with it).
    let points: Vec<Vec3> = match &input {
        SurfelInput::Points { positions, .. } => positions.iter().map(vec).collect(),
        SurfelInput::Mesh {
            vertices,
            triangles,
        } => {
            let v: Vec<Vec3> = vertices.iter().map(vec).collect();
            sample_mesh(&v, triangles, 5000, 1).map_or(v, |(p, _)| p)
        }
    };
    let finite: Vec<Vec3> = points.into_iter().filter(|p| p.is_finite()).collect();
    let nodes = nodes_for(&finite, NODES);
    let mut surfels = json!({"nodes": nodes.iter().map(|p| p.to_array()).collect::<Vec<_>>()});
    match input {
        SurfelInput::Points { positions, normals } => {
            surfels["points"] = json!({"positions": positions, "normals": normals});
        }
        SurfelInput::Mesh {
            vertices,
            triangles,
        } => {
            surfels["mesh"] =
                json!({"vertices": vertices, "triangles": triangles, "count": args.surfels});
        }
    }
    let mut spec: Value = match &args.spec {
        Some(path) => {
            let text = std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?;
            serde_json::from_slice(&text).map_err(|e| format!("{}: {e}", path.display()))?
        }
        None => json!({"name": file.file_name().and_then(|n| n.to_str()).unwrap_or("surfels")}),
    };
    if !spec.is_object() {
        return Err("--spec must hold a JSON object".into());
    }
    spec["kind"] = json!("surfels");
    spec["surfels"] = surfels;
    if spec.get("camera").is_none() {
        if let Some((lo, hi)) = bounds(&finite) {
            let centre = 0.5 * (lo + hi);
            let size = (hi - lo).length().max(1e-3);
            let eye = centre + Vec3::new(0.25, 0.35, 1.6) * size;
            spec["camera"] = json!({"eye": eye.to_array(), "target": centre.to_array()});
        }
    }
    let client = Client::new(&args.server).map_err(|e| e.to_string())?;
    let body = serde_json::to_vec(&spec).map_err(|e| e.to_string())?;
    let args_spec = PushArgs {
        spec: None,
        ..args.clone()
    };
    let (scene, token) = create_scene(&client, &args_spec, &body)?;
    let step = json!({"positions": nodes.iter().map(|p| p.to_array()).collect::<Vec<_>>()});
    let answer = put_step(
        &client,
        &step_path(&scene, args.start, None, args.replace),
        &format!("Bearer {token}"),
        "application/json",
        Body::Bytes(step.to_string().as_bytes()),
        "step 0 (the nodes at rest)",
    )?;
    println!(
        "step {}: {} ({} nodes); push node positions (N, 3) to deform it",
        args.start,
        answer["outcome"].as_str().unwrap_or("?"),
        nodes.len()
    );
    Ok(())
}

fn bounds(points: &[Vec3]) -> Option<(Vec3, Vec3)> {
    let first = *points.first()?;
    Some(
        points
            .iter()
            .fold((first, first), |(a, b), p| (a.min(*p), b.max(*p))),
    )
}
