//! `isoray render`: one image of a scene, offline: no server, no network. The scene is a
//! description (the JSON body of `POST /api/v1/scenes`) plus one step file, or a built-in
//! demo at a time. Step files go through the same validating parsers as pushed steps, and the
//! image is the one the server's `POST /api/v1/scenes/{id}/render` gives for the same scene,
//! step, camera, isovalue, size and effects (a test compares them byte for byte).

use clap::Parser;
use isoray_protocol::api::{ApiCamera, CreateScene, JsonStep};
use isoray_protocol::effects::EffectChanges;
use isoray_protocol::Codec;
use isoray_render::kinds::metaballs::pdb::{is_molecule, read_models, MoleculeOptions};
use isoray_render::scene::Geometry;
use isoray_render::scenes::DemoScene;
use isoray_render::{Backend, Camera, Scene, View};
use isoray_server::api::client::npy_header_f32;
use isoray_server::body::BodyReader;
use isoray_server::effects::EffectLimits;
use isoray_server::frame::{self, FrameRequest, Pass};
use isoray_server::kinds::convert;
use isoray_server::kinds::SceneSetup;
use isoray_server::scenes::prepared::PreparedState;
use isoray_server::store::format::{verify_payload, StepHeader, HEADER_LEN};
use isoray_server::store::ingest::{ingest_json, ingest_npy, ingest_raw, IngestLimits, Target};
use isoray_server::style::{self, SceneLook};
use std::path::{Path, PathBuf};
use std::sync::Arc;

/// Render one image of a scene file, offline.
///
/// Either a step file (`.npy`, a JSON step `.json`, a store `.step` file, a raw `ISRA`
/// array, or a molecule: `.pdb`, `.ent`, `.cif`) with an optional scene description
/// (`--spec`), or a built-in demo (`--demo ID`).
/// The output's extension picks PNG or JPEG.
#[derive(Debug, Parser)]
#[command(name = "isoray render")]
pub struct RenderArgs {
    /// The step to show.
    #[arg(required_unless_present = "demo", conflicts_with = "demo")]
    pub step: Option<PathBuf>,
    /// Scene description: a JSON file like the body of `POST /api/v1/scenes` (default:
    /// `{"kind": "metaballs"}`).
    #[arg(long, conflicts_with = "demo")]
    pub spec: Option<PathBuf>,
    /// A built-in demo scene instead of a step file (e.g. `blobs`).
    #[arg(long)]
    pub demo: Option<String>,
    /// Which model of a molecule file to show (the first is 1).
    #[arg(long, default_value_t = 1, conflicts_with = "demo")]
    pub model: usize,
    /// Time of the demo scene, seconds, in [0, 1e9].
    #[arg(long, default_value_t = 0.0, requires = "demo")]
    pub time: f64,
    /// Where to write the image: `.png`, `.jpg` or `.jpeg` (or `.npy`).
    #[arg(long, short)]
    pub output: PathBuf,
    /// `png`, `jpeg`, or `npy` (an `(H, W, 4)` float32 array of hit distance and outward
    /// normal per pixel, infinity for a miss); default: from the output's extension.
    #[arg(long)]
    pub format: Option<String>,
    #[arg(long, default_value_t = 640)]
    pub width: u32,
    #[arg(long, default_value_t = 480)]
    pub height: u32,
    /// Isovalue, inside the scene's range (default: the scene's).
    #[arg(long, allow_hyphen_values = true)]
    pub isovalue: Option<f64>,
    /// Camera position `x,y,z` (default: the scene's camera).
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub eye: Option<[f64; 3]>,
    /// Point the camera looks at, `x,y,z`.
    #[arg(long, value_parser = parse_vec3, allow_hyphen_values = true)]
    pub target: Option<[f64; 3]>,
    /// Vertical field of view in degrees.
    #[arg(long, allow_hyphen_values = true)]
    pub fov: Option<f64>,
    /// Effect changes over the scene's own and a viewer's look (`clip`, `surfaces`,
    /// `color_map`), as JSON (as in the `effects` websocket message), e.g. `{"shadows": true}`.
    #[arg(long)]
    pub effects: Option<String>,
    /// JPEG quality, 1–100.
    #[arg(long, default_value_t = 90)]
    pub quality: u8,
    /// Passes to average, 1–4096: soft shadows and occlusion get that many samples a pixel
    /// and the image is antialiased over that many sub-pixel positions.
    #[arg(long, default_value_t = 1)]
    pub passes: u32,
    /// Render threads (0: one per core), at most 1024.
    #[arg(long, default_value_t = 0)]
    pub threads: usize,
}

fn parse_vec3(s: &str) -> Result<[f64; 3], String> {
    let v: Vec<f64> = s
        .split(',')
        .map(|p| p.trim().parse::<f64>())
        .collect::<Result<_, _>>()
        .map_err(|e| format!("`{s}`: {e}; expected x,y,z"))?;
    <[f64; 3]>::try_from(v).map_err(|_| format!("`{s}`: expected three numbers x,y,z"))
}

/// What was loaded: the scene state and what a viewer starts with.
struct Loaded {
    scene: Scene,
    camera: Camera,
    isovalue: f32,
    /// The isovalue slider's range (a colour map's default range).
    slider: (f32, f32),
}

/// Runs the command; the error is what to print.
pub fn run(args: RenderArgs) -> Result<(), String> {
    let loaded = loaded(&args)?;
    let camera = camera(&args, loaded.camera)?;
    let has_field = !matches!(loaded.scene.geometry, Geometry::Surfels(_));
    let isovalue = match args.isovalue {
        Some(v) => convert::isovalue(v, loaded.scene.isovalue_range(), has_field, "--isovalue")
            .map_err(|e| e.message)?,
        None => loaded.isovalue,
    };
    for (name, v) in [("--width", args.width), ("--height", args.height)] {
        if !(1..=16384).contains(&v) {
            return Err(format!("{name} {v} must be in 1..=16384"));
        }
    }
    let changes: Option<EffectChanges> = match &args.effects {
        Some(text) => Some(serde_json::from_str(text).map_err(|e| format!("--effects: {e}"))?),
        None => None,
    };
    let scene_look = SceneLook {
        lighting: &loaded.scene.lighting,
        has_field,
        isovalue_range: loaded.scene.isovalue_range(),
        slider: loaded.slider,
    };
    let (fx, style) = style::one_shot(&scene_look, changes.as_ref(), &EffectLimits::ENGINE)
        .map_err(|e| format!("--effects: {}: {}", e.field, e.message))?;
    let format = format(&args)?;
    let backend = Backend::cpu(args.threads).map_err(|e| e.to_string())?;
    let state = PreparedState {
        prepared: Arc::new(loaded.scene).prepare(),
        update_us: 0,
        build_us: 0,
        step_time: None,
    };
    let view = View {
        width: args.width,
        height: args.height,
        camera,
        isovalue,
    };
    let codec = match format {
        Format::Png => Codec::Png,
        Format::Jpeg => Codec::Jpeg,
        Format::Npy => Codec::Png,
    };
    let bytes = if let Format::Npy = format {
        frame::surface_npy(&backend, &state, &view, &fx, Some(&style))
    } else {
        let request = FrameRequest {
            style: Some(&style),
            pass: match args.passes {
                1 => Pass::Single,
                n => Pass::Accumulate(n),
            },
            ..FrameRequest::image(view, &fx, codec, args.quality)
        };
        frame::render(&backend, &state, &request, None)
            .map_err(|e| e.to_string())?
            .payload
    };
    std::fs::write(&args.output, bytes).map_err(|e| format!("{}: {e}", args.output.display()))?;
    println!(
        "wrote {} ({}×{})",
        args.output.display(),
        args.width,
        args.height
    );
    Ok(())
}

/// The scene `args` name: a demo at `--time`, or a step file.
fn loaded(args: &RenderArgs) -> Result<Loaded, String> {
    Ok(match &args.demo {
        Some(id) => {
            let demo = DemoScene::ALL
                .iter()
                .copied()
                .find(|d| d.id() == id)
                .ok_or_else(|| {
                    let ids: Vec<&str> = DemoScene::ALL.iter().map(|d| d.id()).collect();
                    format!("no demo `{id}`; the demos are {}", ids.join(", "))
                })?;
            convert::scene_time(args.time, "--time").map_err(|e| e.message)?;
            Loaded {
                scene: demo.state_at(args.time),
                camera: demo.default_camera(),
                isovalue: demo.default_isovalue(),
                slider: demo.isovalue_slider(),
            }
        }
        None => {
            let step = args
                .step
                .as_deref()
                .ok_or("a step file or --demo is needed")?;
            load(args.spec.as_deref(), step, args.model)?
        }
    })
}

/// The scene's `camera` moved by `--eye`, `--target` and `--fov`, checked.
fn camera(args: &RenderArgs, camera: Camera) -> Result<Camera, String> {
    // The camera's checks name the API's fields; a command line has flags.
    let error = |e: isoray_server::kinds::error::KindError| {
        [
            ("camera.eye", "--eye"),
            ("camera.target", "--target"),
            ("camera.fov_y_deg", "--fov"),
            ("camera: ", "--eye, --target: "),
        ]
        .iter()
        .fold(e.message, |m, (field, flag)| m.replace(field, flag))
    };
    Ok(
        if args.eye.is_some() || args.target.is_some() || args.fov.is_some() {
            let c = camera;
            let api = ApiCamera {
                eye: args.eye.unwrap_or(c.eye.to_array().map(f64::from)),
                target: args.target.unwrap_or(c.target.to_array().map(f64::from)),
                up: c.up.to_array().map(f64::from),
                fov_y_deg: args.fov.unwrap_or(f64::from(c.fov_y_deg)),
            };
            convert::camera(&api, "camera").map_err(error)?
        } else {
            camera
        },
    )
}

/// The output's format (`--format`, else the output's extension), and the options that
/// depend on it or on nothing else checked.
fn format(args: &RenderArgs) -> Result<Format, String> {
    let extension = args
        .output
        .extension()
        .map(|e| e.to_string_lossy().to_ascii_lowercase());
    let format = match args.format.as_deref().or(extension.as_deref()) {
        Some("png") => Format::Png,
        Some("jpg" | "jpeg") => Format::Jpeg,
        Some("npy") => Format::Npy,
        _ if args.format.is_some() => {
            return Err(format!(
                "--format {}: use png, jpeg or npy",
                args.format.as_deref().unwrap_or_default()
            ))
        }
        _ => {
            return Err(format!(
                "{}: write .png, .jpg, .jpeg or .npy (or give --format)",
                args.output.display()
            ))
        }
    };
    if !(1..=100).contains(&args.quality) {
        return Err(format!("--quality {} must be in 1..=100", args.quality));
    }
    if !(1..=4096).contains(&args.passes) {
        return Err(format!("--passes {} must be in 1..=4096", args.passes));
    }
    if args.passes > 1 && matches!(format, Format::Npy) {
        return Err(format!(
            "--passes {}: an npy render is one pass through the pixels' centres",
            args.passes
        ));
    }
    let most = isoray_render::backend::MAX_THREADS;
    if args.threads > most {
        return Err(format!(
            "--threads {} must be at most {most} (0: one per core)",
            args.threads
        ));
    }
    Ok(format)
}

enum Format {
    Png,
    Jpeg,
    Npy,
}

/// Reads the scene description and the step, checking both as the server would. A molecule
/// file (`.pdb`, `.ent`, `.cif`) is read as `isoray push` reads it: its first model (or
/// `model`) as the rows of a metaball step, with that command's scene description unless
/// `spec_path` gives one.
fn load(spec_path: Option<&Path>, step_path: &Path, model: usize) -> Result<Loaded, String> {
    let molecule = if is_molecule(step_path) {
        let models = read_models(step_path, MoleculeOptions::default())?;
        let rows = models.get(model.wrapping_sub(1)).ok_or_else(|| {
            format!(
                "{}: --model {model}: the file has models 1 to {}",
                step_path.display(),
                models.len()
            )
        })?;
        let mut npy = npy_header_f32(rows.len() as u64, 8);
        npy.extend(rows.iter().flatten().flat_map(|v| v.to_le_bytes()));
        let stem = step_path
            .file_stem()
            .map_or_else(String::new, |s| s.to_string_lossy().into_owned());
        Some((super::push_molecule::spec(&models, &stem), npy))
    } else {
        None
    };
    let spec: CreateScene = match (spec_path, &molecule) {
        (Some(p), _) => {
            let text = std::fs::read(p).map_err(|e| format!("{}: {e}", p.display()))?;
            serde_json::from_slice(&text).map_err(|e| format!("{}: {e}", p.display()))?
        }
        (None, Some((spec, _))) => serde_json::from_str(spec).map_err(|e| e.to_string())?,
        (None, None) => {
            serde_json::from_str(r#"{"kind":"metaballs"}"#).map_err(|e| e.to_string())?
        }
    };
    let setup = isoray_server::kinds::refuse_field_settings(&spec)
        .and_then(|()| SceneSetup::from_spec(&spec, &EffectLimits::ENGINE))
        .map_err(|e| {
            format!(
                "{}: {}{}",
                spec_path.map_or("scene".into(), |p| p.display().to_string()),
                e.field.map(|f| format!("{f}: ")).unwrap_or_default(),
                e.message
            )
        })?;
    let shown = step_path.display();
    let (bytes, ext) = match molecule {
        Some((_, npy)) => (npy, Some("npy".to_string())),
        None => (
            std::fs::read(step_path).map_err(|e| format!("{shown}: {e}"))?,
            step_path
                .extension()
                .map(|e| e.to_string_lossy().to_ascii_lowercase()),
        ),
    };
    let (columns, payload) = if ext.as_deref() == Some("step") {
        // A step file from a store's data directory, checked like the store checks it.
        let header = StepHeader::decode(&bytes).map_err(|e| format!("{shown}: {e}"))?;
        verify_payload(&header, &bytes[HEADER_LEN..]).map_err(|e| format!("{shown}: {e}"))?;
        (header.columns, bytes[HEADER_LEN..].to_vec())
    } else {
        let limits = IngestLimits {
            layout: setup.layout(),
            max_rows: u64::from(u32::MAX),
            max_step_bytes: u64::MAX,
        };
        let target = Target {
            temp_path: std::env::temp_dir().join(format!(
                ".tmp-isoray-render-{}-{}.step",
                std::process::id(),
                isoray_server::random::random_hex(8)
            )),
            index: 0,
            time: 0.0,
        };
        let written = match ext.as_deref() {
            Some("npy") => ingest_npy(BodyReader::from_bytes(bytes.into()), &limits, target),
            Some("json") => {
                let step: JsonStep =
                    serde_json::from_slice(&bytes).map_err(|e| format!("{shown}: {e}"))?;
                ingest_json(&step, &limits, target)
            }
            _ => ingest_raw(BodyReader::from_bytes(bytes.into()), &limits, target),
        }
        .map_err(|e| {
            format!(
                "{shown}: {}{}",
                e.field.map(|f| format!("{f}: ")).unwrap_or_default(),
                e.message
            )
        })?;
        let file = std::fs::read(written.temp.path()).map_err(|e| e.to_string())?;
        (written.header.columns, file[HEADER_LEN..].to_vec())
    };
    Ok(Loaded {
        scene: setup.scene(Some((columns, &payload))),
        camera: setup.camera,
        isovalue: setup.isovalue,
        slider: setup.slider,
    })
}
