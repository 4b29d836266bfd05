//! Slow headers: a client that sends a request's headers too slowly (or never finishes them)
//! is cut off after `--header-timeout-secs`, while one that finishes in time is answered and
//! other clients are served meanwhile (a slowloris cannot hold connections forever).

use super::*;
use std::io::{Read, Write};
use std::net::TcpStream;
use std::time::Instant;

/// Reads until the server closes the connection; what it sent, and when it closed.
fn read_until_closed(stream: &mut TcpStream, limit: Duration) -> (Vec<u8>, Option<Duration>) {
    let start = Instant::now();
    stream
        .set_read_timeout(Some(Duration::from_millis(100)))
        .expect("read timeout");
    let mut got = Vec::new();
    let mut buf = [0u8; 4096];
    while start.elapsed() < limit {
        match stream.read(&mut buf) {
            Ok(0) => return (got, Some(start.elapsed())),
            Ok(n) => got.extend_from_slice(&buf[..n]),
            Err(e)
                if matches!(
                    e.kind(),
                    std::io::ErrorKind::WouldBlock | std::io::ErrorKind::TimedOut
                ) => {}
            Err(_) => return (got, Some(start.elapsed())),
        }
    }
    (got, None)
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_client_sending_headers_too_slowly_is_cut_off() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--header-timeout-secs", "1"]).await;
    let addr = server.addr;
    call(move || {
        // Half a request line, then nothing: closed after about a second, with no answer.
        let mut slow = TcpStream::connect(addr).expect("connect");
        slow.write_all(b"GET /healthz HTTP/1.1\r\nHost: x\r\n")
            .expect("partial head");
        // Meanwhile another client is served.
        let r = get(&format!("http://{addr}"), "/healthz");
        assert_eq!(r.status, 200);
        let (got, closed_after) = read_until_closed(&mut slow, Duration::from_secs(10));
        let closed_after = closed_after.expect("the server closed the slow connection");
        assert!(
            closed_after >= Duration::from_millis(700) && closed_after < Duration::from_secs(5),
            "closed after {closed_after:?}, the timeout is 1 s"
        );
        assert!(
            got.is_empty(),
            "an unfinished request gets no answer: {:?}",
            String::from_utf8_lossy(&got)
        );

        // A connection that never sends a byte is closed as well.
        let mut silent = TcpStream::connect(addr).expect("connect");
        let (_, closed_after) = read_until_closed(&mut silent, Duration::from_secs(10));
        assert!(closed_after.is_some(), "a silent connection is closed");

        // Headers trickled in pieces that finish within the timeout are answered.
        let mut trickle = TcpStream::connect(addr).expect("connect");
        for piece in [
            &b"GET /healthz HT"[..],
            b"TP/1.1\r\nHost: x\r\n",
            b"Connection: close\r\n\r\n",
        ] {
            trickle.write_all(piece).expect("piece");
            std::thread::sleep(Duration::from_millis(200));
        }
        let (got, closed_after) = read_until_closed(&mut trickle, Duration::from_secs(10));
        let text = String::from_utf8_lossy(&got);
        assert!(closed_after.is_some(), "closed after answering");
        assert!(
            text.starts_with("HTTP/1.1 200") && text.ends_with("ok"),
            "answered: {text:?}"
        );
    })
    .await;
    // Graceful shutdown still completes with the accept loop in place.
    server.stop().await;
}
