//! Scenes and steps survive a clean restart; a kind's scene without its data (a surfel scene
//! without its object), an unknown kind and another kind's settings are refused with the
//! field named; a one-shot render
//! answers a PNG.

use super::*;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn scenes_without_their_kind_are_refused_and_steps_survive_a_restart() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    let (id, before) = call(move || {
        let c = Client::new(&base).expect("url");
        let r = c
            .request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"kind":"surfels"}"#),
            )
            .expect("answer");
        // Every value fits the schema, but a surfel scene needs its object: a 422.
        assert_eq!(r.status, 422, "{}", r.text());
        assert_eq!(json(&r)["field"], "surfels");
        let r = c
            .request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"kind":"voxels"}"#),
            )
            .expect("answer");
        assert_eq!(r.status, 400, "not a kind of the schema: {}", r.text());
        assert!(r.text().contains("kind"), "{}", r.text());
        // Another kind's settings beside a kind are refused, not ignored unchecked.
        let r = c
            .request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"kind":"metaballs","tets":{"color_range":[0,1]}}"#),
            )
            .expect("answer");
        assert_eq!(r.status, 422, "{}", r.text());
        assert_eq!(json(&r)["field"], "tets");
        let (id, token) = create(&base);
        let js = br#"{"positions":[[0,0,0],[0.4,0,0]],"radii":[0.5,0.5]}"#;
        assert_eq!(
            push(&base, &id, "0", &token, "application/json", js).status,
            201
        );
        assert_eq!(
            push(&base, &id, "1", &token, NPY, &npy(&[0.1, 0.0, 0.0, 0.6], 4)).status,
            201
        );
        let r = c
            .request(
                "POST",
                &format!("/api/v1/scenes/{id}/render"),
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"width":32,"height":24}"#),
            )
            .expect("render");
        assert_eq!(r.status, 200);
        assert!(r.body.starts_with(b"\x89PNG"), "a PNG");
        let listed = steps(&base, &id);
        assert_eq!(listed.as_array().map(Vec::len), Some(2));
        (id, listed)
    })
    .await;
    server.stop().await;
    let server = Server::start(dir.path(), &[]).await;
    let base = server.base.clone();
    let after = call(move || steps(&base, &id)).await;
    assert_eq!(after, before, "every step reloaded with the same checksum");
    server.stop().await;
}
