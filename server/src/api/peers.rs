//! Every process lists every scene: `GET /api/v1/scenes` asks the peers of `--peers` for
//! their own scenes (`?scope=local`, so a peer does not ask further) at once, waits at most
//! `--peer-timeout-ms` for each, and merges their lists with this one's. A peer that does not
//! answer, answers with an error, or whose `dns://` name does not resolve in time is named in
//! `unreachable_shards`; the scenes of every other process are listed all the same.
//!
//! Behind a load balancer each scene lives on one process (its id names the shard); without
//! this the list depended on which process answered. Scenes are merged by id, so a process that
//! finds itself among its peers (a Kubernetes headless service lists every pod) lists its
//! scenes once.

use crate::api::client::Client;
use crate::config::Config;
use isoray_protocol::api::{SceneInfo, SceneInfoList};
use std::collections::HashSet;
use std::time::Duration;

/// What the peers hold: their scenes, and the peers that did not answer.
pub struct PeerScenes {
    pub scenes: Vec<SceneInfo>,
    pub unreachable: Vec<String>,
}

/// The base URLs of the peers: `http://` entries as they are, `dns://NAME:PORT` entries as
/// one URL per address NAME resolves to; names that do not resolve in time are unreachable.
async fn targets(config: &Config, timeout: Duration) -> (Vec<String>, Vec<String>) {
    let mut urls = Vec::new();
    let mut unreachable = Vec::new();
    for peer in &config.peers {
        if let Some(name) = peer.strip_prefix("dns://") {
            match tokio::time::timeout(timeout, tokio::net::lookup_host(name)).await {
                Ok(Ok(addrs)) => {
                    let mut found: Vec<String> = addrs.map(|a| format!("http://{a}")).collect();
                    found.sort();
                    found.dedup();
                    if found.is_empty() {
                        unreachable.push(peer.clone());
                    }
                    urls.extend(found);
                }
                Ok(Err(_)) | Err(_) => unreachable.push(peer.clone()),
            }
        } else {
            urls.push(peer.trim_end_matches('/').to_string());
        }
    }
    (urls, unreachable)
}

/// One peer's own scenes, or why not.
fn fetch(
    url: &str,
    authorization: Option<&str>,
    timeout: Duration,
) -> Result<Vec<SceneInfo>, String> {
    let mut client = Client::new(url).map_err(|e| e.to_string())?;
    client.timeout = timeout;
    let headers: Vec<(&str, &str)> = authorization
        .map(|a| vec![("Authorization", a)])
        .unwrap_or_default();
    let r = client
        .request(
            "GET",
            "/api/v1/scenes?scope=local",
            &headers,
            crate::api::client::Body::Empty,
        )
        .map_err(|e| e.to_string())?;
    if r.status != 200 {
        return Err(format!("answered {}", r.status));
    }
    r.json::<SceneInfoList>()
        .map(|l| l.scenes)
        .map_err(|e| e.to_string())
}

/// Every peer's scenes, asked at once, each within `--peer-timeout-ms`. The blocking client
/// runs on blocking threads; a peer that takes longer is given up (its thread ends at its
/// socket timeouts, the same bound).
pub async fn peer_scenes(config: &Config, authorization: Option<String>) -> PeerScenes {
    let timeout = Duration::from_millis(config.peer_timeout_ms);
    let (urls, mut unreachable) = targets(config, timeout).await;
    let asks: Vec<_> = urls
        .into_iter()
        .map(|url| {
            let auth = authorization.clone();
            let task = tokio::task::spawn_blocking({
                let url = url.clone();
                move || fetch(&url, auth.as_deref(), timeout)
            });
            async move {
                match tokio::time::timeout(timeout, task).await {
                    Ok(Ok(Ok(scenes))) => Ok(scenes),
                    Ok(Ok(Err(why))) => Err((url, why)),
                    Ok(Err(e)) => Err((url, e.to_string())),
                    Err(_) => Err((url, "no answer in time".to_string())),
                }
            }
        })
        .collect();
    let mut scenes = Vec::new();
    for answer in futures_util::future::join_all(asks).await {
        match answer {
            Ok(list) => scenes.extend(list),
            Err((url, why)) => {
                tracing::warn!(peer = %url, %why, "a peer did not list its scenes");
                unreachable.push(url);
            }
        }
    }
    PeerScenes {
        scenes,
        unreachable,
    }
}

/// This process's scenes, then the peers' not already listed (by id).
pub fn merge(local: Vec<SceneInfo>, peers: Vec<SceneInfo>) -> Vec<SceneInfo> {
    let mut seen: HashSet<String> = local.iter().map(|s| s.id.clone()).collect();
    let mut out = local;
    for s in peers {
        if seen.insert(s.id.clone()) {
            out.push(s);
        }
    }
    out
}
