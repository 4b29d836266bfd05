//! Serving: the app's router over an [`AppState`] ([`app`]; tests drive it in-process), the
//! websocket stream route, and [`serve`], which runs the router on a listener until a
//! shutdown future completes, then closes every session with a reason and drains.
//!
//! Architecture invariant: no handler renders or encodes; those run on the render pool or
//! the job pool and come back through channels (see `session` and `jobs`).

use crate::api::access::check_stream_view;
use crate::api::origin::check_upgrade_origin;
use crate::error::AppError;
use crate::state::AppState;
use crate::{metrics, placement, web};
use axum::extract::ws::rejection::WebSocketUpgradeRejection;
use axum::extract::ws::WebSocketUpgrade;
use axum::extract::{Path, State};
use axum::response::Response;
use axum::routing::get;
use axum::Router;
use std::future::Future;
use std::time::Duration;
use tokio::net::TcpListener;
use tower_http::trace::TraceLayer;

/// Largest websocket message a client may send: inputs are small JSON objects.
const MAX_CLIENT_MESSAGE_BYTES: usize = 64 * 1024;

/// How long shutdown waits for sessions to close before it gives up on them.
const DRAIN_TIMEOUT: Duration = Duration::from_secs(5);

/// The HTTP routes.
pub fn app(state: AppState) -> Router {
    Router::new()
        .route("/", get(web::index))
        .route("/healthz", get(|| async { "ok" }))
        .route("/metrics", get(metrics_text))
        .route("/api/v1/scenes/{id}/stream", get(stream))
        .route("/{file}", get(web::asset))
        .merge(crate::api::routes::router(state.config()))
        .layer(crate::api::origin::cors_layer(
            &state.config().allowed_origins,
        ))
        .layer(TraceLayer::new_for_http())
        .with_state(state)
}

/// `/metrics`, behind `--metrics-token` when it is set.
async fn metrics_text(
    State(state): State<AppState>,
    headers: axum::http::HeaderMap,
) -> Result<impl axum::response::IntoResponse, AppError> {
    if let Some(token) = &state.config().metrics_token {
        let hash = crate::api::auth::token_hash(token);
        crate::api::auth::require(
            crate::api::auth::bearer(&headers),
            &[&hash],
            "reading metrics",
        )?;
    }
    Ok((
        [(
            axum::http::header::CONTENT_TYPE,
            "text/plain; version=0.0.4; charset=utf-8",
        )],
        metrics::render(),
    ))
}

async fn stream(
    State(state): State<AppState>,
    Path(id): Path<String>,
    headers: axum::http::HeaderMap,
    axum::extract::RawQuery(query): axum::extract::RawQuery,
    ws: Result<WebSocketUpgrade, WebSocketUpgradeRejection>,
) -> Result<Response, AppError> {
    // A browser page of another origin may not watch through its visitor (CORS does not
    // cover websockets).
    check_upgrade_origin(&state.config().allowed_origins, &headers)?;
    let entry = state.scenes().get(&id).ok_or_else(|| {
        match placement::misrouted(state.config().shard.as_deref(), &id) {
            Some(message) => AppError::new(
                axum::http::StatusCode::MISDIRECTED_REQUEST,
                "misrouted",
                message,
            ),
            None => AppError::not_found(format!("no scene with id `{id}`")),
        }
    })?;
    // With --view-token, watching needs it (header or `?token=`).
    if let Err(e) = check_stream_view(&state, &headers, query.as_deref(), &entry) {
        return Ok(axum::response::IntoResponse::into_response(e));
    }
    let ws = ws.map_err(|e| {
        AppError::new(
            e.status(),
            "not_websocket",
            format!("this route streams frames over a websocket: {e}"),
        )
    })?;
    let ws = ws.max_message_size(MAX_CLIENT_MESSAGE_BYTES);
    Ok(match state.admit_session() {
        Some(ticket) => {
            ws.on_upgrade(move |socket| crate::session::socket::run(socket, state, entry, ticket))
        }
        None => {
            let limit = state.config().max_sessions;
            tracing::warn!(limit, "session refused: server full");
            ::metrics::counter!(metrics::SESSIONS_REFUSED).increment(1);
            ws.on_upgrade(move |socket| crate::session::socket::refuse(socket, limit))
        }
    })
}

/// Serves `state` on `listener` until `shutdown` completes, then closes sessions and drains.
///
/// The accept loop is ours rather than `axum::serve`'s so that hyper gets a timer: without
/// one its header read timeout never fires and a client that sends its headers slowly (or
/// never) holds a connection forever. A connection that has not sent a request's headers
/// within `--header-timeout-secs` (also an idle keep-alive connection) is closed.
pub async fn serve(
    listener: TcpListener,
    state: AppState,
    shutdown: impl Future<Output = ()> + Send + 'static,
) -> std::io::Result<()> {
    use hyper_util::rt::{TokioIo, TokioTimer};
    use tower::ServiceExt;

    let router = app(state.clone());
    let mut http = hyper::server::conn::http1::Builder::new();
    http.timer(TokioTimer::new())
        .header_read_timeout(Duration::from_secs(state.config().header_timeout_secs));
    // Connections hold a receiver each: `closed()` on the sender resolves once all are done;
    // the value turns true (once) when shutdown begins.
    let (closing_tx, closing_rx) = tokio::sync::watch::channel(false);
    let mut shutdown = std::pin::pin!(shutdown);
    loop {
        let (stream, remote) = tokio::select! {
            accepted = listener.accept() => match accepted {
                Ok(connection) => connection,
                Err(e) => {
                    // Per-connection failures (reset before accept) are nothing; running out
                    // of file descriptors is worth a pause, as axum::serve does.
                    if !matches!(
                        e.kind(),
                        std::io::ErrorKind::ConnectionAborted | std::io::ErrorKind::ConnectionReset
                    ) {
                        tracing::warn!(error = %e, "accept failed; pausing for a second");
                        tokio::time::sleep(Duration::from_secs(1)).await;
                    }
                    continue;
                }
            },
            () = &mut shutdown => break,
        };
        let router = router.clone();
        let service = hyper::service::service_fn(move |req: axum::http::Request<_>| {
            let mut req = req.map(axum::body::Body::new);
            req.extensions_mut()
                .insert(axum::extract::ConnectInfo::<std::net::SocketAddr>(remote));
            router.clone().oneshot(req)
        });
        let connection = http
            .serve_connection(TokioIo::new(stream), service)
            .with_upgrades();
        let mut closing = closing_rx.clone();
        tokio::spawn(async move {
            let mut connection = std::pin::pin!(connection);
            tokio::select! {
                result = connection.as_mut() => {
                    if let Err(e) = result {
                        tracing::debug!(error = %e, "connection ended with an error");
                    }
                }
                _ = closing.changed() => {
                    // Finish the request in flight, if any, then close.
                    connection.as_mut().graceful_shutdown();
                    let _ = connection.await;
                }
            }
            drop(closing);
        });
    }
    drop(listener);
    tracing::info!("shutting down: closing sessions");
    state.begin_shutdown();
    closing_tx.send_replace(true);
    drop(closing_rx);
    closing_tx.closed().await;
    // Upgraded websockets outlive the HTTP server's own drain; wait for them here.
    let deadline = tokio::time::Instant::now() + DRAIN_TIMEOUT;
    while state.sessions().count() > 0 && tokio::time::Instant::now() < deadline {
        tokio::time::sleep(Duration::from_millis(20)).await;
    }
    let left = state.sessions().count();
    if left > 0 {
        tracing::warn!(
            sessions = left,
            "sessions still open after the drain timeout"
        );
    }
    Ok(())
}
