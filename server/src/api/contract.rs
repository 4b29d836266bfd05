//! The OpenAPI document as a contract: what utoipa generates from the wire types and the
//! handlers' annotations, completed with every constraint the server checks that the types
//! cannot carry, for the limits this server was started with.
//!
//! - Value constraints of request bodies (lengths of fixed-size arrays, ranges, string
//!   lengths, names), from the checks in `kinds::convert`, `kinds::*::setup`, `style`,
//!   `effects`, `store::ingest` and the handlers; the configured ones (`--max-size`,
//!   `--max-step-index`, `--max-ray-depth`, `--max-samples`) from `Config`.
//! - Who may call what: `security` per operation from `--admin-token` and `--view-token`.
//! - Every status a route can answer (401/403 before anything else, 404/421 for a scene id,
//!   400/408/413/415/422 for a body, 409 for a built-in demo, 429, 507).
//!
//! A request the schema allows but that breaks a rule between values (eye and target differ,
//! low below high, indices within the mesh, an isovalue inside the scene's range) is answered
//! 422 (`KindErrorKind::Relational`); each such rule is named in a description here. The
//! `api::schemathesis` test runs schemathesis against a live server and this document.

use crate::config::Config;
use crate::kinds::surfels::setup::{MAX_NODES, MAX_SURFELS, MIN_POSITIVE};
use isoray_protocol::api::SceneKind;
use serde_json::{json, Map, Value};

/// Largest magnitude of coordinates and most scalars in a scene description
/// (`kinds::convert::finite`).
const COORD: f64 = 1.0e6;
/// Largest finite `f32`: step values are stored as `f32`.
const F32_MAX: f64 = f32::MAX as f64;

/// Completes the generated document for this server's configuration.
pub fn apply(doc: &mut Value, config: &Config) {
    constrain_schemas(doc, config);
    complete_operations(doc, config);
}

/// `n` numbers, each in `[lo, hi]`.
fn numbers(n: u64, lo: f64, hi: f64) -> Value {
    json!({"minItems": n, "maxItems": n, "items": {"minimum": lo, "maximum": hi}})
}

fn range(lo: f64, hi: f64) -> Value {
    json!({"minimum": lo, "maximum": hi})
}

/// Merges `patch` into `target`, objects key by key.
fn merge(target: &mut Value, patch: &Value) {
    match (target, patch) {
        (Value::Object(t), Value::Object(p)) => {
            for (k, v) in p {
                merge(t.entry(k.clone()).or_insert(Value::Null), v);
            }
        }
        (t, p) => *t = p.clone(),
    }
}

/// The kinds this server's engine serves (a creation request for another is refused).
fn served_kinds() -> Vec<&'static str> {
    [SceneKind::Metaballs, SceneKind::Surfels, SceneKind::Tets]
        .into_iter()
        .filter(|k| crate::kinds::StepLayout::of(*k).is_some())
        .map(SceneKind::as_str)
        .collect()
}

/// A property's constraints: (schema, property, what to merge into it).
type Constraint = (&'static str, &'static str, Value);

/// A scene description's own fields, its kinds' data and steps.
fn scene_constraints() -> Vec<Constraint> {
    let point = numbers(3, -COORD, COORD);
    let kernels: Vec<&str> = crate::kinds::metaballs::setup::KERNEL_NAMES
        .split(", ")
        .collect();
    vec![
        (
            "CreateScene",
            "kind",
            json!({"type": "string", "enum": served_kinds(), "$ref": null,
                   "description": "A kind this server serves."}),
        ),
        ("CreateScene", "name", json!({"maxLength": 200})),
        ("CreateScene", "description", json!({"maxLength": 4000})),
        (
            "CreateScene",
            "isovalue",
            json!({"minimum": -COORD, "maximum": COORD,
                   "description": "The isovalue viewers start with (default 0.5); positive in a metaball scene (422 otherwise)."}),
        ),
        (
            "CreateScene",
            "isovalue_slider",
            json!({"minItems": 2, "maxItems": 2, "items": range(-COORD, COORD),
                   "description": "Slider range offered to viewers (default [0.05, 1.5]): [lo, hi] with lo < hi, and 0 < lo in a metaball scene (422 otherwise)."}),
        ),
        ("MetaballDefaults", "kernel", json!({"enum": kernels})),
        (
            "MetaballDefaults",
            "radius",
            json!({"exclusiveMinimum": 0.0, "maximum": COORD}),
        ),
        ("MetaballDefaults", "strength", range(-COORD, COORD)),
        ("MetaballDefaults", "color", point.clone()),
        (
            "TetSpec",
            "color_range",
            json!({"minItems": 2, "maxItems": 2, "items": range(-COORD, COORD),
                   "description": "Scalar values at the two ends of the colour map (default: the isovalue slider's range); two different values (422 otherwise)."}),
        ),
        (
            "TetMeshData",
            "vertices",
            json!({"items": numbers(3, -F32_MAX, F32_MAX),
                   "description": "Vertex positions (finite f32)."}),
        ),
        (
            "TetMeshData",
            "cells",
            json!({"items": {"minItems": 4, "maxItems": 4, "items": {"maximum": u64::MAX}},
                   "description": "Four vertex indices per tet, each below the number of vertices, four different vertices of a tet with positive volume (422 otherwise)."}),
        ),
    ]
}

/// A scene's lighting: lights, materials, groups, floor, clip box, isosurfaces, volume.
fn lighting_constraints() -> Vec<Constraint> {
    let rgb = numbers(3, 0.0, 1.0);
    let point = numbers(3, -COORD, COORD);
    vec![
        ("LightingSpec", "lights", json!({"maxItems": 8})),
        ("LightingSpec", "ambient", rgb.clone()),
        ("LightingSpec", "background_top", rgb.clone()),
        ("LightingSpec", "background_bottom", rgb.clone()),
        ("LightingSpec", "shininess", range(1.0, 10_000.0)),
        ("LightingSpec", "specular", range(0.0, 1.0)),
        (
            "LightingSpec",
            "materials",
            json!({"minItems": 1, "maxItems": 64}),
        ),
        ("LightingSpec", "groups", json!({"maxItems": 1024})),
        ("LightingSpec", "isosurfaces", json!({"maxItems": 4})),
        (
            "LightingSpec",
            "occlusion_distance",
            json!({"exclusiveMinimum": 0.0, "maximum": COORD}),
        ),
        (
            "LightSpec",
            "to_light",
            json!({"minItems": 3, "maxItems": 3, "items": range(-COORD, COORD),
                   "description": "Directional lights only, and needed by them: direction from the surface towards the light, not zero (422 otherwise)."}),
        ),
        (
            "LightSpec",
            "position",
            json!({"minItems": 3, "maxItems": 3, "items": range(-COORD, COORD),
                   "description": "Point and sphere lights only, and needed by them (422 otherwise)."}),
        ),
        (
            "LightSpec",
            "radius",
            json!({"exclusiveMinimum": 0.0, "maximum": COORD,
                   "description": "Sphere lights only, and needed by them (422 otherwise)."}),
        ),
        ("LightSpec", "color", rgb.clone()),
        ("LightSpec", "intensity", range(0.0, COORD)),
        (
            "ApiCamera",
            "eye",
            json!({"minItems": 3, "maxItems": 3, "items": range(-COORD, COORD),
                   "description": "Differs from `target`, and `up` is not parallel to the view (422 otherwise)."}),
        ),
        ("ApiCamera", "target", point.clone()),
        ("ApiCamera", "up", point.clone()),
        ("ApiCamera", "fov_y_deg", range(1.0, 170.0)),
        ("MaterialSpec", "diffuse", rgb.clone()),
        ("MaterialSpec", "specular", range(0.0, 1.0)),
        ("MaterialSpec", "shininess", range(1.0, 10_000.0)),
        ("MaterialSpec", "reflectivity", range(0.0, 1.0)),
        ("MaterialSpec", "ior", range(1.0, 4.0)),
        ("MaterialSpec", "opacity", range(0.0, 1.0)),
        ("MaterialSpec", "emission", numbers(3, 0.0, 1000.0)),
        ("GroupSpec", "first", range(0.0, f64::from(u32::MAX))),
        ("GroupSpec", "count", range(0.0, f64::from(u32::MAX))),
        (
            "GroupSpec",
            "material",
            json!({"maximum": u16::MAX, "description": "Index of a material in `lighting.materials` (422 otherwise)."}),
        ),
        ("FloorSpec", "height", range(-COORD, COORD)),
        (
            "FloorSpec",
            "material",
            json!({"maximum": u16::MAX, "description": "Index of a material in `lighting.materials` (422 otherwise)."}),
        ),
        (
            "FloorSpec",
            "colors",
            json!({"minItems": 2, "maxItems": 2, "items": numbers(3, 0.0, 1.0)}),
        ),
        ("FloorSpec", "checker", range(0.0, COORD)),
        (
            "ClipBoxSpec",
            "min",
            json!({"minItems": 3, "maxItems": 3, "items": range(-COORD, COORD),
                   "description": "Below `max` on every axis (422 otherwise)."}),
        ),
        ("ClipBoxSpec", "max", point.clone()),
        (
            "IsosurfaceSpec",
            "isovalue",
            json!({"exclusiveMinimum": 0.0, "maximum": COORD}),
        ),
        (
            "IsosurfaceSpec",
            "material",
            json!({"maximum": u16::MAX, "description": "Index of a material in `lighting.materials` (422 otherwise)."}),
        ),
        (
            "VolumeSpec",
            "density",
            json!({"exclusiveMinimum": 0.0, "maximum": COORD}),
        ),
        ("VolumeSpec", "color", rgb.clone()),
    ]
}

/// A viewer's effects and look, and a render request, within this server's limits.
fn view_constraints(config: &Config) -> Vec<Constraint> {
    let rgb = numbers(3, 0.0, 1.0);
    let max_depth = f64::from(config.max_ray_depth);
    let max_samples = f64::from(config.max_samples);
    let mut maps: Vec<&str> = isoray_render::colormap::ColorMapKind::ALL
        .iter()
        .map(|k| k.name())
        .collect();
    maps.push("none");
    vec![
        ("EffectChanges", "depth", range(0.0, max_depth)),
        ("EffectChanges", "layers", range(0.0, max_depth)),
        ("EffectChanges", "light_samples", range(1.0, max_samples)),
        ("EffectChanges", "ao_samples", range(1.0, max_samples)),
        (
            "EffectChanges",
            "surfaces",
            json!({"maxItems": crate::style::MAX_SURFACES}),
        ),
        (
            "SurfaceStyleSpec",
            "isovalue",
            json!({"description": "Inside the scene's isovalue range (422 otherwise)."}),
        ),
        ("SurfaceStyleSpec", "color", rgb.clone()),
        ("SurfaceStyleSpec", "opacity", range(0.0, 1.0)),
        ("ColorMapSpec", "name", json!({"enum": maps})),
        (
            "ColorMapSpec",
            "range",
            json!({"minItems": 2, "maxItems": 2, "items": range(-1.0e30, 1.0e30),
                   "description": "Low below high (422 otherwise); default: the scene's isovalue slider range."}),
        ),
        (
            "RenderRequest",
            "width",
            range(1.0, f64::from(config.max_size)),
        ),
        (
            "RenderRequest",
            "height",
            range(1.0, f64::from(config.max_size)),
        ),
        ("RenderRequest", "quality", range(1.0, 100.0)),
        (
            "RenderRequest",
            "passes",
            json!({"minimum": 1.0, "maximum": f64::from(config.max_refine_passes),
                   "description": "Passes to average; 1 with `format: \"npy\"` (422 otherwise)."}),
        ),
        ("RenderRequest", "time", range(0.0, 1.0e9)),
        (
            "RenderRequest",
            "isovalue",
            json!({"description": "Inside the scene's isovalue range (422 otherwise)."}),
        ),
        (
            "RenderRequest",
            "step",
            json!({"description": "Stored step to render (default: the newest, or the one `time` picks). Stored scenes only (422 for a built-in demo), one the scene holds, and not with `time` (422 otherwise)."}),
        ),
        (
            "JsonStep",
            "positions",
            json!({"items": numbers(3, -F32_MAX, F32_MAX),
                   "description": "One row per ball; `radii`, `strengths` and `colors`, when present, have as many entries, strengths need radii and colours need both (422 otherwise)."}),
        ),
        (
            "JsonStep",
            "radii",
            json!({"items": {"exclusiveMinimum": 0.0, "maximum": F32_MAX}}),
        ),
        (
            "JsonStep",
            "strengths",
            json!({"items": range(-F32_MAX, F32_MAX)}),
        ),
        (
            "JsonStep",
            "colors",
            json!({"items": numbers(3, -F32_MAX, F32_MAX)}),
        ),
        (
            "JsonTetStep",
            "positions",
            json!({"items": numbers(3, -F32_MAX, F32_MAX),
                   "description": "This step's vertex positions, one row per mesh vertex (default: the mesh's own); no tet may become inverted or degenerate (422 otherwise)."}),
        ),
        (
            "JsonTetStep",
            "scalars",
            json!({"items": range(-F32_MAX, F32_MAX),
                   "description": "One scalar per mesh vertex (422 otherwise, or for a metaball scene)."}),
        ),
    ]
}

/// A surfel scene's object (`kinds::surfels::setup`): what the schema can state, and in
/// prose the rules between values (422).
fn surfel_constraints() -> Vec<Constraint> {
    let point = numbers(3, -COORD, COORD);
    let colour = numbers(3, 0.0, 1.0);
    let positive = json!({"minimum": MIN_POSITIVE, "maximum": COORD});
    let group = json!({"minimum": 0, "maximum": u16::MAX});
    vec![
        (
            "CreateScene",
            "surfels",
            json!({"description": "Static data of a surfel scene: its surfels and simulation nodes; required for a surfel scene (422 otherwise)."}),
        ),
        (
            "SurfelSpec",
            "surfels",
            json!({"maxItems": MAX_SURFELS,
                   "description": "The surfels; with those of `points` and `mesh`, at least one and at most the limit of this list (422 otherwise)."}),
        ),
        (
            "SurfelSpec",
            "nodes",
            json!({"minItems": 1, "maxItems": MAX_NODES, "items": point.clone(),
                   "description": "Rest positions of the simulation nodes; each step moves them, one row per node (a step with another row count is a 422)."}),
        ),
        (
            "SurfelSpec",
            "node_mass",
            json!({"items": positive.clone(),
                   "description": "Masses of the nodes (default all 1): one per node (422 otherwise)."}),
        ),
        (
            "SurfelSpec",
            "clip",
            json!({"items": {"minItems": 2, "maxItems": 2, "items": group.clone()},
                   "description": "Clipping relations [a, b]: surfels of group a are cut by the surface of group b; both groups have surfels (422 otherwise)."}),
        ),
        (
            "SurfelSpec",
            "update",
            json!({"enum": ["auto", "lazy", "eager", "rebuild", null]}),
        ),
        ("SurfelData", "centre", point.clone()),
        (
            "SurfelData",
            "t1",
            json!({"minItems": 3, "maxItems": 3, "items": range(-COORD, COORD),
                   "description": "First tangent axis: not of zero length (422 otherwise)."}),
        ),
        (
            "SurfelData",
            "t2",
            json!({"minItems": 3, "maxItems": 3, "items": range(-COORD, COORD),
                   "description": "Second tangent axis: not of zero length, not parallel to t1 (422 otherwise)."}),
        ),
        (
            "SurfelData",
            "normal",
            json!({"minItems": 3, "maxItems": 3, "items": range(-COORD, COORD),
                   "description": "Outward normal (default t1 × t2): not of zero length, not in the tangent plane (422 otherwise)."}),
        ),
        ("SurfelData", "radius", positive.clone()),
        ("SurfelData", "color", colour.clone()),
        ("SurfelData", "group", group),
        (
            "SurfelPoints",
            "positions",
            json!({"minItems": 1, "maxItems": MAX_SURFELS, "items": point.clone()}),
        ),
        (
            "SurfelPoints",
            "normals",
            json!({"items": point.clone(),
                   "description": "One per position (422 otherwise); a zero normal is estimated like a missing one."}),
        ),
        ("SurfelPoints", "color", colour.clone()),
        ("SurfelMesh", "vertices", json!({"items": point})),
        (
            "SurfelMesh",
            "triangles",
            json!({"minItems": 1, "items": {"minItems": 3, "maxItems": 3, "items": {"maximum": u64::MAX}},
                   "description": "Vertex indices of each triangle, each below the number of vertices; not every face of zero area (422 otherwise)."}),
        ),
        (
            "SurfelMesh",
            "count",
            json!({"minimum": 1, "maximum": MAX_SURFELS}),
        ),
        ("SurfelMesh", "color", colour),
    ]
}

fn constrain_schemas(doc: &mut Value, config: &Config) {
    let mut table = scene_constraints();
    table.extend(surfel_constraints());
    table.extend(lighting_constraints());
    table.extend(view_constraints(config));
    let Some(schemas) = doc
        .pointer_mut("/components/schemas")
        .and_then(Value::as_object_mut)
    else {
        return;
    };
    for (schema, property, patch) in &table {
        let Some(target) = schemas
            .get_mut(*schema)
            .and_then(|s| s.get_mut("properties"))
            .and_then(|p| p.get_mut(*property))
        else {
            tracing::warn!(
                schema,
                property,
                "OpenAPI contract names a missing property"
            );
            continue;
        };
        constrain(target, patch);
    }
    // A scene's starting effects have no viewer-only fields (`style::refuse_in_scene`).
    if let Some(effects) = schemas
        .get_mut("LightingSpec")
        .and_then(|s| s.pointer_mut("/properties/effects"))
    {
        *effects = json!({"oneOf": [
            {"allOf": [
                {"$ref": "#/components/schemas/EffectChanges"},
                {"type": "object", "properties": {
                    "clip": {"type": "null"},
                    "surfaces": {"type": "null"},
                    "scene_surfaces": {"type": "null"},
                    "color_map": {"type": "null"}
                }}
            ]},
            {"type": "null"}
        ], "description": "The effects viewers start with (default: none); not the viewer-only `clip`, `surfaces`, `scene_surfaces` and `color_map`."});
    }
}

/// Applies a property's constraints: to the schema itself, or to the non-null branch of an
/// optional one (`oneOf: [X, null]`, where X may be a reference that other places share).
fn constrain(target: &mut Value, patch: &Value) {
    if patch.get("$ref").is_some_and(Value::is_null) {
        // Replace the schema (an enum narrower than the shared one it referred to).
        let mut p = patch.clone();
        if let Some(o) = p.as_object_mut() {
            o.remove("$ref");
        }
        *target = p;
        return;
    }
    merge(target, patch);
}

/// An error response with the API's error body.
fn error_response(description: &str) -> Value {
    json!({
        "description": description,
        "content": {"application/json": {"schema": {"$ref": "#/components/schemas/ApiErrorBody"}}}
    })
}

/// Operations that write to a scene: the scene's write token or the admin token.
const WRITES: [&str; 4] = ["delete_scene", "push_step", "delete_step", "put_mesh"];
/// Operations that view a scene (the view token, with `--view-token`).
const VIEWS: [&str; 7] = [
    "list_scenes",
    "get_scene",
    "list_steps",
    "get_step",
    "get_step_data",
    "render",
    "histogram",
];
/// Operations with a JSON (or binary) body.
const BODIES: [&str; 4] = ["create_scene", "render", "push_step", "put_mesh"];
/// Operations whose path has a step index.
const INDEXED: [&str; 4] = ["get_step", "get_step_data", "push_step", "delete_step"];

fn complete_operations(doc: &mut Value, config: &Config) {
    let Some(paths) = doc.get_mut("paths").and_then(Value::as_object_mut) else {
        return;
    };
    let optional = json!([{}, {"bearer": []}]);
    let required = json!([{"bearer": []}]);
    for (path, item) in paths.iter_mut() {
        let Some(item) = item.as_object_mut() else {
            continue;
        };
        for (_method, op) in item.iter_mut() {
            let Some(op) = op.as_object_mut() else {
                continue;
            };
            let id = op
                .get("operationId")
                .and_then(Value::as_str)
                .unwrap_or_default()
                .to_string();
            let id = id.as_str();
            let mut add: Vec<(&str, &str)> = Vec::new();
            if path.contains("{id}") && path.starts_with("/api/") {
                add.push(("404", "No such scene (or step)"));
                add.push((
                    "421",
                    "The id names another shard: the load balancer misrouted the request",
                ));
            }
            if WRITES.contains(&id) {
                op.insert("security".into(), required.clone());
                add.extend([
                    (
                        "401",
                        "`Authorization: Bearer` missing: checked before anything else",
                    ),
                    ("403", "Neither the scene's write token nor the admin token"),
                    (
                        "409",
                        "A built-in demo takes no writes, or a conflict with what is stored",
                    ),
                    (
                        "429",
                        "Too many writes from this client (--write-rate, --write-burst)",
                    ),
                ]);
            }
            if id == "create_scene" {
                let security = match config.admin_token {
                    Some(_) => required.clone(),
                    None => optional.clone(),
                };
                op.insert("security".into(), security);
            }
            if VIEWS.contains(&id) {
                let security = match config.view_token {
                    Some(_) => required.clone(),
                    None => optional.clone(),
                };
                op.insert("security".into(), security);
                add.extend([
                    ("401", "View token missing (server started with --view-token): checked before anything else"),
                    ("403", "Not a token that may view this scene"),
                ]);
            }
            if BODIES.contains(&id) {
                add.extend([
                    ("400", "The body breaks the schema; names the field or byte offset"),
                    ("408", "The body did not arrive within --push-timeout-secs"),
                    ("413", "The body is larger than the server's limit"),
                    ("415", "Content-Type is not one the operation takes"),
                    ("422", "The values fit the schema but break a rule between them that its descriptions state"),
                ]);
            }
            if id == "histogram" {
                add.extend([
                    ("400", "A query parameter breaks its schema"),
                    ("422", "lo without hi, hi without lo, or lo not below hi"),
                ]);
            }
            if id == "render" {
                add.push((
                    "429",
                    "Too many renders from this client (--render-rate, --render-burst)",
                ));
            }
            if id == "list_scenes" {
                constrain_param(
                    op,
                    "scope",
                    json!({"type": "string", "enum": ["all", "local"]}),
                );
            }
            if id == "histogram" {
                constrain_param(
                    op,
                    "bins",
                    json!({"type": "integer", "minimum": 1, "maximum": 1024}),
                );
                constrain_param(
                    op,
                    "time",
                    json!({"type": "number", "minimum": 0, "maximum": 1.0e9}),
                );
            }
            if id == "push_step" {
                if let Some(json_body) = op
                    .get_mut("requestBody")
                    .and_then(|b| b.pointer_mut("/content/application~1json"))
                {
                    json_body["schema"] = json!({"oneOf": [
                        {"$ref": "#/components/schemas/JsonStep"},
                        {"$ref": "#/components/schemas/JsonTetStep"}
                    ], "description": "JsonStep for a metaball scene, JsonTetStep for a tet scene, JsonStep with `positions` only (JsonSurfelStep: the nodes' positions) for a surfel scene (another kind's step is a 422)"});
                }
            }
            if INDEXED.contains(&id) {
                add.push(("400", "The step index is beyond --max-step-index"));
                add.push(("409", "A built-in demo has no stored steps"));
                constrain_index(op, config.max_step_index);
            }
            if id == "push_step" || id == "put_mesh" || id == "create_scene" {
                add.push(("507", "The server's disk is full; nothing was stored"));
            }
            let responses = op
                .entry("responses")
                .or_insert_with(|| Value::Object(Map::new()));
            if let Some(responses) = responses.as_object_mut() {
                for (status, description) in add {
                    responses
                        .entry(status)
                        .or_insert_with(|| error_response(description));
                }
            }
        }
    }
}

/// Sets the schema of the parameter `name`.
fn constrain_param(op: &mut Map<String, Value>, name: &str, schema: Value) {
    let Some(params) = op.get_mut("parameters").and_then(Value::as_array_mut) else {
        return;
    };
    for p in params {
        if p.get("name").and_then(Value::as_str) == Some(name) {
            p["schema"] = schema.clone();
        }
    }
}

/// The step index path parameter: an integer in `0..=--max-step-index`.
fn constrain_index(op: &mut Map<String, Value>, max: u64) {
    let Some(params) = op.get_mut("parameters").and_then(Value::as_array_mut) else {
        return;
    };
    for p in params {
        if p.get("name").and_then(Value::as_str) == Some("index") {
            merge(
                p,
                &json!({
                    "description": format!("Step index, 0 to {max} (--max-step-index)"),
                    "schema": {"type": "integer", "minimum": 0, "maximum": max}
                }),
            );
        }
    }
}
