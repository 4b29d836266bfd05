//! `isoray push` of particle files as metaball steps: CSV (`.csv`), XYZ (`.xyz`) and NumPy
//! archives (`.npz`), read by [`super::points_files`] (which says what each may hold); the
//! steps go to a new metaball scene, or to `--scene`, as `.npy` steps in order.

use super::points_files::read_steps;
use super::push_args::{create_scene, put_step, step_path, PushArgs};
use isoray_server::api::client::{npy_header_f32, Body, Client};

/// Pushes particle files as the steps of a metaball scene, in order (an XYZ file's frames and
/// an NPZ's `(S, N, 3)` steps one after the other).
pub fn run(args: &PushArgs) -> Result<(), String> {
    if args.array.is_some() {
        return Err("--array picks a point array of a .vtu series".into());
    }
    let mut steps = Vec::new();
    for file in &args.files {
        let read = read_steps(file)?;
        println!(
            "{}: {} step{} of {} particles",
            file.display(),
            read.len(),
            if read.len() == 1 { "" } else { "s" },
            read.first()
                .map_or(0, |s| s.values.len() / s.columns as usize)
        );
        steps.extend(read.into_iter().map(|s| (file, s)));
    }
    let client = Client::new(&args.server).map_err(|e| e.to_string())?;
    let (scene, token) = match (&args.scene, &args.token) {
        (Some(scene), Some(token)) => (scene.clone(), token.clone()),
        (Some(_), None) => {
            return Err("--scene needs --token (or ISORAY_TOKEN): the scene's write token".into())
        }
        (None, _) => create_scene(&client, args, br#"{"kind":"metaballs"}"#)?,
    };
    let auth = format!("Bearer {token}");
    for (i, (file, step)) in steps.iter().enumerate() {
        let index = args.start + i as u64;
        let rows = step.values.len() as u64 / u64::from(step.columns);
        let mut payload = npy_header_f32(rows, step.columns);
        payload.extend(step.values.iter().flat_map(|v| v.to_le_bytes()));
        let time = args.time_step.map(|dt| index as f64 * dt);
        let answer = put_step(
            &client,
            &step_path(&scene, index, time, args.replace),
            &auth,
            "application/x-npy",
            Body::Bytes(&payload),
            &format!("step {index} ({})", file.display()),
        )?;
        println!(
            "step {index}: {} ({rows} balls, {} columns, checksum {})",
            answer["outcome"].as_str().unwrap_or("?"),
            step.columns,
            answer["step"]["checksum"].as_str().unwrap_or("?")
        );
    }
    println!("pushed {} steps to scene {scene}", steps.len());
    Ok(())
}
