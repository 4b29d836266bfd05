//! Request limits: writes per client are rate limited (reads are not), oversized headers are
//! refused, and a push whose body arrives too slowly is abandoned with 408, storing nothing.

use super::*;
use std::io::{Read, Write};
use std::time::Duration;

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn writes_are_rate_limited_per_client_and_reads_are_not() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--write-rate", "0.01", "--write-burst", "3"]).await;
    let base = server.base.clone();
    call(move || {
        let (id, token) = create(&base);
        let body = npy(&[0.0, 0.0, 0.0], 3);
        assert_eq!(push(&base, &id, "0", &token, NPY, &body).status, 201);
        assert_eq!(push(&base, &id, "1", &token, NPY, &body).status, 201);
        let r = push(&base, &id, "2", &token, NPY, &body);
        assert_eq!(
            r.status,
            429,
            "the fourth write is over the burst: {}",
            r.text()
        );
        let v = json(&r);
        assert_eq!(v["code"], "rate_limited");
        assert!(
            v["message"]
                .as_str()
                .is_some_and(|m| m.contains("retry in")),
            "{v}"
        );
        for _ in 0..10 {
            assert_eq!(
                get(&base, "/api/v1/scenes").status,
                200,
                "reads are not limited"
            );
        }
        assert_eq!(steps(&base, &id).as_array().map(Vec::len), Some(2));
    })
    .await;
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn oversized_headers_are_refused() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &[]).await;
    let addr = server.addr;
    let status = call(move || {
        let mut s = std::net::TcpStream::connect(addr).expect("connect");
        s.set_read_timeout(Some(Duration::from_secs(20)))
            .expect("timeout");
        let big = "a".repeat(1 << 20);
        let _ = s.write_all(
            format!("GET /api/v1/scenes HTTP/1.1\r\nHost: x\r\nX-Big: {big}\r\n\r\n").as_bytes(),
        );
        let mut answer = Vec::new();
        let _ = s.read_to_end(&mut answer);
        String::from_utf8_lossy(&answer)
            .lines()
            .next()
            .unwrap_or("")
            .to_string()
    })
    .await;
    assert!(
        status.starts_with("HTTP/1.1 431"),
        "a 1 MiB header gets 431 Request Header Fields Too Large: `{status}`"
    );
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_push_that_arrives_too_slowly_is_abandoned() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--push-timeout-secs", "1"]).await;
    let base = server.base.clone();
    let addr = server.addr;
    let root = dir.path().to_path_buf();
    call(move || {
        let (id, token) = create(&base);
        let before = store_snapshot(&root);
        let body = npy(&[0.5; 3000], 3);
        let mut s = std::net::TcpStream::connect(addr).expect("connect");
        s.set_read_timeout(Some(Duration::from_secs(20)))
            .expect("timeout");
        let head = format!(
            "PUT /api/v1/scenes/{id}/steps/0 HTTP/1.1\r\nHost: x\r\nContent-Type: {NPY}\r\n\
             Authorization: Bearer {token}\r\nContent-Length: {}\r\n\r\n",
            body.len()
        );
        s.write_all(head.as_bytes()).expect("head");
        s.write_all(&body[..body.len() / 2]).expect("half the body");
        // ... and then nothing: the server gives up after --push-timeout-secs.
        let mut answer = Vec::new();
        let _ = s.read_to_end(&mut answer);
        let answer = String::from_utf8_lossy(&answer);
        assert!(
            answer.starts_with("HTTP/1.1 408"),
            "408 Request Timeout: {answer}"
        );
        assert!(answer.contains("\"code\":\"timeout\""), "{answer}");
        assert_eq!(store_snapshot(&root), before, "nothing stored");
        assert!(temp_files(&root).is_empty(), "no temporary file left");
    })
    .await;
    server.stop().await;
}

/// `--max-scenes` caps the stored scenes; one more is refused with 409 naming the limit, and
/// deleting one makes room again.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn the_number_of_scenes_is_limited() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--max-scenes", "2"]).await;
    let base = server.base.clone();
    call(move || {
        let (first, token) = create(&base);
        create(&base);
        let c = Client::new(&base).expect("url");
        let post = || {
            c.request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"kind":"metaballs"}"#),
            )
            .expect("answer")
        };
        let r = post();
        assert_eq!(r.status, 409, "a third scene: {}", r.text());
        assert_eq!(json(&r)["code"], "too_many_scenes");
        assert!(r.text().contains("--max-scenes"), "{}", r.text());
        let auth = format!("Bearer {token}");
        let r = c
            .request(
                "DELETE",
                &format!("/api/v1/scenes/{first}"),
                &[("Authorization", &auth)],
                Body::Empty,
            )
            .expect("delete");
        assert_eq!(r.status, 204);
        assert_eq!(post().status, 201, "room again after a delete");
    })
    .await;
    server.stop().await;
}
