//! `isoray push` of molecules: Protein Data Bank (`.pdb`, `.ent`) and mmCIF (`.cif`) files,
//! read with pdbtbx (`isoray_render::kinds::metaballs::pdb::read_models`), as a metaball
//! scene.
//!
//! Each atom becomes a ball like the Molecule scenes of fitted-bvh-metaballs.txt §6: at the
//! atom's position, with support radius `--radius-scale` (default 2) times the element's
//! van der Waals radius (Bondi; with the Wyvill kernel and the isovalue 0.5 this scene is
//! created with, a lone atom's surface is then its van der Waals sphere) and the element's
//! CPK colour; radii and colours are the engine's own table (`kinds::metaballs::pdb`).
//! Each model of the file is a time step. Hydrogens and waters are left out unless
//! `--hydrogens` / `--waters`. Coordinates are moved so that the first model's centre is the
//! origin (the same shift for every model), and a new scene's camera frames the molecule.

use super::push_args::{create_scene, put_step, step_path, PushArgs};
use isoray_render::kinds::metaballs::pdb::{read_models, MoleculeOptions, Row};
use isoray_server::api::client::{npy_header_f32, Body, Client};

/// A new scene's description: Wyvill balls at isovalue 0.5, the camera framing the first
/// model.
pub fn spec(models: &[Vec<Row>], name: &str) -> String {
    let reach = models[0]
        .iter()
        .map(|r| (r[0] * r[0] + r[1] * r[1] + r[2] * r[2]).sqrt() + r[3])
        .fold(1.0f32, f32::max);
    let distance = 2.6 * reach;
    serde_json::json!({
        "kind": "metaballs",
        "name": name,
        "isovalue": 0.5,
        "camera": {"eye": [0.0, 0.0, distance], "target": [0.0, 0.0, 0.0]},
    })
    .to_string()
}

/// Pushes a molecule file's models as steps of a metaball scene.
pub fn run(args: &PushArgs) -> Result<(), String> {
    let [file] = args.files.as_slice() else {
        return Err("give one molecule file (.pdb or .cif); its models become the steps".into());
    };
    let opts = MoleculeOptions {
        hydrogens: args.hydrogens,
        waters: args.waters,
        radius_scale: args.radius_scale,
    };
    if !(opts.radius_scale.is_finite() && opts.radius_scale > 0.0) {
        return Err(format!(
            "--radius-scale {} must be positive",
            opts.radius_scale
        ));
    }
    let models = read_models(file, opts)?;
    let client = Client::new(&args.server).map_err(|e| e.to_string())?;
    let (scene, token) = match (&args.scene, &args.token) {
        (Some(scene), Some(token)) => (scene.clone(), token.clone()),
        (Some(_), None) => {
            return Err("--scene needs --token (or ISORAY_TOKEN): the scene's write token".into())
        }
        (None, _) => {
            let stem = file
                .file_stem()
                .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
            create_scene(&client, args, spec(&models, &stem).as_bytes())?
        }
    };
    let auth = format!("Bearer {token}");
    for (i, rows) in models.iter().enumerate() {
        let index = args.start + i as u64;
        let mut body = npy_header_f32(rows.len() as u64, 8);
        body.extend(rows.iter().flatten().flat_map(|v| v.to_le_bytes()));
        let time = args.time_step.map(|dt| index as f64 * dt);
        let answer = put_step(
            &client,
            &step_path(&scene, index, time, args.replace),
            &auth,
            "application/x-npy",
            Body::Bytes(&body),
            &format!("model {} ({})", i + 1, file.display()),
        )?;
        println!(
            "step {index}: {} (model {}, {} atoms, checksum {})",
            answer["outcome"].as_str().unwrap_or("?"),
            i + 1,
            rows.len(),
            answer["step"]["checksum"].as_str().unwrap_or("?")
        );
    }
    println!("pushed {} models to scene {scene}", models.len());
    Ok(())
}
