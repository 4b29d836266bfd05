//! Tokens: a scene's write token or the admin token may push and delete, nothing else may;
//! with `--admin-token`, only the admin creates scenes; with `--view-token`, viewing
//! (listing, fetching, rendering, streaming) needs a token too.

use super::*;

const VIEW: &str = "view-token-0123456789";
const ADMIN: &str = "admin-token-0123456789";

fn with_auth(base: &str, method: &str, path: &str, token: Option<&str>) -> Response {
    let auth = token.map(|t| format!("Bearer {t}"));
    let mut headers = vec![("Content-Type", "application/json")];
    if let Some(a) = &auth {
        headers.push(("Authorization", a.as_str()));
    }
    let body: &[u8] = if method == "POST" { b"{}" } else { b"" };
    Client::new(base)
        .expect("url")
        .request(method, path, &headers, Body::Bytes(body))
        .expect("answer")
}

fn create_as_admin(base: &str) -> (String, String) {
    let r = Client::new(base)
        .expect("url")
        .request(
            "POST",
            "/api/v1/scenes",
            &[
                ("Content-Type", "application/json"),
                ("Authorization", &format!("Bearer {ADMIN}")),
            ],
            Body::Bytes(br#"{"kind":"metaballs"}"#),
        )
        .expect("create");
    assert_eq!(r.status, 201, "the admin creates: {}", r.text());
    let v = json(&r);
    (
        v["scene"]["id"].as_str().expect("id").into(),
        v["write_token"].as_str().expect("token").into(),
    )
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn write_and_view_tokens_are_enforced_everywhere() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--view-token", VIEW, "--admin-token", ADMIN]).await;
    let base = server.base.clone();
    let addr = server.addr;
    let id = call(move || {
        // Creating needs the admin token: none is 401, any other token 403, and neither
        // leaves a scene behind.
        let r = with_auth(&base, "POST", "/api/v1/scenes", None);
        assert_eq!(r.status, 401, "create without a token: {}", r.text());
        assert_eq!(json(&r)["field"], "Authorization");
        let r = with_auth(&base, "POST", "/api/v1/scenes", Some(VIEW));
        assert_eq!(
            r.status,
            403,
            "the view token does not create: {}",
            r.text()
        );
        let listed = json(&with_auth(&base, "GET", "/api/v1/scenes", Some(VIEW)));
        let stored = listed["scenes"]
            .as_array()
            .expect("scenes")
            .iter()
            .filter(|s| s["source"] == "stored")
            .count();
        assert_eq!(stored, 0, "refused creations stored nothing: {listed}");
        let (id, token) = create_as_admin(&base);
        let (other_id, other_token) = create_as_admin(&base);
        let step = npy(&[0.0, 0.0, 0.0], 3);
        assert_eq!(push(&base, &id, "0", &token, NPY, &step).status, 201);
        assert_eq!(
            push(&base, &id, "1", ADMIN, NPY, &step).status,
            201,
            "admin pushes"
        );
        let r = push(&base, &id, "2", &other_token, NPY, &step);
        assert_eq!(
            r.status,
            403,
            "another scene's token does not: {}",
            r.text()
        );
        let r = push(&base, &id, "2", VIEW, NPY, &step);
        assert_eq!(r.status, 403, "the view token does not write: {}", r.text());

        for path in [
            "/api/v1/scenes".to_string(),
            format!("/api/v1/scenes/{id}"),
            format!("/api/v1/scenes/{id}/steps"),
            format!("/api/v1/scenes/{id}/steps/0"),
            format!("/api/v1/scenes/{id}/steps/0/data"),
        ] {
            let r = with_auth(&base, "GET", &path, None);
            assert_eq!(r.status, 401, "GET {path} without a token: {}", r.text());
            assert_eq!(json(&r)["field"], "Authorization");
            assert_eq!(
                with_auth(&base, "GET", &path, Some("nope")).status,
                403,
                "{path}"
            );
            for ok in [VIEW, ADMIN] {
                assert_eq!(
                    with_auth(&base, "GET", &path, Some(ok)).status,
                    200,
                    "{path}"
                );
            }
        }
        let render = format!("/api/v1/scenes/{id}/render");
        assert_eq!(with_auth(&base, "POST", &render, None).status, 401);
        let r = with_auth(&base, "POST", &render, Some(&token));
        assert_eq!(
            r.status,
            200,
            "the scene's write token also views: {}",
            r.text()
        );

        let r = with_auth(
            &base,
            "DELETE",
            &format!("/api/v1/scenes/{id}/steps/1"),
            Some(&other_token),
        );
        assert_eq!(r.status, 403);
        let r = with_auth(
            &base,
            "DELETE",
            &format!("/api/v1/scenes/{id}/steps/1"),
            Some(ADMIN),
        );
        assert_eq!(r.status, 204, "{}", r.text());
        let r = with_auth(
            &base,
            "DELETE",
            &format!("/api/v1/scenes/{other_id}"),
            Some(&other_token),
        );
        assert_eq!(r.status, 204, "{}", r.text());
        assert_eq!(
            with_auth(
                &base,
                "GET",
                &format!("/api/v1/scenes/{other_id}"),
                Some(VIEW)
            )
            .status,
            404
        );
        id
    })
    .await;

    // The websocket: refused without the token, open with `?token=`.
    let url = format!("ws://{addr}/api/v1/scenes/{id}/stream");
    match tokio_tungstenite::connect_async(url.clone()).await {
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => assert_eq!(r.status(), 401),
        other => panic!("a stream without the view token is refused: {other:?}"),
    }
    let (mut ws, _) = tokio_tungstenite::connect_async(format!("{url}?token={VIEW}"))
        .await
        .expect("the view token opens the stream");
    match crate::e2e::support::next_text(&mut ws).await {
        isoray_protocol::ServerMessage::Info(info) => assert_eq!(info.scene.id, id),
        other => panic!("info first, got {other:?}"),
    }
    drop(ws);
    server.stop().await;
}

/// `encodeURIComponent` as browsers define it: every byte of the UTF-8 form but
/// `A–Z a–z 0–9 - _ . ! ~ * ' ( )` becomes `%XX`.
fn encode_uri_component(s: &str) -> String {
    s.bytes()
        .map(|b| {
            if b.is_ascii_alphanumeric() || b"-_.!~*'()".contains(&b) {
                (b as char).to_string()
            } else {
                format!("%{b:02X}")
            }
        })
        .collect()
}

/// A view token with characters a URL encodes (`+ / = % &`, a space) works over REST and on
/// the websocket, where the browser sends `?token=` + `encodeURIComponent(token)`.
#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn a_view_token_with_url_special_characters_opens_the_stream() {
    const ODD: &str = "a+b/c=d%e f&g-0123456789";
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--view-token", ODD]).await;
    let base = server.base.clone();
    let r = call(move || with_auth(&base, "GET", "/api/v1/scenes", Some(ODD))).await;
    assert_eq!(
        r.status,
        200,
        "the header carries it as it is: {}",
        r.text()
    );

    let url = format!("ws://{}/api/v1/scenes/blobs/stream", server.addr);
    let encoded = encode_uri_component(ODD);
    let (mut ws, _) =
        tokio_tungstenite::connect_async(format!("{url}?reproject=off&token={encoded}"))
            .await
            .unwrap_or_else(|e| panic!("?token={encoded} opens the stream: {e}"));
    match crate::e2e::support::next_text(&mut ws).await {
        isoray_protocol::ServerMessage::Info(info) => assert_eq!(info.scene.id, "blobs"),
        other => panic!("info first, got {other:?}"),
    }
    drop(ws);
    // The undecoded form is a different token, and is refused.
    match tokio_tungstenite::connect_async(format!("{url}?token={}", ODD.replace(' ', "%20"))).await
    {
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => assert_eq!(r.status(), 403),
        other => panic!("`+` means a space in a query, so this token is wrong: {other:?}"),
    }
    server.stop().await;
}
