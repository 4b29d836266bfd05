//! Slow bodies: a client that trickles a push's body (a few bytes at a time, never stopping,
//! so no single read waits long) is answered 408 once `--push-timeout-secs` has passed since
//! the body began, for `.npy` steps and JSON bodies alike, and stores nothing; other clients
//! push and are served meanwhile. (limits.rs covers a body that stops altogether.)

use super::*;
use std::io::{Read, Write};
use std::net::TcpStream;

/// Sends `head` then `body` 64 bytes at a time until the server answers; returns the answer
/// and how many body bytes were sent. Fails if the whole body went out unanswered.
fn trickle(addr: std::net::SocketAddr, head: &str, body: &[u8]) -> (String, usize) {
    let mut s = TcpStream::connect(addr).expect("connect");
    s.set_read_timeout(Some(Duration::from_millis(50)))
        .expect("read timeout");
    s.write_all(head.as_bytes()).expect("head");
    let mut sent = 0;
    let mut answer = Vec::new();
    let mut buf = [0u8; 4096];
    loop {
        match s.read(&mut buf) {
            Ok(0) => break,
            Ok(n) => {
                answer.extend_from_slice(&buf[..n]);
                if String::from_utf8_lossy(&answer).contains("\"}") {
                    break;
                }
                continue;
            }
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => break,
        }
        if !answer.is_empty() {
            continue;
        }
        assert!(
            sent < body.len(),
            "the whole {}-byte body was sent without an answer",
            body.len()
        );
        let end = (sent + 64).min(body.len());
        if s.write_all(&body[sent..end]).is_err() {
            // The server answered and closed: read what it sent.
            s.set_read_timeout(Some(Duration::from_secs(10)))
                .expect("read timeout");
            let _ = s.read_to_end(&mut answer);
            break;
        }
        sent = end;
    }
    (String::from_utf8_lossy(&answer).into_owned(), sent)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_trickled_body_gets_408_while_others_are_served() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--push-timeout-secs", "1"]).await;
    let (base, addr, root) = (server.base.clone(), server.addr, dir.path().to_path_buf());
    call(move || {
        let (id, token) = create(&base);
        let before = store_snapshot(&root);
        // 64 KB at 64 bytes per 50 ms would take 50 s.
        let step = npy(&[0.25; 16_384], 4);
        let json_step = serde_json::json!({"positions": vec![[0.1, 0.2, 0.3]; 2000], "radii": vec![0.5; 2000]})
            .to_string()
            .into_bytes();
        let head = |ct: &str, len: usize, index: u32| {
            format!(
                "PUT /api/v1/scenes/{id}/steps/{index} HTTP/1.1\r\nHost: x\r\nContent-Type: {ct}\r\n\
                 Authorization: Bearer {token}\r\nContent-Length: {len}\r\n\r\n"
            )
        };
        let slow = {
            let (npy_head, json_head) = (head(NPY, step.len(), 0), head("application/json", json_step.len(), 1));
            let (step, json_step) = (step.clone(), json_step.clone());
            std::thread::spawn(move || {
                [
                    trickle(addr, &npy_head, &step),
                    trickle(addr, &json_head, &json_step),
                ]
            })
        };
        // Meanwhile other clients push and read.
        let r = push(&base, &id, "5", &token, NPY, &npy(&[0.5; 400], 4));
        assert_eq!(r.status, 201, "{}", r.text());
        assert_eq!(get(&base, "/healthz").status, 200);
        for ((answer, sent), total) in slow.join().expect("no panic").into_iter().zip([step.len(), json_step.len()]) {
            let status = answer.lines().next().unwrap_or("");
            println!("trickled {sent} of {total} bytes, then: {status}");
            assert!(status.starts_with("HTTP/1.1 408"), "408 for a trickled body: {answer}");
            assert!(answer.contains("\"code\":\"timeout\""), "{answer}");
            assert!(answer.contains("--push-timeout-secs"), "{answer}");
            assert!(sent < total, "answered before the body was complete");
        }
        // Only the fast push was stored; no temporary file is left.
        let after = store_snapshot(&root);
        let added: Vec<&String> = after.keys().filter(|k| !before.contains_key(*k)).collect();
        assert!(added.iter().all(|k| k.contains("steps")), "{added:?}");
        let listed: Vec<u64> = steps(&base, &id)
            .as_array()
            .expect("steps")
            .iter()
            .map(|s| s["index"].as_u64().expect("index"))
            .collect();
        assert_eq!(listed, [5], "the trickled steps are not stored");
        assert!(temp_files(&root).is_empty(), "no temporary file left");
    })
    .await;
    server.stop().await;
}
