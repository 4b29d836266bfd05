//! Crash safety: the `isoray` binary, SIGKILLed in the middle of a large push, restarts with
//! every completed step intact (checksums verified, data byte for byte), without the
//! interrupted step, and with no temporary file left in the store.

use super::*;
use std::io::Write;
use std::time::{Duration, Instant};

/// `rows × 4` f32 values, different for each `seed`.
fn balls(rows: usize, seed: u32) -> Vec<f32> {
    let mut v = Vec::with_capacity(rows * 4);
    for i in 0..rows as u32 {
        let h = i
            .wrapping_mul(2_654_435_761)
            .wrapping_add(seed.wrapping_mul(97));
        let u = |k: u32| ((h.rotate_left(k * 8) % 10_000) as f32) / 10_000.0;
        v.extend_from_slice(&[
            4.0 * u(0) - 2.0,
            4.0 * u(1) - 2.0,
            4.0 * u(2) - 2.0,
            0.05 + 0.1 * u(3),
        ]);
    }
    v
}

fn payload(values: &[f32]) -> Vec<u8> {
    values.iter().flat_map(|v| v.to_le_bytes()).collect()
}

#[test]
fn sigkill_during_a_push_loses_only_that_push() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Process::start(dir.path());
    let (id, token) = create(&server.base);
    let mut sent = Vec::new();
    for index in 0..3u32 {
        let values = balls(20_000, index);
        let r = push(
            &server.base,
            &id,
            &index.to_string(),
            &token,
            NPY,
            &npy(&values, 4),
        );
        assert_eq!(r.status, 201, "step {index}: {}", r.text());
        let checksum = json(&r)["step"]["checksum"]
            .as_str()
            .expect("checksum")
            .to_string();
        let p = payload(&values);
        assert_eq!(
            checksum,
            format!("{:032x}", xxhash_rust::xxh3::xxh3_128(&p)),
            "the checksum is XXH3-128 of the stored values"
        );
        sent.push((index, p, checksum));
    }
    let before = steps(&server.base, &id);

    // A 16 MB push: send half of it, wait until the server is writing it, then SIGKILL.
    let big = npy(&balls(1_000_000, 7), 4);
    let addr = server.base.trim_start_matches("http://").to_string();
    let mut stream = std::net::TcpStream::connect(&addr).expect("connect");
    let head = format!(
        "PUT /api/v1/scenes/{id}/steps/3 HTTP/1.1\r\nHost: {addr}\r\nContent-Type: {NPY}\r\n\
         Authorization: Bearer {token}\r\nContent-Length: {}\r\n\r\n",
        big.len()
    );
    stream.write_all(head.as_bytes()).expect("head");
    stream.write_all(&big[..big.len() / 2]).expect("first half");
    stream.flush().expect("flush");
    let steps_dir = dir.path().join("scenes").join(&id).join("steps");
    let deadline = Instant::now() + Duration::from_secs(60);
    let in_progress = loop {
        let partial = temp_files(&steps_dir)
            .into_iter()
            .find(|p| std::fs::metadata(p).is_ok_and(|m| m.len() > 1 << 20));
        if let Some(p) = partial {
            break p;
        }
        assert!(
            Instant::now() < deadline,
            "the server never started writing the push"
        );
        std::thread::sleep(Duration::from_millis(10));
    };
    server.kill();
    drop(stream);
    assert!(
        in_progress.exists(),
        "the kill left the interrupted push's temporary file behind (so the restart has work to do)"
    );

    let server = Process::start(dir.path());
    let after = steps(&server.base, &id);
    assert_eq!(
        after, before,
        "every completed step is back, with the same checksums"
    );
    let r = get(&server.base, &format!("/api/v1/scenes/{id}/steps/3"));
    assert_eq!(
        r.status,
        404,
        "the interrupted step is absent: {}",
        r.text()
    );
    for (index, p, checksum) in &sent {
        let r = get(
            &server.base,
            &format!("/api/v1/scenes/{id}/steps/{index}/data"),
        );
        assert_eq!(r.status, 200);
        let header_len = npy_header_f32(20_000, 4).len();
        assert_eq!(
            &r.body[header_len..],
            &p[..],
            "step {index}'s values, byte for byte"
        );
        assert_eq!(
            format!(
                "{:032x}",
                xxhash_rust::xxh3::xxh3_128(&r.body[header_len..])
            ),
            *checksum
        );
    }
    let leftovers = temp_files(dir.path());
    assert!(
        leftovers.is_empty(),
        "no temporary files after the restart: {leftovers:?}"
    );
    let corrupt: Vec<_> = walk(dir.path())
        .into_iter()
        .filter(|p| p.extension().is_some_and(|e| e == "corrupt"))
        .collect();
    assert!(corrupt.is_empty(), "nothing was quarantined: {corrupt:?}");

    // The store still takes pushes after the crash, at the interrupted index too.
    let r = push(
        &server.base,
        &id,
        "3",
        &token,
        NPY,
        &npy(&balls(1000, 3), 4),
    );
    assert_eq!(r.status, 201, "{}", r.text());
    server.kill();
}
