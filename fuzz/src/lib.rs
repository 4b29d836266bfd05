//! Shared pieces of the fuzz targets: the `isoray push` VTK readers, which live in the
//! server's binary crate and are compiled here from the same source files.

pub mod cli;

use std::io::Write;
use std::path::PathBuf;

/// Writes `data` to one scratch file per process (the VTK readers take a path, as `isoray
/// push` does) and returns its path.
pub fn scratch_file(data: &[u8], suffix: &str) -> PathBuf {
    static DIR: std::sync::OnceLock<tempfile::TempDir> = std::sync::OnceLock::new();
    let dir = DIR.get_or_init(|| tempfile::tempdir().expect("a scratch directory"));
    let path = dir.path().join(format!("input{suffix}"));
    let mut f = std::fs::File::create(&path).expect("scratch file");
    f.write_all(data).expect("scratch write");
    path
}

/// The step ingest functions' signature (`ingest_npy`, `ingest_raw`).
pub type Ingest = fn(
    isoray_server::body::BodyReader,
    &isoray_server::store::ingest::IngestLimits,
    isoray_server::store::ingest::Target,
) -> Result<
    isoray_server::store::ingest::WrittenStep,
    isoray_server::store::ingest::IngestError,
>;

/// Feeds a pushed step to `ingest`: the first byte picks the layout (even: metaballs; odd: a
/// tet scene of `byte >> 1` vertices), the rest is the body.
pub fn fuzz_step(data: &[u8], ingest: Ingest) {
    use isoray_server::kinds::StepLayout;
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let layout = if which & 1 == 0 {
        StepLayout::Metaballs
    } else {
        StepLayout::Tets {
            vertices: Some(u64::from(which >> 1)),
        }
    };
    ingest_step(body, layout, ingest);
}

/// Ingests `body` as a step of `layout` with `ingest`, under small limits, into a scratch file.
fn ingest_step(body: &[u8], layout: isoray_server::kinds::StepLayout, ingest: Ingest) {
    use isoray_server::store::ingest::{IngestLimits, Target};
    let limits = IngestLimits {
        layout,
        max_rows: 4096,
        max_step_bytes: 1 << 20,
    };
    let target = Target {
        temp_path: scratch_file(&[], ".step"),
        index: 0,
        time: 0.0,
    };
    let body = isoray_server::body::BodyReader::from_bytes(bytes::Bytes::copy_from_slice(body));
    let _ = ingest(body, &limits, target);
}

/// One render pool of one thread for every execution of a process.
fn backend() -> &'static isoray_render::CpuBackend {
    static BACKEND: std::sync::OnceLock<isoray_render::CpuBackend> = std::sync::OnceLock::new();
    BACKEND.get_or_init(|| isoray_render::CpuBackend::new(1).expect("a render pool"))
}

/// The most surfels a fuzzed mesh is sampled into (the API's default is 20,000: seconds an
/// execution), and the nodes laid around a file's object (`isoray push` lays 450).
const FUZZ_MESH_SURFELS: u64 = 256;
const FUZZ_NODES: usize = 24;

/// The scene description `isoray push` makes of a point cloud or mesh file: nodes on a lattice
/// around its finite points, and the points (or the mesh, sampled) as surfels.
pub fn surfel_spec_of(input: cli::surfel_files::SurfelInput) -> isoray_protocol::api::SurfelSpec {
    use cli::surfel_files::SurfelInput;
    use isoray_protocol::api::{SurfelMesh, SurfelPoints, SurfelSpec};
    let vec = |p: &[f64; 3]| glam::Vec3::new(p[0] as f32, p[1] as f32, p[2] as f32);
    let points: Vec<glam::Vec3> = match &input {
        SurfelInput::Points { positions, .. } => positions.iter().map(vec).collect(),
        SurfelInput::Mesh { vertices, .. } => vertices.iter().map(vec).collect(),
    };
    let finite: Vec<glam::Vec3> = points.into_iter().filter(|p| p.is_finite()).collect();
    let nodes = isoray_render::kinds::surfels::input::nodes_for(&finite, FUZZ_NODES)
        .iter()
        .map(|p| p.as_dvec3().to_array())
        .collect();
    let (points, mesh) = match input {
        SurfelInput::Points { positions, normals } => (
            Some(SurfelPoints {
                positions,
                normals,
                color: None,
            }),
            None,
        ),
        SurfelInput::Mesh {
            vertices,
            triangles,
        } => (
            None,
            Some(SurfelMesh {
                vertices,
                triangles,
                count: Some(FUZZ_MESH_SURFELS),
                color: None,
            }),
        ),
    };
    SurfelSpec {
        surfels: Vec::new(),
        points,
        mesh,
        nodes,
        node_mass: None,
        clip: None,
        update: None,
    }
}

/// What the server does with a surfel scene's description and its steps: checks and
/// precomputes it (`setup_from_spec`), then prepares and traces (8×8, shadows on) the rest
/// shape and one step whose nodes move by `scale` times the object's size in pseudo-random
/// directions (`seed`), with the gradients estimated by least squares as for a pushed step.
pub fn exercise_surfels(spec: &isoray_protocol::api::SurfelSpec, scale: f32, seed: u64) {
    use isoray_render::geom::rng::SplitMix64;
    use isoray_render::scene::Geometry;
    use isoray_render::{Camera, Scene, View};
    let Ok(setup) = isoray_server::kinds::surfels::setup::setup_from_spec(Some(spec)) else {
        return;
    };
    let rest = &setup.model.nodes;
    let (lo, hi) = rest.iter().fold(
        (glam::Vec3::splat(f32::MAX), glam::Vec3::splat(f32::MIN)),
        |(a, b), p| (a.min(*p), b.max(*p)),
    );
    let size = (hi - lo).length().max(1e-3);
    let mut rng = SplitMix64(seed);
    let moved: Vec<u8> = rest
        .iter()
        .flat_map(|p| (*p + rng.in_unit_ball() * (scale * size)).to_array())
        .flat_map(f32::to_le_bytes)
        .collect();
    let backend = backend();
    let centre = 0.5 * (lo + hi);
    let view = View {
        width: 8,
        height: 8,
        camera: Camera {
            eye: centre + glam::Vec3::new(0.3, 0.4, 1.6) * size,
            target: centre,
            up: glam::Vec3::Y,
            fov_y_deg: 45.0,
        },
        isovalue: 0.5,
    };
    for step in [None, Some((3, &moved[..]))] {
        let mut lighting = isoray_render::shade::Lighting::default();
        lighting.effects.shadows = true;
        let scene = Scene {
            geometry: Geometry::Surfels(setup.scene(step)),
            lighting,
        };
        if scene.validate(usize::MAX).is_ok() {
            let _ = backend.render(&std::sync::Arc::new(scene).prepare(), &view);
        }
    }
}

/// A pushed surfel step (node positions, `.npy` when the first byte is even, raw otherwise)
/// for a scene of `byte >> 1` nodes, through the step ingest the server runs.
pub fn fuzz_surfel_step(data: &[u8]) {
    use isoray_server::kinds::StepLayout;
    use isoray_server::store::ingest::{ingest_npy, ingest_raw};
    let Some((&which, body)) = data.split_first() else {
        return;
    };
    let layout = StepLayout::Surfels {
        nodes: u64::from(which >> 1),
    };
    let ingest: Ingest = if which & 1 == 0 {
        ingest_npy
    } else {
        ingest_raw
    };
    ingest_step(body, layout, ingest);
}

/// What the server builds of a created scene, traced once: the kind's first state (seven
/// metaballs in a row, the tet scene before its mesh, the surfel object at rest) lit, shaded
/// and with the effects of the validated description, seen from its camera at 8×8.
pub fn render_setup(setup: &isoray_server::kinds::SceneSetup) {
    use isoray_render::scene::Geometry;
    use isoray_render::{Scene, View};
    use isoray_server::kinds::{metaballs, KindSetup};
    let rows: Vec<u8> = (0..7)
        .flat_map(|i| [i as f32 * 0.6 - 1.8, 0.0, 0.0, 1.0])
        .flat_map(f32::to_le_bytes)
        .collect();
    let geometry = match &setup.kind {
        KindSetup::Metaballs(d) => Geometry::Metaballs(metaballs::setup::scene(
            d,
            Some((4, &rows)),
            setup.slider.0.min(setup.isovalue).max(1e-3),
        )),
        KindSetup::Tets(t) => Geometry::Tets(t.scene(None)),
        KindSetup::Surfels(s) => Geometry::Surfels(s.scene(None)),
    };
    let scene = Scene {
        geometry,
        lighting: setup.lighting.clone(),
    };
    if scene.validate(usize::MAX).is_err() {
        return;
    }
    let view = View {
        width: 8,
        height: 8,
        camera: setup.camera,
        isovalue: setup.isovalue,
    };
    let _ = backend().render(&std::sync::Arc::new(scene).prepare(), &view);
}
