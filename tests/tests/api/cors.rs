//! Other web pages cannot use the API through a visitor's browser: JSON bodies must say
//! `Content-Type: application/json` (which a cross-origin page can only send after a CORS
//! preflight), the CORS policy allows only the origins `--allowed-origins` names (none by
//! default: same origin only), and the websocket upgrade checks `Origin` against the same list.

use super::*;
use tokio_tungstenite::tungstenite::client::IntoClientRequest;

fn send(base: &str, method: &str, path: &str, headers: &[(&str, &str)], body: &[u8]) -> Response {
    Client::new(base)
        .expect("url")
        .request(method, path, headers, Body::Bytes(body))
        .expect("answer")
}

fn allow_origin(r: &Response) -> Option<String> {
    r.header("access-control-allow-origin").map(str::to_string)
}

async fn upgrade(addr: std::net::SocketAddr, origin: Option<&str>) -> Result<(), u16> {
    let mut req = format!("ws://{addr}/api/v1/scenes/blobs/stream")
        .into_client_request()
        .expect("request");
    if let Some(o) = origin {
        req.headers_mut()
            .insert("Origin", o.parse().expect("header value"));
    }
    match tokio_tungstenite::connect_async(req).await {
        Ok(_) => Ok(()),
        Err(tokio_tungstenite::tungstenite::Error::Http(r)) => Err(r.status().as_u16()),
        Err(e) => panic!("upgrade failed otherwise: {e}"),
    }
}

#[tokio::test(flavor = "multi_thread", worker_threads = 2)]
async fn json_bodies_need_their_content_type_and_only_listed_origins_get_cors() {
    let dir = tempfile::tempdir().expect("temp dir");
    let server = Server::start(dir.path(), &["--allowed-origins", "https://viewer.example"]).await;
    let base = server.base.clone();
    call(move || {
        // A page's plain form post (text/plain, no preflight) is refused, creating nothing.
        for (method, path) in [
            ("POST", "/api/v1/scenes"),
            ("POST", "/api/v1/scenes/blobs/render"),
        ] {
            for ct in [
                None,
                Some("text/plain"),
                Some("application/x-www-form-urlencoded"),
            ] {
                let headers: Vec<(&str, &str)> =
                    ct.map(|c| ("Content-Type", c)).into_iter().collect();
                let r = send(&base, method, path, &headers, br#"{"kind":"metaballs"}"#);
                assert_eq!(r.status, 415, "{method} {path} with {ct:?}: {}", r.text());
                assert_eq!(json(&r)["code"], "unsupported_media_type");
                assert_eq!(json(&r)["field"], "Content-Type");
            }
        }
        let r = get(&base, "/api/v1/scenes");
        let stored = json(&r)["scenes"]
            .as_array()
            .expect("scenes")
            .iter()
            .filter(|s| s["source"] == "stored")
            .count();
        assert_eq!(stored, 0, "no scene was created");
        // With its content type (and parameters) it works.
        let r = send(
            &base,
            "POST",
            "/api/v1/scenes",
            &[("Content-Type", "Application/JSON; charset=utf-8")],
            br#"{"kind":"metaballs"}"#,
        );
        assert_eq!(r.status, 201, "{}", r.text());

        // CORS: a preflight from another origin gets no permission; a listed one does.
        let preflight = |origin: &str| {
            send(
                &base,
                "OPTIONS",
                "/api/v1/scenes",
                &[
                    ("Origin", origin),
                    ("Access-Control-Request-Method", "POST"),
                    (
                        "Access-Control-Request-Headers",
                        "content-type,authorization",
                    ),
                ],
                b"",
            )
        };
        let r = preflight("https://evil.example");
        assert_eq!(allow_origin(&r), None, "no CORS for an unlisted origin");
        let r = preflight("https://viewer.example");
        assert_eq!(allow_origin(&r).as_deref(), Some("https://viewer.example"));
        let r = send(
            &base,
            "GET",
            "/api/v1/scenes",
            &[("Origin", "https://evil.example")],
            b"",
        );
        assert_eq!(r.status, 200);
        assert_eq!(
            allow_origin(&r),
            None,
            "an unlisted origin cannot read the answer"
        );
    })
    .await;

    // The websocket: no Origin (not a browser), the same origin, or a listed one.
    let addr = server.addr;
    assert_eq!(upgrade(addr, None).await, Ok(()));
    assert_eq!(upgrade(addr, Some(&format!("http://{addr}"))).await, Ok(()));
    assert_eq!(upgrade(addr, Some("https://viewer.example")).await, Ok(()));
    assert_eq!(upgrade(addr, Some("https://evil.example")).await, Err(403));
    assert_eq!(upgrade(addr, Some("null")).await, Err(403));
    server.stop().await;

    // By default: same origin only.
    let server = Server::start(dir.path(), &[]).await;
    let addr = server.addr;
    assert_eq!(upgrade(addr, Some(&format!("http://{addr}"))).await, Ok(()));
    assert_eq!(
        upgrade(addr, Some("https://viewer.example")).await,
        Err(403)
    );
    server.stop().await;
}
