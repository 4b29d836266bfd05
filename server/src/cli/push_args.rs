//! What `isoray push` and its VTK series path share: the flags, the step path, one step PUT
//! and creating the scene.

use clap::Parser;
use isoray_server::api::client::{Body, Client};
use std::path::PathBuf;

/// Push simulation files to an isoray server as the time steps of a scene.
///
/// Files are pushed in the order given, as steps `--start`, `--start + 1`, ... Without
/// `--scene`, a metaball scene is created first (from `--spec`, a JSON file with the body of
/// `POST /api/v1/scenes`, or `{"kind": "metaballs"}`), and its id and write token are printed.
/// A VTK series (`.vtu` files of tetrahedra, or a `.pvd` collection of them) makes a tet
/// scene: the first file's mesh, then one step per file from a point scalar array; a point
/// cloud or triangle mesh makes a surfel scene, a molecule file a metaball scene of its atoms.
#[derive(Clone, Debug, Parser)]
#[command(name = "isoray push")]
pub struct PushArgs {
    /// The server's base URL.
    #[arg(long, env = "ISORAY_SERVER", default_value = "http://127.0.0.1:8080")]
    pub server: String,
    /// The scene to push to (default: create one).
    #[arg(long)]
    pub scene: Option<String>,
    /// The scene's write token (or the server's admin token). Needed with `--scene`.
    #[arg(long, env = "ISORAY_TOKEN", hide_env_values = true)]
    pub token: Option<String>,
    /// Scene description for a new scene: a JSON file like the body of `POST /api/v1/scenes`.
    #[arg(long, conflicts_with = "scene")]
    pub spec: Option<PathBuf>,
    /// Index of the first file's step.
    #[arg(long, default_value_t = 0)]
    pub start: u64,
    /// Simulation time between consecutive steps (default: each step's time is its index).
    #[arg(long)]
    pub time_step: Option<f64>,
    /// Overwrite steps that exist with different content.
    #[arg(long)]
    pub replace: bool,
    /// The point array of a `.vtu` series to push (default: the first with one component).
    #[arg(long)]
    pub array: Option<String>,
    /// Molecules (.pdb, .cif): keep hydrogen atoms.
    #[arg(long)]
    pub hydrogens: bool,
    /// Molecules: keep waters (HOH, WAT, DOD).
    #[arg(long)]
    pub waters: bool,
    /// Molecules: a ball's support radius over its element's van der Waals radius.
    #[arg(long, default_value_t = 2.0)]
    pub radius_scale: f32,
    /// Point clouds and meshes (.xyz, .ply, .obj, .off): surfels to sample from a mesh
    /// (default 20,000).
    #[arg(long)]
    pub surfels: Option<u64>,
    /// The step files: `.npy` (float32 or float64, shape (rows, columns)), raw arrays with
    /// the 16-byte `ISRA` header (any other extension), a VTK series (`.vtu`, `.pvd`,
    /// `.vtk`), one molecule (`.pdb`, `.cif`: its models are the steps), particle files
    /// (`.csv` with a header naming x, y, z [radius, strength, red, green, blue]; `.xyz`
    /// frames, whose first line is the particle count; `.npz` with the array `positions` and
    /// optional `radius`, `strength`, `color`), or one point cloud or triangle mesh (`.xyz`
    /// of `x y z [nx ny nz]` lines, `.ply`, `.obj`, `.off`: a surfel scene).
    #[arg(required = true)]
    pub files: Vec<PathBuf>,
}

/// `/api/v1/scenes/{scene}/steps/{index}` with its `time` and `replace` query.
pub fn step_path(scene: &str, index: u64, time: Option<f64>, replace: bool) -> String {
    let mut query = Vec::new();
    if let Some(t) = time {
        query.push(format!("time={t}"));
    }
    if replace {
        query.push("replace=true".into());
    }
    format!(
        "/api/v1/scenes/{scene}/steps/{index}{}{}",
        if query.is_empty() { "" } else { "?" },
        query.join("&")
    )
}

/// PUTs one step and returns the server's answer; errors start with `what`.
pub fn put_step(
    client: &Client,
    path: &str,
    auth: &str,
    content_type: &str,
    body: Body<'_>,
    what: &str,
) -> Result<serde_json::Value, String> {
    let r = client
        .request(
            "PUT",
            path,
            &[("Content-Type", content_type), ("Authorization", auth)],
            body,
        )
        .map_err(|e| format!("{what}: {e}"))?;
    if !(r.status == 200 || r.status == 201) {
        return Err(format!(
            "{what}: the server answered {}: {}",
            r.status,
            r.text()
        ));
    }
    r.json().map_err(|e| e.to_string())
}

/// Creates a scene from `--spec`, or from `default` without one; prints and returns its id
/// and write token.
pub fn create_scene(
    client: &Client,
    args: &PushArgs,
    default: &[u8],
) -> Result<(String, String), String> {
    let spec = match &args.spec {
        Some(path) => std::fs::read(path).map_err(|e| format!("{}: {e}", path.display()))?,
        None => default.to_vec(),
    };
    let auth = args.token.as_ref().map(|t| format!("Bearer {t}"));
    let mut headers = vec![("Content-Type", "application/json")];
    if let Some(a) = &auth {
        headers.push(("Authorization", a));
    }
    let r = client
        .request("POST", "/api/v1/scenes", &headers, Body::Bytes(&spec))
        .map_err(|e| e.to_string())?;
    if r.status != 201 {
        return Err(format!(
            "creating the scene: the server answered {}: {}",
            r.status,
            r.text()
        ));
    }
    let created: serde_json::Value = r.json().map_err(|e| e.to_string())?;
    let (Some(id), Some(token)) = (
        created["scene"]["id"].as_str(),
        created["write_token"].as_str(),
    ) else {
        return Err(format!("unexpected answer: {}", r.text()));
    };
    println!("created scene {id}");
    println!("write token {token} (shown once; keep it to push more steps)");
    Ok((id.to_string(), token.to_string()))
}
