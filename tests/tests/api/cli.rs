//! The `isoray` binary's commands: `isoray push` streams `.npy` files into a scene, `isoray
//! render` draws offline exactly what the server's one-shot render draws, and the plain
//! server start works with the default data directory, even an unusable one.

use super::*;
use std::ffi::OsStr;

fn isoray(args: &[&OsStr]) -> std::process::Output {
    Command::new(isoray_binary())
        .args(args)
        .output()
        .expect("isoray runs")
}

fn text(out: &std::process::Output) -> String {
    format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    )
}

fn os(s: &str) -> &OsStr {
    OsStr::new(s)
}

const SPEC: &str = r#"{"kind":"metaballs","metaballs":{"radius":0.6},
    "camera":{"eye":[0,1,5],"target":[0,0,0]},"isovalue":0.4}"#;

fn step_values(k: usize) -> Vec<f32> {
    (0..40)
        .flat_map(|i| {
            let a = i as f32 * 0.5 + k as f32 * 0.3;
            [a.cos() * 1.2, (i as f32 * 0.05) - 1.0, a.sin() * 1.2]
        })
        .collect()
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn push_streams_npy_files_and_render_matches_the_server() {
    let dir = tempfile::tempdir().expect("temp dir");
    let files = dir.path().join("files");
    std::fs::create_dir(&files).expect("mkdir");
    let mut paths = Vec::new();
    for k in 0..3 {
        let p = files.join(format!("step{k}.npy"));
        std::fs::write(&p, npy(&step_values(k), 3)).expect("write npy");
        paths.push(p);
    }
    let spec = files.join("scene.json");
    std::fs::write(&spec, SPEC).expect("write spec");
    let server = Server::start(&dir.path().join("store"), &[]).await;
    let base = server.base.clone();
    call(move || {
        // No --scene: the scene is created from --spec, and its id and token printed.
        let mut args = vec![os("push"), os("--server"), os(&base), os("--spec")];
        args.push(spec.as_os_str());
        args.push(os("--time-step"));
        args.push(os("0.5"));
        args.extend(paths[..2].iter().map(|p| p.as_os_str()));
        let out = isoray(&args);
        let said = text(&out);
        assert!(out.status.success(), "{said}");
        let word_after = |key: &str| {
            said.lines()
                .find_map(|l| l.strip_prefix(key))
                .and_then(|r| r.split_whitespace().next())
                .unwrap_or_else(|| panic!("`{key}` in: {said}"))
                .to_string()
        };
        let id = word_after("created scene ");
        let token = word_after("write token ");
        let listed = steps(&base, &id);
        let listed = listed.as_array().expect("steps");
        assert_eq!(listed.len(), 2);
        for (k, s) in listed.iter().enumerate() {
            let payload: Vec<u8> = step_values(k)
                .iter()
                .flat_map(|v| v.to_le_bytes())
                .collect();
            assert_eq!(s["index"], k as u64);
            assert_eq!(s["time"], k as f64 * 0.5);
            assert_eq!(
                s["checksum"],
                format!("{:032x}", xxhash_rust::xxh3::xxh3_128(&payload))
            );
        }
        // More steps into the same scene, with its token.
        let out = isoray(&[
            os("push"),
            os("--server"),
            os(&base),
            os("--scene"),
            os(&id),
            os("--token"),
            os(&token),
            os("--start"),
            os("2"),
            paths[2].as_os_str(),
        ]);
        assert!(out.status.success(), "{}", text(&out));
        assert_eq!(steps(&base, &id).as_array().map(Vec::len), Some(3));
        // A wrong token is refused with the server's answer, and nothing is pushed.
        let out = isoray(&[
            os("push"),
            os("--server"),
            os(&base),
            os("--scene"),
            os(&id),
            os("--token"),
            os("wrong"),
            os("--start"),
            os("3"),
            paths[0].as_os_str(),
        ]);
        assert!(!out.status.success());
        assert!(text(&out).contains("403"), "{}", text(&out));
        // A .vtu that is not a VTK file is refused naming the file (good series: api::tets),
        // and mixing it with .npy steps is refused before anything is sent.
        let vtu = files.join("mesh_000.vtu");
        std::fs::write(&vtu, "<VTKFile/>").expect("write");
        let out = isoray(&[os("push"), os("--server"), os(&base), vtu.as_os_str()]);
        assert!(!out.status.success());
        assert!(text(&out).contains("mesh_000.vtu"), "{}", text(&out));
        let out = isoray(&[
            os("push"),
            os("--server"),
            os(&base),
            vtu.as_os_str(),
            paths[0].as_os_str(),
        ]);
        assert!(!out.status.success());
        assert!(text(&out).contains("not both"), "{}", text(&out));

        // The offline render of step 1 is the server's render of step 1, byte for byte.
        let png = files.join("offline.png");
        let out = isoray(&[
            os("render"),
            paths[1].as_os_str(),
            os("--spec"),
            spec.as_os_str(),
            os("--width"),
            os("64"),
            os("--height"),
            os("48"),
            os("--effects"),
            os(r#"{"shadows":true}"#),
            os("-o"),
            png.as_os_str(),
        ]);
        assert!(out.status.success(), "{}", text(&out));
        let offline = std::fs::read(&png).expect("the image was written");
        let r = Client::new(&base)
            .expect("url")
            .request(
                "POST",
                &format!("/api/v1/scenes/{id}/render"),
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"step":1,"width":64,"height":48,"effects":{"shadows":true}}"#),
            )
            .expect("render");
        assert_eq!(r.status, 200, "{}", r.text());
        assert_eq!(offline, r.body, "offline and server renders are identical");
        let img = image::load_from_memory(&offline).expect("a PNG").to_rgb8();
        assert!(
            crate::e2e::support::pixel_stddev(&img) > 5.0,
            "the image shows the balls"
        );

        // A demo, to JPEG; and a bad step file is refused with its location.
        let jpg = files.join("demo.jpg");
        let out = isoray(&[
            os("render"),
            os("--demo"),
            os("blobs"),
            os("--time"),
            os("1.5"),
            os("--width"),
            os("48"),
            os("--height"),
            os("32"),
            os("-o"),
            jpg.as_os_str(),
        ]);
        assert!(out.status.success(), "{}", text(&out));
        assert!(image::load_from_memory(&std::fs::read(&jpg).expect("jpg")).is_ok());
        let bad = files.join("bad.npy");
        let mut bytes = npy(&step_values(0), 3);
        let n = bytes.len();
        bytes[n - 4..].copy_from_slice(&f32::NAN.to_le_bytes());
        std::fs::write(&bad, &bytes).expect("write");
        let out = isoray(&[os("render"), bad.as_os_str(), os("-o"), png.as_os_str()]);
        assert!(!out.status.success());
        assert!(
            text(&out).contains(&format!("byte offset {}", n - 4)),
            "{}",
            text(&out)
        );
    })
    .await;
    server.stop().await;
}

#[test]
fn the_server_starts_with_the_default_data_dir_even_an_unusable_one() {
    // A fresh home: the store is created under ~/.local/share/isoray.
    let home = tempfile::tempdir().expect("temp dir");
    let p = Process::spawn(
        &[],
        &[("HOME", home.path().as_os_str()), ("XDG_DATA_HOME", os(""))],
    );
    let (id, _) = create(&p.base);
    p.kill();
    let scene_dir = home.path().join(".local/share/isoray/scenes").join(&id);
    assert!(
        scene_dir.join("scene.json").is_file(),
        "{}",
        scene_dir.display()
    );

    // A home that cannot hold a store: the server still serves its demos, without pushes.
    let file = home.path().join("not-a-directory");
    std::fs::write(&file, "x").expect("write");
    let p = Process::spawn(
        &[],
        &[("HOME", file.as_os_str()), ("XDG_DATA_HOME", os(""))],
    );
    let r = get(&p.base, "/api/v1/scenes");
    assert_eq!(r.status, 200);
    assert!(json(&r)["scenes"].as_array().is_some_and(|s| !s.is_empty()));
    let r = Client::new(&p.base)
        .expect("url")
        .request(
            "POST",
            "/api/v1/scenes",
            &[("Content-Type", "application/json")],
            Body::Bytes(br#"{"kind":"metaballs"}"#),
        )
        .expect("answer");
    assert_eq!(r.status, 503, "{}", r.text());
    assert_eq!(json(&r)["code"], "no_store");
    p.kill();
}

/// The binary the tests spawn has the features this test build has: `.ci/run` builds it with
/// `--all-features` and runs `cargo test --all-features`, and the tests must exercise that
/// binary, not a default-features one built behind its back.
#[test]
fn the_spawned_binary_has_the_features_of_this_test_build() {
    let home = tempfile::tempdir().expect("temp dir");
    let p = Process::start(home.path());
    let text = get(&p.base, "/metrics").text();
    p.kill();
    let info = text
        .lines()
        .find(|l| l.starts_with("isoray_build_info{"))
        .unwrap_or_else(|| panic!("no isoray_build_info in /metrics:\n{text}"));
    let want = format!("features=\"{}\"", isoray_server::metrics::features());
    assert!(
        info.contains(&want),
        "the spawned binary reports `{info}`; this test build has {want}"
    );
}
