//! The `isoray` binary: parse flags, start logging, serve until Ctrl-C or SIGTERM. With no
//! arguments it serves the built-in demos on 127.0.0.1:8080. Two commands do other things:
//! `isoray push` sends step files to a server and `isoray render` draws one image offline.

mod cli;

use clap::Parser;
use isoray_server::{serve, AppState, Config};
use tokio::net::TcpListener;
use tracing_subscriber::EnvFilter;

fn main() -> std::process::ExitCode {
    // A build for newer CPUs (README, "Building for the host CPU") refuses to start on one
    // that lacks what it was compiled to use, rather than dying of an illegal instruction.
    let missing = isoray_render::cpu::missing();
    if !missing.is_empty() {
        eprintln!(
            "isoray: this binary was built for CPUs with {}; this CPU lacks {}. \
             Use the portable build (cargo build --release, no target-cpu).",
            isoray_render::cpu::compiled_for().join(", "),
            missing.join(", ")
        );
        return std::process::ExitCode::from(2);
    }
    // The commands are picked by the first argument, so that every flag-only (or empty)
    // command line still starts the server exactly as before.
    let command = std::env::args_os().nth(1);
    let outcome = match command.as_ref().and_then(|c| c.to_str()) {
        Some("push") => Some(cli::push::run(cli::push_args::PushArgs::parse_from(
            std::env::args_os().skip(1),
        ))),
        Some("render") => Some(cli::render::run(cli::render::RenderArgs::parse_from(
            std::env::args_os().skip(1),
        ))),
        _ => None,
    };
    match outcome {
        Some(Ok(())) => return std::process::ExitCode::SUCCESS,
        Some(Err(e)) => {
            eprintln!("isoray: {e}");
            return std::process::ExitCode::FAILURE;
        }
        None => {}
    }
    let config = Config::parse();
    let filter = EnvFilter::try_new(&config.log).unwrap_or_else(|e| {
        eprintln!(
            "isoray: bad --log filter {:?} ({e}); using `info`",
            config.log
        );
        EnvFilter::new("info")
    });
    tracing_subscriber::fmt().with_env_filter(filter).init();

    let runtime = match tokio::runtime::Builder::new_multi_thread()
        .enable_all()
        .thread_name("isoray-io")
        .build()
    {
        Ok(rt) => rt,
        Err(e) => {
            eprintln!("isoray: cannot start the async runtime: {e}");
            return std::process::ExitCode::FAILURE;
        }
    };
    match runtime.block_on(run(config)) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("isoray: {e}");
            std::process::ExitCode::FAILURE
        }
    }
}

async fn run(config: Config) -> Result<(), String> {
    let state = AppState::new(config.clone())?;
    let listener = TcpListener::bind(config.listen)
        .await
        .map_err(|e| format!("cannot listen on {}: {e}", config.listen))?;
    let addr = listener.local_addr().map_err(|e| e.to_string())?;
    tracing::info!(
        threads = state.backend().threads(),
        backend = state.backend().name(),
        build = %isoray_render::cpu::build_line(),
        "render pool started"
    );
    println!("isoray is serving its demo scenes: open http://{addr}/ in a browser");
    serve(listener, state, shutdown_signal())
        .await
        .map_err(|e| format!("server failed: {e}"))
}

async fn shutdown_signal() {
    let ctrl_c = async {
        if let Err(e) = tokio::signal::ctrl_c().await {
            tracing::error!(error = %e, "cannot listen for Ctrl-C");
            std::future::pending::<()>().await;
        }
    };
    #[cfg(unix)]
    let terminate = async {
        match tokio::signal::unix::signal(tokio::signal::unix::SignalKind::terminate()) {
            Ok(mut s) => {
                s.recv().await;
            }
            Err(e) => {
                tracing::error!(error = %e, "cannot listen for SIGTERM");
                std::future::pending::<()>().await;
            }
        }
    };
    #[cfg(not(unix))]
    let terminate = std::future::pending::<()>();
    tokio::select! {
        () = ctrl_c => {}
        () = terminate => {}
    }
}
