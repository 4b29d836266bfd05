//! A viewer's look through the render endpoint (the same `effects` fields the websocket takes):
//! a colour map recolours a tet scene's isosurfaces, a clip box and an added isosurface change
//! the image, a look that changes nothing leaves the bytes as they were, bad values are 400s
//! naming the field, a surfel scene (no field) refuses them, and a scene description refuses
//! them; `isoray render --effects` draws the same look byte for byte. The scene description
//! endpoint reports the scene's bounds.

use super::tets::post_json;
use super::*;

/// PNG bytes to RGB pixels.
fn pixels(body: &[u8]) -> image::RgbImage {
    image::load_from_memory(body).expect("PNG").to_rgb8()
}

/// Share of pixels whose channels differ by more than 40 levels (clearly coloured).
fn coloured(img: &image::RgbImage) -> f64 {
    let n = img
        .pixels()
        .filter(|p| {
            let (lo, hi) = (p.0.iter().min(), p.0.iter().max());
            matches!((lo, hi), (Some(lo), Some(hi)) if hi - lo > 40)
        })
        .count();
    n as f64 / (img.width() * img.height()) as f64
}

fn render(base: &str, effects: &str) -> Response {
    let body = format!(r#"{{"time":0,"width":80,"height":60,"effects":{effects}}}"#);
    post_json(base, "/api/v1/scenes/tets-gyroid/render", &body)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_viewers_look_through_the_render_endpoint_and_the_scene_bounds() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    let offline = dir.path().join("look.png");
    call(move || {
        for id in ["tets-gyroid", "blobs"] {
            let scene = json(&get(&base, &format!("/api/v1/scenes/{id}")));
            let b = &scene["bounds"];
            for k in 0..3 {
                let (lo, hi) = (b["min"][k].as_f64(), b["max"][k].as_f64());
                assert!(
                    matches!((lo, hi), (Some(lo), Some(hi)) if lo < hi),
                    "{id}: {scene}"
                );
            }
        }
        // The list does not compute bounds (that needs every scene's state).
        let list = json(&get(&base, "/api/v1/scenes"));
        assert!(list["scenes"][0].get("bounds").is_none(), "{list}");

        let plain = render(&base, "{}");
        assert_eq!(plain.status, 200, "{}", plain.text());
        // A look that changes nothing: byte for byte the same image.
        let none = render(&base, r#"{"color_map":{"name":"none"}}"#);
        assert_eq!(none.body, plain.body, "no map, no change");

        let own = pixels(&plain.body);
        let grey = pixels(&render(&base, r#"{"color_map":{"name":"grey"}}"#).body);
        assert!(coloured(&own) > 0.05, "the scene's own colours");
        assert!(
            coloured(&grey) < 0.005,
            "a grey map leaves no coloured pixel ({})",
            coloured(&grey)
        );
        let viridis = render(
            &base,
            r#"{"color_map":{"name":"viridis","range":[-0.05,2]}}"#,
        );
        assert_ne!(viridis.body, plain.body);

        let clipped = render(
            &base,
            r#"{"clip_box":true,"clip":{"min":[-5,-5,0],"max":[5,5,5]}}"#,
        );
        assert_eq!(clipped.status, 200, "{}", clipped.text());
        assert_ne!(clipped.body, plain.body, "the clip box cuts");
        let added = render(
            &base,
            r#"{"isosurfaces":true,"surfaces":[{"isovalue":-0.6,"color":[0,1,0]}]}"#,
        );
        assert_eq!(added.status, 200, "{}", added.text());
        assert_ne!(added.body, plain.body, "the added isosurface shows");

        // Outside the schema: 400; a rule between values (min below max, an isovalue inside
        // the scene's range): 422.
        for (effects, field, status) in [
            (r#"{"color_map":{"name":"jet"}}"#, "effects.color_map", 400),
            (
                r#"{"clip":{"min":[1,0,0],"max":[0,1,1]}}"#,
                "effects.clip",
                422,
            ),
            (
                r#"{"surfaces":[{"isovalue":1e9}]}"#,
                "effects.surfaces",
                422,
            ),
            (
                r#"{"surfaces":[{"isovalue":0.1,"opacity":2}]}"#,
                "effects.surfaces",
                400,
            ),
            // Drawn like a surface of the scene's own past those it has.
            (
                r#"{"surfaces":[{"isovalue":0.1,"scene_surface":9}]}"#,
                "effects.surfaces",
                422,
            ),
        ] {
            let r = render(&base, effects);
            assert_eq!(r.status, status, "{effects}: {}", r.text());
            assert_eq!(json(&r)["field"], field, "{effects}: {}", r.text());
        }

        // `isoray render --effects` takes the same look (the scene's effects and the viewer's
        // colour map and clip box), byte for byte.
        let look = r#"{"color_map":{"name":"viridis","range":[-0.05,2]},"clip_box":true,"clip":{"min":[0,-3,0],"max":[3,3,3]}}"#;
        let served = render(&base, look);
        assert_eq!(served.status, 200, "{}", served.text());
        assert_ne!(served.body, render(&base, "{}").body, "the look changes the image");
        let out = Command::new(isoray_binary())
            .args(["render", "--demo", "tets-gyroid", "--time", "0", "--width", "80"])
            .args(["--height", "60", "--effects", look, "-o"])
            .arg(&offline)
            .output()
            .expect("isoray runs");
        assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
        assert!(
            std::fs::read(&offline).expect("written") == served.body,
            "isoray render --effects draws the served look"
        );

        // A surfel scene has no field: an isovalue, further isosurfaces and a colour map are
        // 422s naming them; its effects and the look's resets render.
        let surfel = |body: &str| post_json(&base, "/api/v1/scenes/surfel-heads/render", body);
        for (body, field) in [
            (r#"{"width":40,"height":30,"isovalue":0.5}"#, "isovalue"),
            (
                r#"{"width":40,"height":30,"effects":{"surfaces":[{"isovalue":0.5}]}}"#,
                "effects.surfaces",
            ),
            (
                r#"{"width":40,"height":30,"effects":{"color_map":{"name":"grey"}}}"#,
                "effects.color_map",
            ),
        ] {
            let r = surfel(body);
            assert_eq!(r.status, 422, "{body}: {}", r.text());
            assert_eq!(json(&r)["field"], field, "{body}: {}", r.text());
            assert!(r.text().contains("surfel"), "{body}: {}", r.text());
        }
        let r = surfel(
            r#"{"width":40,"height":30,"effects":{"shadows":true,"surfaces":[],"color_map":{"name":"none"}}}"#,
        );
        assert_eq!(r.status, 200, "{}", r.text());

        // A scene description has its own clip box and isosurfaces, and no colour map.
        let r = post_json(
            &base,
            "/api/v1/scenes",
            r#"{"kind":"metaballs","lighting":{"effects":{"color_map":{"name":"grey"}}}}"#,
        );
        assert_eq!(r.status, 400, "{}", r.text());
        assert_eq!(
            json(&r)["field"],
            "lighting.effects.color_map",
            "{}",
            r.text()
        );
    })
    .await;
    server.stop().await;
}

/// An isovalue and a time are checked alike by the render endpoint and `isoray render` (and
/// the websocket, `e2e::bad_input`): a tet scene's negative isovalue renders the same image on
/// both, one outside the scene's range is refused by both naming the range, a surfel scene,
/// which has no field, refuses any; a time past 1e9 s is refused by both and by the histogram
/// (offline it used to panic in the gyroid's generator, its phase overflowing). A thread
/// count past `MAX_THREADS` is refused offline too, and a bad camera flag is named as the flag.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn an_isovalue_and_a_time_are_checked_alike_by_the_endpoint_and_the_cli() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    let offline = dir.path().join("iso.png");
    call(move || {
        let cli = |demo: &str, args: &[&str]| {
            let out = Command::new(isoray_binary())
                .args(["render", "--demo", demo, "--width", "80", "--height", "60"])
                .args(args)
                .arg("-o")
                .arg(&offline)
                .output()
                .expect("isoray runs");
            match out.status.success() {
                true => Ok(std::fs::read(&offline).expect("written")),
                false => Err(String::from_utf8_lossy(&out.stderr).into_owned()),
            }
        };
        let served = post_json(
            &base,
            "/api/v1/scenes/tets-gyroid/render",
            r#"{"width":80,"height":60,"isovalue":-0.3}"#,
        );
        assert_eq!(served.status, 200, "{}", served.text());
        assert!(
            cli("tets-gyroid", &["--isovalue", "-0.3"]) == Ok(served.body),
            "the same image offline"
        );

        let r = post_json(
            &base,
            "/api/v1/scenes/tets-gyroid/render",
            r#"{"width":80,"height":60,"isovalue":1e6}"#,
        );
        assert_eq!(r.status, 422, "{}", r.text());
        assert_eq!(json(&r)["field"], "isovalue", "{}", r.text());
        assert!(
            r.text().contains("outside the scene's range"),
            "{}",
            r.text()
        );
        let refused = cli("tets-gyroid", &["--isovalue", "1e6"]).expect_err("out of range");
        assert!(refused.contains("outside the scene's range"), "{refused}");
        let refused = cli("surfel-heads", &["--isovalue", "0.5"]).expect_err("no field");
        assert!(refused.contains("no scalar field"), "{refused}");

        let r = post_json(
            &base,
            "/api/v1/scenes/tets-gyroid/render",
            r#"{"width":80,"height":60,"time":1e300}"#,
        );
        assert_eq!(r.status, 400, "{}", r.text());
        assert_eq!(json(&r)["field"], "time", "{}", r.text());
        let r = get(&base, "/api/v1/scenes/tets-gyroid/histogram?time=2e9");
        assert_eq!(r.status, 400, "{}", r.text());
        assert_eq!(json(&r)["field"], "time", "{}", r.text());
        assert_eq!(
            get(&base, "/api/v1/scenes/tets-gyroid/histogram?time=1e9").status,
            200
        );
        let refused = cli("tets-gyroid", &["--time", "1e300"]).expect_err("too late");
        assert!(
            refused.contains("[0, 1e9]") && !refused.contains("panicked"),
            "{refused}"
        );
        // The camera's flags are named as flags.
        let refused = cli("blobs", &["--fov", "0"]).expect_err("no view");
        assert!(refused.contains("--fov 0 must be in [1, 170]"), "{refused}");
        // A mistyped thread count is refused before a pool of that many threads is started.
        let refused = cli("blobs", &["--threads", "100000"]).expect_err("too many");
        assert!(
            refused.contains("--threads 100000 must be at most"),
            "{refused}"
        );
    })
    .await;
    server.stop().await;
}
