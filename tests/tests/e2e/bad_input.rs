//! Every kind of bad input gets a clear error on the socket, and the session goes on.

use super::support::*;
use serde_json::json;

/// After an error, the session must still answer a valid input with a frame.
async fn assert_session_alive(ws: &mut Ws, input_id: u64) {
    send_json(
        ws,
        json!({"type": "isovalue", "input_id": input_id, "value": 0.45 + input_id as f64 * 1e-3}),
    )
    .await;
    let frame = frame_for_input(ws, input_id).await;
    assert_eq!(frame.header.input_id, input_id);
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn each_bad_input_is_named_and_the_session_goes_on() {
    let server = TestServer::start(&["--max-size", "4096"]).await;
    let (mut ws, info) = server.connect("blobs").await;
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 1.0})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 64, "height": 48}),
    )
    .await;
    frame_for_input(&mut ws, 2).await;

    // (message, expected code, a phrase the message must contain)
    let cases: &[(&str, &str, &str)] = &[
        ("{\"type\": \"camera\", ", "bad_json", "not valid JSON"),
        ("hello", "bad_json", "not valid JSON"),
        (
            r#"{"type":"teleport","input_id":10}"#,
            "unknown_type",
            "teleport",
        ),
        (r#"{"input_id":10}"#, "invalid_message", "no `type`"),
        (
            r#"{"type":"camera","input_id":11,"eye":[NaN,0,5],"target":[0,0,0],"up":[0,1,0]}"#,
            "bad_json",
            "not valid JSON",
        ),
        (
            r#"{"type":"camera","input_id":12,"eye":[0,0,1e999],"target":[0,0,0],"up":[0,1,0]}"#,
            "bad_json",
            "out of range",
        ),
        (
            r#"{"type":"camera","input_id":13,"eye":[0,null,5],"target":[0,0,0],"up":[0,1,0]}"#,
            "invalid_message",
            "eye[1]",
        ),
        (
            r#"{"type":"camera","input_id":14,"eye":[0,0,1e300],"target":[0,0,0],"up":[0,1,0]}"#,
            "invalid_value",
            "camera.eye[2]",
        ),
        (
            r#"{"type":"camera","input_id":15,"eye":[0,0,0],"target":[0,0,0],"up":[0,1,0]}"#,
            "invalid_value",
            "coincide",
        ),
        (
            r#"{"type":"resize","input_id":16,"width":0,"height":100}"#,
            "invalid_value",
            "at least 1",
        ),
        (
            r#"{"type":"resize","input_id":17,"width":100000,"height":100}"#,
            "invalid_value",
            "maximum 4096×4096",
        ),
        (
            r#"{"type":"resize","input_id":18,"width":-5,"height":100}"#,
            "invalid_message",
            "width",
        ),
        (
            r#"{"type":"isovalue","input_id":19,"value":-0.5}"#,
            "invalid_value",
            "outside the scene's range",
        ),
        (
            r#"{"type":"isovalue","input_id":20,"value":1000}"#,
            "invalid_value",
            "outside the scene's range",
        ),
        (
            r#"{"type":"isovalue","input_id":21,"value":"high"}"#,
            "invalid_message",
            "value",
        ),
        (
            r#"{"type":"isovalue","input_id":22,"value":0.5,"colour":"red"}"#,
            "invalid_message",
            "colour",
        ),
        (
            r#"{"type":"time","input_id":23,"time":-3}"#,
            "invalid_value",
            "time",
        ),
        (
            r#"{"type":"isovalue","input_id":9007199254740993,"value":0.5}"#,
            "invalid_value",
            "2^53",
        ),
        (
            r#"{"type":"ack","sequence":999999}"#,
            "invalid_value",
            "last frame sent",
        ),
        (r#"[1,2,3]"#, "invalid_message", "JSON object"),
    ];
    let range = info.isovalue_range;
    assert!(range[0] < 0.5 && 0.5 < range[1]);
    for (i, (text, code, phrase)) in cases.iter().enumerate() {
        send_text(&mut ws, text).await;
        let error = next_error(&mut ws).await;
        assert_eq!(&error.code, code, "{text} → {error:?}");
        assert!(
            error.message.contains(phrase),
            "{text}: message {:?} lacks {phrase:?}",
            error.message
        );
        assert_session_alive(&mut ws, 100 + i as u64).await;
    }

    // Binary input is not part of the protocol.
    use futures_util::SinkExt;
    ws.send(tokio_tungstenite::tungstenite::Message::Binary(
        vec![1u8, 2, 3].into(),
    ))
    .await
    .expect("send");
    assert_eq!(next_error(&mut ws).await.code, "unsupported");
    assert_session_alive(&mut ws, 500).await;

    let stats = server.state.sessions().snapshot();
    assert_eq!(stats.len(), 1);
    let rejected = stats[0]
        .1
        .inputs_rejected
        .load(std::sync::atomic::Ordering::Relaxed);
    assert_eq!(rejected, cases.len() as u64 + 1);
    drop(ws);
    server.stop().await;
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn garbage_never_takes_the_session_down() {
    let server = TestServer::start(&[]).await;
    let (mut ws, _) = server.connect("blobs").await;
    send_json(&mut ws, json!({"type": "time", "input_id": 1, "time": 0.5})).await;
    send_json(
        &mut ws,
        json!({"type": "resize", "input_id": 2, "width": 32, "height": 32}),
    )
    .await;
    frame_for_input(&mut ws, 2).await;
    // Deterministic mutations of valid messages: truncations, byte flips, odd numbers.
    let seeds = [
        r#"{"type":"camera","input_id":3,"eye":[1,2,3],"target":[0,0,0],"up":[0,1,0],"fov_y_deg":40}"#,
        r#"{"type":"resize","input_id":3,"width":64,"height":64}"#,
        r#"{"type":"isovalue","input_id":3,"value":0.5}"#,
        r#"{"type":"time","input_id":3,"time":1.5}"#,
    ];
    let mut x: u64 = 0x2545_F491_4F6C_DD1D;
    let mut sent = 0;
    for round in 0..400usize {
        x ^= x << 13;
        x ^= x >> 7;
        x ^= x << 17;
        let mut bytes = seeds[round % seeds.len()].as_bytes().to_vec();
        match x % 4 {
            0 => bytes.truncate((x >> 8) as usize % bytes.len()),
            1 => {
                let i = (x >> 8) as usize % bytes.len();
                bytes[i] = b"0-e9.,:\"[]{}nN"[(x >> 20) as usize % 14];
            }
            2 => {
                let i = (x >> 8) as usize % bytes.len();
                bytes.insert(i, b"-1e308"[(x >> 20) as usize % 6]);
            }
            _ => {}
        }
        if let Ok(text) = String::from_utf8(bytes) {
            send_text(&mut ws, &text).await;
            sent += 1;
        }
    }
    assert!(sent > 300);
    send_json(
        &mut ws,
        json!({"type": "isovalue", "input_id": 9999, "value": 0.6}),
    )
    .await;
    let frame = frame_for_input(&mut ws, 9999).await;
    assert_eq!(
        frame.header.input_id, 9999,
        "the session survived {sent} mutated messages"
    );
    drop(ws);
    server.stop().await;
}
