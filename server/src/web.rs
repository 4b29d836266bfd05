//! The browser client, embedded in the binary so `isoray` runs from any directory. `build.rs`
//! lists the files, so a new client module needs no change here.

use axum::extract::Path;
use axum::http::{header, StatusCode};
use axum::response::{IntoResponse, Response};

// `FILES`: (path, content type, bytes) of every file at the top of `client-web/`, listed by
// `build.rs`.
include!(concat!(env!("OUT_DIR"), "/client_files.rs"));

fn file(path: &str) -> Response {
    match FILES.iter().find(|(p, _, _)| *p == path) {
        Some((_, mime, bytes)) => (
            [
                (header::CONTENT_TYPE, *mime),
                (header::CACHE_CONTROL, "no-cache"),
            ],
            *bytes,
        )
            .into_response(),
        None => (StatusCode::NOT_FOUND, "not found").into_response(),
    }
}

pub async fn index() -> Response {
    file("index.html")
}

pub async fn asset(Path(path): Path<String>) -> Response {
    file(&path)
}

#[cfg(test)]
mod tests {
    use super::FILES;

    #[test]
    fn every_client_module_is_embedded() {
        let names: Vec<&str> = FILES.iter().map(|(name, _, _)| *name).collect();
        for wanted in ["index.html", "app.js", "protocol.js", "style.css"] {
            assert!(names.contains(&wanted), "{wanted} missing from {names:?}");
        }
        // Every module a client file imports is served too.
        for (name, _, bytes) in FILES.iter().filter(|(n, _, _)| n.ends_with(".js")) {
            let text = std::str::from_utf8(bytes).expect("client modules are UTF-8");
            for import in text.split("from './").skip(1) {
                let module = import.split('\'').next().unwrap_or_default();
                assert!(
                    names.contains(&module),
                    "{name} imports {module}, which is not embedded"
                );
            }
        }
    }
}
