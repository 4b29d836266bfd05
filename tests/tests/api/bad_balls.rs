//! Bad metaball data in a pushed step — a NaN or infinite position, a zero or negative radius,
//! more balls than `--max-primitives` — is refused with a 4xx that names the offending ball
//! (row and column, or the JSON field with its index), and nothing stored changes. (The
//! issue's list, each case on its own; `push_errors` covers every other way a push is wrong.)

use super::*;

#[tokio::test]
async fn bad_balls_are_refused_naming_the_ball_and_nothing_changes() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--max-primitives", "4"]).await;
    let base = server.base.clone();
    call(move || {
        let (id, token) = create(&base);
        // Rows are x y z radius.
        let good = [0.0, 0.0, 0.0, 0.5, 1.0, 0.0, 0.0, 0.5, 2.0, 0.0, 0.0, 0.5];
        let r = push(&base, &id, "0", &token, NPY, &npy(&good, 4));
        assert_eq!(r.status, 201, "{}", r.text());
        let before = steps(&base, &id);
        let with = |row: usize, col: usize, v: f32| {
            let mut rows = good.to_vec();
            rows[row * 4 + col] = v;
            npy(&rows, 4)
        };
        let five_rows = npy(&[0.5; 20], 4);
        let cases: Vec<(&str, Vec<u8>, &str, &str)> = vec![
            ("NaN position", with(2, 0, f32::NAN), NPY, "[2][0]"),
            (
                "infinite position",
                with(1, 2, f32::INFINITY),
                NPY,
                "[1][2]",
            ),
            (
                "-infinite position",
                with(0, 1, f32::NEG_INFINITY),
                NPY,
                "[0][1]",
            ),
            ("zero radius", with(2, 3, 0.0), NPY, "[2][3]"),
            ("negative radius", with(1, 3, -0.25), NPY, "[1][3]"),
            ("more balls than the limit", five_rows, NPY, "shape"),
            (
                "JSON zero radius",
                br#"{"positions":[[0,0,0],[1,0,0]],"radii":[0.5,0]}"#.to_vec(),
                "application/json",
                "radii[1]",
            ),
            (
                "JSON negative radius",
                br#"{"positions":[[0,0,0],[1,0,0]],"radii":[-1,0.5]}"#.to_vec(),
                "application/json",
                "radii[0]",
            ),
            (
                "JSON position beyond f32",
                br#"{"positions":[[0,0,0],[1,1e300,0]]}"#.to_vec(),
                "application/json",
                "positions[1][1]",
            ),
        ];
        for (what, body, content_type, field) in cases {
            let r = push(&base, &id, "1", &token, content_type, &body);
            assert!(
                (400..500).contains(&r.status),
                "{what}: status {} {}",
                r.status,
                r.text()
            );
            let v = json(&r);
            assert_eq!(v["field"], field, "{what} names the ball: {v}");
            let message = v["message"].as_str().unwrap_or_default();
            assert!(!message.is_empty(), "{what}: a message for the user: {v}");
            if what == "more balls than the limit" {
                assert!(
                    message.contains('5') && message.contains('4'),
                    "{what}: the count and the limit: {message}"
                );
            }
        }
        assert_eq!(steps(&base, &id), before, "refused pushes stored nothing");
    })
    .await;
    server.stop().await;
}
