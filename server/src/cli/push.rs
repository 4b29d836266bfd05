//! `isoray push`: pushes `.npy` files (or raw `ISRA` arrays) to a server as consecutive time
//! steps of a scene, creating the scene first unless one is named. Each file is streamed from
//! disk, never read whole into memory; the server validates it and answers per step. A VTK
//! series (`.vtu` files, or a `.pvd` collection) is a tet scene: see `push_vtu`; molecules
//! (`.pdb`, `.cif`) and particle files (`.csv`, `.xyz` frames, `.npz`) are metaball scenes:
//! see `push_molecule` and `push_points`; point clouds and meshes (`.xyz` points, `.ply`,
//! `.obj`, `.off`) are surfel scenes: see `push_surfels`.

use super::push_args::{create_scene, put_step, step_path, PushArgs};
use isoray_server::api::client::{Body, Client};
use std::time::Instant;

/// Runs the command; the error is what to print.
pub fn run(args: PushArgs) -> Result<(), String> {
    for file in &args.files {
        if !file.is_file() {
            return Err(format!("{}: no such file", file.display()));
        }
    }
    if let Some(dt) = args.time_step {
        if !(dt.is_finite() && dt > 0.0) {
            return Err(format!("--time-step {dt} must be a positive number"));
        }
    }
    if args
        .files
        .iter()
        .any(|f| isoray_render::kinds::metaballs::pdb::is_molecule(f))
    {
        return super::push_molecule::run(&args);
    }
    let points = args
        .files
        .iter()
        .filter(|f| super::points_files::is_points(f))
        .count();
    if points == args.files.len() {
        return super::push_points::run(&args);
    }
    if points > 0 {
        return Err(
            "give either particle files (.csv, .xyz, .npz) or other step files, not both".into(),
        );
    }
    if args
        .files
        .iter()
        .any(|f| super::surfel_files::is_surfel_input(f))
    {
        return super::push_surfels::run(&args);
    }
    let series = args
        .files
        .iter()
        .filter(|f| super::push_vtu::is_vtk_series(f))
        .count();
    if series == args.files.len() {
        return super::push_vtu::run(&args);
    }
    if series > 0 {
        return Err(
            "give either .npy/raw step files or a VTK series (.vtu, .pvd), not both".into(),
        );
    }
    if args.array.is_some() {
        return Err("--array picks a point array of a .vtu series".into());
    }
    let client = Client::new(&args.server).map_err(|e| e.to_string())?;
    let (scene, token) = match (&args.scene, &args.token) {
        (Some(scene), Some(token)) => (scene.clone(), token.clone()),
        (Some(_), None) => {
            return Err("--scene needs --token (or ISORAY_TOKEN): the scene's write token".into())
        }
        (None, _) => create(&client, &args)?,
    };
    let auth = format!("Bearer {token}");
    let started = Instant::now();
    let mut total_bytes = 0u64;
    for (i, file) in args.files.iter().enumerate() {
        let index = args.start + i as u64;
        let content_type = match file.extension().and_then(|e| e.to_str()) {
            Some(e) if e.eq_ignore_ascii_case("npy") => "application/x-npy",
            _ => "application/octet-stream",
        };
        let time = args.time_step.map(|dt| index as f64 * dt);
        let path = step_path(&scene, index, time, args.replace);
        let mut reader =
            std::fs::File::open(file).map_err(|e| format!("{}: {e}", file.display()))?;
        let len = reader
            .metadata()
            .map_err(|e| format!("{}: {e}", file.display()))?
            .len();
        let answer = put_step(
            &client,
            &path,
            &auth,
            content_type,
            Body::Reader(&mut reader, len),
            &format!("step {index} ({})", file.display()),
        )?;
        println!(
            "step {index}: {} ({} rows, checksum {})",
            answer["outcome"].as_str().unwrap_or("?"),
            answer["step"]["primitives"],
            answer["step"]["checksum"].as_str().unwrap_or("?")
        );
        total_bytes += len;
    }
    let secs = started.elapsed().as_secs_f64().max(1e-9);
    println!(
        "pushed {} steps to scene {scene}: {:.1} MB in {secs:.2} s ({:.1} MB/s)",
        args.files.len(),
        total_bytes as f64 / 1e6,
        total_bytes as f64 / 1e6 / secs
    );
    Ok(())
}

fn create(client: &Client, args: &PushArgs) -> Result<(String, String), String> {
    create_scene(client, args, br#"{"kind":"metaballs"}"#)
}
