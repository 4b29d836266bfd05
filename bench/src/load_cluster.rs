//! The deployment side of `isoray-bench load`: scenes created through the balancer
//! (`--create`), pushers that add a step per period to some of them while the viewers watch
//! (`--push-to`, `--push-hz`), and which process served each scene, read from every
//! process's own `/metrics` in the middle of the run (`--backend NAME=URL`).
//!
//! Pushes use the server's own blocking HTTP client on blocking threads; each is timed from
//! the request to the `201`. A scene's id names the shard that created it (`s1_…`), so the
//! expected sessions per process follow from the ids; the report sets them beside the
//! `isoray_sessions` gauge each process reports.

use isoray_server::api::client::{Body, Client};
use serde::Serialize;
use std::time::{Duration, Instant};

/// A scene made for the run.
#[derive(Clone, Debug)]
pub struct Created {
    pub id: String,
    pub token: String,
}

/// What one pusher did.
#[derive(Clone, Debug, Default, Serialize)]
pub struct PushReport {
    pub scene: String,
    pub pushed: u64,
    pub failed: u64,
    pub latency_p50_ms: f64,
    pub latency_p95_ms: f64,
    pub latency_max_ms: f64,
    pub error_messages: Vec<String>,
}

/// One process's view of the run, from its `/metrics` at mid-run.
#[derive(Clone, Debug, Default, Serialize)]
pub struct ProcessReport {
    pub name: String,
    pub url: String,
    /// `isoray_sessions` on that process at mid-run.
    pub sessions: f64,
    /// Viewers whose scene id names this process.
    pub expected_sessions: usize,
    pub error: Option<String>,
}

/// `n` balls of a step placed by `seed` (moves a little with every step), as JSON.
fn step_json(balls: usize, seed: u64) -> String {
    let t = seed as f64 * 0.15;
    let positions: Vec<[f64; 3]> = (0..balls)
        .map(|i| {
            let a = i as f64 * 2.399_963 + t;
            let y = 1.0 - 2.0 * (i as f64 + 0.5) / balls as f64;
            let r = (1.0 - y * y).max(0.0).sqrt();
            [a.cos() * r, y, a.sin() * r]
        })
        .collect();
    serde_json::json!({ "positions": positions, "radii": vec![0.35; balls] }).to_string()
}

fn client(url: &str) -> Result<Client, String> {
    let mut c = Client::new(url).map_err(|e| e.to_string())?;
    c.timeout = Duration::from_secs(60);
    Ok(c)
}

/// Creates `n` metaball scenes of `balls` balls through `url` and pushes step 0 to each.
pub fn create_scenes(url: &str, n: usize, balls: usize) -> Result<Vec<Created>, String> {
    let c = client(url)?;
    let mut out = Vec::with_capacity(n);
    for k in 0..n {
        let r = c
            .request(
                "POST",
                "/api/v1/scenes",
                &[("Content-Type", "application/json")],
                Body::Bytes(br#"{"kind":"metaballs"}"#),
            )
            .map_err(|e| format!("create scene {k}: {e}"))?;
        if r.status != 201 {
            return Err(format!("create scene {k}: {} {}", r.status, r.text()));
        }
        let v: serde_json::Value = r.json().map_err(|e| e.to_string())?;
        let created = Created {
            id: v["scene"]["id"].as_str().unwrap_or_default().to_string(),
            token: v["write_token"].as_str().unwrap_or_default().to_string(),
        };
        push(&c, &created, 0, balls)?;
        out.push(created);
    }
    Ok(out)
}

fn push(c: &Client, scene: &Created, index: u64, balls: usize) -> Result<(), String> {
    let auth = format!("Bearer {}", scene.token);
    let body = step_json(balls, index);
    let r = c
        .request(
            "PUT",
            &format!("/api/v1/scenes/{}/steps/{index}?time={index}", scene.id),
            &[
                ("Content-Type", "application/json"),
                ("Authorization", &auth),
            ],
            Body::Bytes(body.as_bytes()),
        )
        .map_err(|e| format!("push {index}: {e}"))?;
    if r.status != 201 {
        return Err(format!("push {index}: {} {}", r.status, r.text()));
    }
    Ok(())
}

/// Pushes step 1, 2, … to `scene` every `1/hz` s until `duration` has passed.
pub fn pusher(
    url: String,
    scene: Created,
    balls: usize,
    hz: f64,
    duration: Duration,
) -> PushReport {
    let mut report = PushReport {
        scene: scene.id.clone(),
        ..PushReport::default()
    };
    let c = match client(&url) {
        Ok(c) => c,
        Err(e) => {
            report.failed += 1;
            report.error_messages.push(e);
            return report;
        }
    };
    let period = Duration::from_secs_f64(1.0 / hz);
    let start = Instant::now();
    let mut latencies = Vec::new();
    for index in 1u64.. {
        let due = start + period.mul_f64(index as f64 - 1.0);
        if due >= start + duration {
            break;
        }
        if let Some(wait) = due.checked_duration_since(Instant::now()) {
            std::thread::sleep(wait);
        }
        let t = Instant::now();
        match push(&c, &scene, index, balls) {
            Ok(()) => {
                report.pushed += 1;
                latencies.push(t.elapsed().as_secs_f64() * 1000.0);
            }
            Err(e) => {
                report.failed += 1;
                if report.error_messages.len() < 5 {
                    report.error_messages.push(e);
                }
            }
        }
    }
    latencies.sort_by(f64::total_cmp);
    report.latency_p50_ms = crate::common::quantile(&latencies, 0.5);
    report.latency_p95_ms = crate::common::quantile(&latencies, 0.95);
    report.latency_max_ms = latencies.last().copied().unwrap_or(0.0);
    report
}

/// `NAME=http://HOST:PORT` of `--backend`.
pub fn parse_backend(s: &str) -> Result<(String, String), String> {
    match s.split_once('=') {
        Some((name, url)) if !name.is_empty() && url.starts_with("http://") => {
            Ok((name.to_string(), url.to_string()))
        }
        _ => Err(format!("--backend {s:?} is not NAME=http://HOST:PORT")),
    }
}

/// The value of the unlabelled gauge `name` in a Prometheus text exposition.
pub fn gauge(text: &str, name: &str) -> Option<f64> {
    text.lines().filter(|l| !l.starts_with('#')).find_map(|l| {
        let (metric, value) = l.rsplit_once(' ')?;
        (metric == name).then(|| value.parse().ok())?
    })
}

/// Reads `isoray_sessions` from every backend.
pub fn scrape(backends: &[(String, String)], token: Option<&str>) -> Vec<ProcessReport> {
    backends
        .iter()
        .map(|(name, url)| {
            let mut p = ProcessReport {
                name: name.clone(),
                url: url.clone(),
                ..ProcessReport::default()
            };
            let auth = token.map(|t| format!("Bearer {t}"));
            let headers: Vec<(&str, &str)> = auth
                .as_deref()
                .map(|a| vec![("Authorization", a)])
                .unwrap_or_default();
            match client(url).and_then(|c| {
                c.request("GET", "/metrics", &headers, Body::Empty)
                    .map_err(|e| e.to_string())
            }) {
                Ok(r) if r.status == 200 => match gauge(&r.text(), "isoray_sessions") {
                    Some(v) => p.sessions = v,
                    None => p.error = Some("no isoray_sessions in /metrics".into()),
                },
                Ok(r) => p.error = Some(format!("/metrics: {}", r.status)),
                Err(e) => p.error = Some(e),
            }
            p
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn gauges_and_backends_are_read() {
        let text = "# HELP isoray_sessions open\n# TYPE isoray_sessions gauge\nisoray_sessions 16\nisoray_sessions_refused_total 2\n";
        assert_eq!(gauge(text, "isoray_sessions"), Some(16.0));
        assert_eq!(gauge(text, "isoray_frames_sent_total"), None);
        assert_eq!(
            parse_backend("s1=http://127.0.0.1:8082"),
            Ok(("s1".into(), "http://127.0.0.1:8082".into()))
        );
        assert!(parse_backend("http://127.0.0.1:8082").is_err());
        let step: serde_json::Value = serde_json::from_str(&step_json(5, 3)).expect("a JSON step");
        assert_eq!(step["positions"].as_array().map(Vec::len), Some(5));
    }
}
