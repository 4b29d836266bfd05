//! A stored scene rendered at a time (`POST .../render` with `time`): the step a viewer's time
//! input shows, the latest at or before it (the first before any), as `step` would name it;
//! `time` and `step` together are refused naming `time`.

use super::tets::post_json;
use super::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_stored_scene_at_a_time_is_the_step_a_viewer_sees_then() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    call(move || {
        let (id, token) = create(&base);
        // One ball moving across the view: steps at 2, 5 and 10 s.
        for (index, (x, time)) in [(-1.0f32, 2.0), (0.0, 5.0), (1.0, 10.0)].iter().enumerate() {
            let path = format!("{index}?time={time}");
            let r = push(&base, &id, &path, &token, NPY, &npy(&[*x, 0.0, 0.0], 3));
            assert!(r.status == 200 || r.status == 201, "{}", r.text());
        }
        let steps: Vec<Vec<u8>> = (0..3).map(|i| render_png(&base, &id, i)).collect();
        assert!(
            steps[0] != steps[1] && steps[1] != steps[2],
            "the steps differ"
        );
        let at = |time: &str| {
            let body = format!(r#"{{"time":{time},"width":48,"height":36}}"#);
            post_json(&base, &format!("/api/v1/scenes/{id}/render"), &body)
        };
        for (time, step) in [
            ("0", 0),
            ("2", 0),
            ("4.9", 0),
            ("5", 1),
            ("7.5", 1),
            ("1e9", 2),
        ] {
            let r = at(time);
            assert_eq!(r.status, 200, "{time}: {}", r.text());
            assert!(r.body == steps[step], "time {time}: step {step}'s image");
        }
        let both = r#"{"time":5,"step":0,"width":48,"height":36}"#;
        let r = post_json(&base, &format!("/api/v1/scenes/{id}/render"), both);
        assert_eq!(r.status, 422, "{}", r.text());
        assert_eq!(json(&r)["field"], "time", "{}", r.text());
    })
    .await;
    server.stop().await;
}
