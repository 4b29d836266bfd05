//! Scene descriptions with effects, over the REST API: every wrong value (unknown field,
//! negative light intensity, IOR below 1, NaN or out-of-range colour, quality beyond the
//! server's configured maximum) is a 400 naming the field, nothing is created, and the
//! server keeps serving. A valid description with every part is accepted.

use isoray_server::api::client::{Body, Client};
use serde_json::Value;

/// POSTs `body` as a scene; returns (status, JSON answer).
async fn create(base: &str, body: String) -> (u16, Value) {
    let base = base.to_string();
    tokio::task::spawn_blocking(move || {
        let r = Client::new(&base)
            .expect("url")
            .request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(body.as_bytes()),
            )
            .expect("answered");
        let v = serde_json::from_slice(&r.body).unwrap_or(Value::Null);
        (r.status, v)
    })
    .await
    .expect("client thread")
}

fn scene(lighting: &str) -> String {
    format!(r#"{{"kind":"metaballs","lighting":{lighting}}}"#)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn bad_scene_descriptions_name_the_field_and_create_nothing() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server =
        crate::api::Server::start(dir.path(), &["--max-ray-depth", "4", "--max-samples", "16"])
            .await;
    let base = server.base.clone();
    let cases: &[(&str, &str, &str)] = &[
        // (lighting JSON, field the error must name, word the message must contain)
        (
            r#"{"lights":[{"to_light":[0,1,0],"colour":[1,1,1]}]}"#,
            "lighting.lights[0]",
            "colour",
        ),
        (
            r#"{"materials":[{"ior":1.5,"glossy":true}]}"#,
            "lighting.materials[0]",
            "glossy",
        ),
        (
            r#"{"lights":[{"to_light":[0,1,0],"intensity":-2}]}"#,
            "lighting.lights[0].intensity",
            "-2",
        ),
        (
            r#"{"lights":[{"kind":"sphere","position":[0,5,0],"radius":1,"intensity":-0.5}]}"#,
            "lighting.lights[0].intensity",
            "-0.5",
        ),
        (
            r#"{"materials":[{"ior":0.8}]}"#,
            "lighting.materials[0].ior",
            "0.8",
        ),
        (
            r#"{"materials":[{},{"ior":0.99,"opacity":0.5}]}"#,
            "lighting.materials[1].ior",
            "0.99",
        ),
        (
            r#"{"lights":[{"to_light":[0,1,0],"color":[NaN,0,0]}]}"#,
            "lighting.lights[0].color[0]",
            "",
        ),
        (
            r#"{"materials":[{"diffuse":[0.5,"NaN",0.5]}]}"#,
            "lighting.materials[0].diffuse[1]",
            "",
        ),
        (
            r#"{"materials":[{"emission":[0,0,1e999]}]}"#,
            "lighting.materials[0].emission[2]",
            "",
        ),
        (
            r#"{"background_top":[0.2,-0.1,0.3]}"#,
            "lighting.background_top[1]",
            "-0.1",
        ),
        (
            r#"{"effects":{"depth":5}}"#,
            "lighting.effects.depth",
            "0..=4",
        ),
        (
            r#"{"effects":{"layers":100}}"#,
            "lighting.effects.layers",
            "0..=4",
        ),
        (
            r#"{"effects":{"light_samples":17}}"#,
            "lighting.effects.light_samples",
            "1..=16",
        ),
        (r#"{"effects":{"depth":-1}}"#, "lighting.effects.depth", ""),
        (
            r#"{"lights":[{"kind":"sphere","position":[0,5,0]}]}"#,
            "lighting.lights[0].radius",
            "radius",
        ),
        (
            r#"{"lights":[{"kind":"point","to_light":[0,1,0],"position":[0,5,0]}]}"#,
            "lighting.lights[0].to_light",
            "to_light",
        ),
        (
            r#"{"groups":[{"first":0,"count":5,"material":3}]}"#,
            "lighting.groups[0].material",
            "3",
        ),
        (
            r#"{"clip_box":{"min":[1,0,0],"max":[0,1,1]}}"#,
            "lighting.clip_box",
            "min",
        ),
        (
            r#"{"volume":{"density":0}}"#,
            "lighting.volume.density",
            "positive",
        ),
        (
            r#"{"isosurfaces":[{"isovalue":-0.2}]}"#,
            "lighting.isosurfaces[0].isovalue",
            "positive",
        ),
    ];
    for (lighting, field, word) in cases {
        let (status, answer) = create(&base, scene(lighting)).await;
        // Rules between values (a sphere light's radius, a point light's missing direction,
        // a material index, min below max) are 422s; values outside their schema are 400s.
        let relational = [
            "lighting.lights[0].radius",
            "lighting.lights[0].to_light",
            "lighting.groups[0].material",
            "lighting.clip_box",
        ];
        let want = if relational.contains(field) { 422 } else { 400 };
        assert_eq!(status, want, "{lighting}: {answer}");
        let named = answer["field"].as_str().unwrap_or_default();
        assert!(
            named.starts_with(field),
            "{lighting}: the error names the field {field}: {answer}"
        );
        let message = answer["message"].as_str().expect("a message");
        assert!(message.contains(word), "{lighting}: {message}");
    }
    // Nothing was created, and the server still serves.
    let list = tokio::task::spawn_blocking({
        let base = base.clone();
        move || {
            Client::new(&base)
                .expect("url")
                .request("GET", "/api/v1/scenes", &[], Body::Bytes(b""))
                .expect("answered")
        }
    })
    .await
    .expect("client thread");
    assert_eq!(list.status, 200);
    let list: Value = serde_json::from_slice(&list.body).expect("JSON");
    let stored = list["scenes"]
        .as_array()
        .expect("scenes")
        .iter()
        .filter(|s| s["source"] == "stored")
        .count();
    assert_eq!(stored, 0, "a rejected description created a scene");

    // Every part at once, valid.
    let good = r#"{
        "lights":[{"kind":"sphere","position":[2,6,3],"radius":1,"intensity":40},
                  {"kind":"point","position":[-3,4,2],"color":[1,0.9,0.8],"intensity":10},
                  {"to_light":[0,1,0],"intensity":0.2}],
        "materials":[{"diffuse":[0.8,0.4,0.3]},{"opacity":0.1,"ior":1.5,"specular":0.8,"shininess":200},
                     {"reflectivity":0.8},{"emission":[2,2,2]}],
        "groups":[{"first":0,"count":10,"material":1},{"first":10,"count":10,"material":2}],
        "floor":{"height":-1,"material":0,"checker":0.5},
        "clip_box":{"min":[0,-10,0],"max":[10,10,10]},
        "isosurfaces":[{"isovalue":0.2,"material":1}],
        "volume":{"density":0.5},
        "occlusion_distance":2,
        "effects":{"shadows":true,"soft_shadows":true,"reflections":true,"depth":4,"light_samples":16}
    }"#;
    let (status, answer) = create(&base, scene(good)).await;
    assert_eq!(status, 201, "{answer}");
    server.stop().await;
}
