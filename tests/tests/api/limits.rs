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

/// `/render` is rate limited per client with `Retry-After`; behind a trusted proxy each
/// forwarded client has its own allowance, and an untrusted peer's `X-Forwarded-For` is
/// ignored (it cannot buy itself a fresh allowance by naming another address).
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn renders_are_limited_per_client_and_forwarded_addresses_count_only_from_trusted_proxies() {
    let render = |base: &str, id: &str, forwarded: &str| {
        Client::new(base)
            .expect("url")
            .request(
                "POST",
                &format!("/api/v1/scenes/{id}/render"),
                &[
                    ("Content-Type", "application/json"),
                    ("X-Forwarded-For", forwarded),
                ],
                Body::Bytes(br#"{"width": 8, "height": 8}"#),
            )
            .expect("answer")
    };
    let limits = ["--render-rate", "0.01", "--render-burst", "2"];
    let scene = |base: &str| {
        let (id, token) = create(base);
        let r = push(base, &id, "0", &token, NPY, &npy(&[0.0, 0.0, 0.0], 3));
        assert_eq!(r.status, 201, "{}", r.text());
        id
    };

    // Loopback is a trusted proxy: two forwarded clients, two allowances.
    let dir = tempfile::tempdir().expect("temp dir");
    let mut args = limits.to_vec();
    args.extend(["--trusted-proxy", "127.0.0.1,::1"]);
    let server = Server::start(dir.path(), &args).await;
    let base = server.base.clone();
    call(move || {
        let id = scene(&base);
        let a = "198.51.100.7";
        let b = "203.0.113.9";
        for i in 0..2 {
            let r = render(&base, &id, a);
            assert_eq!(r.status, 200, "render {i} of client a: {}", r.text());
        }
        let r = render(&base, &id, a);
        assert_eq!(r.status, 429, "client a is over its burst: {}", r.text());
        assert_eq!(json(&r)["code"], "rate_limited");
        let retry: u64 = r
            .header("retry-after")
            .and_then(|v| v.parse().ok())
            .expect("a Retry-After in seconds");
        assert!((1..=100).contains(&retry), "at 0.01 per second: {retry}");
        // A client prepending an address of its own to what the proxy appends changes nothing.
        let r = render(&base, &id, &format!("192.0.2.1, {a}"));
        assert_eq!(
            r.status,
            429,
            "a spoofed hop left of the proxy's: {}",
            r.text()
        );
        let r = render(&base, &id, b);
        assert_eq!(
            r.status,
            200,
            "client b has its own allowance: {}",
            r.text()
        );
    })
    .await;
    server.stop().await;

    // No trusted proxy: the header is ignored and every request is the peer's.
    let dir = tempfile::tempdir().expect("temp dir");
    let mut args = limits.to_vec();
    args.extend(["--trusted-proxy", "10.9.9.9"]);
    let server = Server::start(dir.path(), &args).await;
    let base = server.base.clone();
    call(move || {
        let id = scene(&base);
        assert_eq!(render(&base, &id, "198.51.100.7").status, 200);
        assert_eq!(render(&base, &id, "203.0.113.9").status, 200);
        let r = render(&base, &id, "192.0.2.55");
        assert_eq!(
            r.status,
            429,
            "an untrusted peer's X-Forwarded-For is not a new client: {}",
            r.text()
        );
        assert!(r.header("retry-after").is_some());
    })
    .await;
    server.stop().await;
}
