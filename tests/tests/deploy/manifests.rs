//! deploy/k8s/isoray.yaml against the Kubernetes schemas (kubernetes-validate, strict: no
//! unknown field, every type right), and against the placement scheme: one shard Service and
//! one Ingress path per StatefulSet pod, the shard name from the pod name, the store on the
//! pod's own volume, probes on /healthz, a drain on stop, websocket-length timeouts, and the
//! Dockerfile's user. No cluster is involved: this is what can be checked offline.

use crate::api::{python, repo_root};
use serde_json::Value;
use std::path::Path;
use std::process::Command;

/// `python -m MODULE ARGS... FILE` of a validator the CI venv has (`package` names it for the
/// message when it is missing): (passed, what it printed).
fn validate(module: &str, package: &str, args: &[&str], file: &Path) -> (bool, String) {
    let out = Command::new(python())
        .args(["-m", module])
        .args(args)
        .arg(file)
        .output()
        .expect("python runs");
    let text = format!(
        "{}{}",
        String::from_utf8_lossy(&out.stdout),
        String::from_utf8_lossy(&out.stderr)
    );
    assert!(
        !text.contains("No module named"),
        "{package} is missing: `bash .ci/run` installs it in the test venv \
         (ISORAY_PYTHON): {text}"
    );
    (out.status.success(), text)
}

/// `python -m kubernetes_validate --strict FILE`: (passed, what it printed).
fn kubernetes_validate(file: &Path) -> (bool, String) {
    validate(
        "kubernetes_validate",
        "kubernetes-validate",
        &["--strict", "--no-warn"],
        file,
    )
}

/// Every document of a YAML file, as JSON (parsed by PyYAML, which kubernetes-validate uses).
fn documents(file: &Path) -> Vec<Value> {
    let out = Command::new(python())
        .args([
            "-c",
            "import json, sys, yaml; print(json.dumps([d for d in yaml.safe_load_all(open(sys.argv[1])) if d]))",
        ])
        .arg(file)
        .output()
        .expect("python runs");
    assert!(
        out.status.success(),
        "{}",
        String::from_utf8_lossy(&out.stderr)
    );
    serde_json::from_slice(&out.stdout).expect("JSON from python")
}

fn find<'a>(docs: &'a [Value], kind: &str, name: &str) -> &'a Value {
    docs.iter()
        .find(|d| d["kind"] == kind && d["metadata"]["name"] == name)
        .unwrap_or_else(|| panic!("a {kind} named {name}"))
}

fn env<'a>(container: &'a Value, name: &str) -> &'a Value {
    container["env"]
        .as_array()
        .expect("env")
        .iter()
        .find(|e| e["name"] == name)
        .unwrap_or_else(|| panic!("env {name}"))
}

#[test]
fn kubernetes_manifests_validate_and_route_each_shard_to_its_pod() {
    let file = repo_root().join("deploy/k8s/isoray.yaml");
    let (passed, report) = kubernetes_validate(&file);
    assert!(passed, "kubernetes-validate --strict:\n{report}");

    // The validator does catch mistakes: a misspelt field fails.
    let text = std::fs::read_to_string(&file).expect("read manifests");
    let dir = tempfile::tempdir().expect("temp dir");
    let broken = dir.path().join("broken.yaml");
    std::fs::write(&broken, text.replace("replicas: 3", "replica: 3")).expect("write");
    let (passed, report) = kubernetes_validate(&broken);
    assert!(!passed && report.contains("replica"), "{report}");

    let docs = documents(&file);
    let sts = find(&docs, "StatefulSet", "isoray");
    let replicas = sts["spec"]["replicas"].as_u64().expect("replicas");
    assert!(replicas >= 2, "several shards");
    let pod = &sts["spec"]["template"]["spec"];
    let container = &pod["containers"][0];

    // The shard is the pod's name, a valid --shard.
    assert_eq!(
        env(container, "ISORAY_SHARD")["valueFrom"]["fieldRef"]["fieldPath"],
        "metadata.name"
    );
    // The store is on the pod's own volume, from the claim template.
    let data_dir = env(container, "ISORAY_DATA_DIR")["value"]
        .as_str()
        .expect("data dir");
    let mount = container["volumeMounts"]
        .as_array()
        .expect("mounts")
        .iter()
        .find(|m| m["mountPath"] == data_dir)
        .expect("the data dir is a mount");
    let claims: Vec<&str> = sts["spec"]["volumeClaimTemplates"]
        .as_array()
        .expect("claim templates")
        .iter()
        .map(|c| c["metadata"]["name"].as_str().expect("name"))
        .collect();
    assert!(
        claims.contains(&mount["name"].as_str().expect("mount name")),
        "the store's volume is a per-pod claim: {claims:?}"
    );
    // Listening port, probes and the Services' target agree.
    let listen = env(container, "ISORAY_LISTEN")["value"]
        .as_str()
        .expect("listen");
    let port = container["ports"][0]["containerPort"]
        .as_u64()
        .expect("port");
    assert!(listen.ends_with(&format!(":{port}")), "{listen} vs {port}");
    let port_name = container["ports"][0]["name"].as_str().expect("port name");
    for probe in ["startupProbe", "readinessProbe", "livenessProbe"] {
        assert_eq!(container[probe]["httpGet"]["path"], "/healthz", "{probe}");
        assert_eq!(container[probe]["httpGet"]["port"], port_name, "{probe}");
    }
    // Graceful stop: preStop, then the server's drain (5 s), within the grace period.
    let pre_stop = &container["lifecycle"]["preStop"]["exec"]["command"];
    assert_eq!(pre_stop[0], "sleep");
    let pre_stop_secs: u64 = pre_stop[1]
        .as_str()
        .expect("seconds")
        .parse()
        .expect("a number");
    let grace = pod["terminationGracePeriodSeconds"]
        .as_u64()
        .expect("grace period");
    assert!(grace >= pre_stop_secs + 5 + 10, "grace {grace} s");
    // Resources: requests for scheduling, threads from the CPU request.
    assert!(container["resources"]["requests"]["cpu"].is_string());
    assert!(container["resources"]["requests"]["memory"].is_string());
    assert_eq!(
        env(container, "ISORAY_THREADS")["valueFrom"]["resourceFieldRef"]["resource"],
        "requests.cpu"
    );
    // The Dockerfile's user is the one the pod runs as (and owns the volume through fsGroup).
    let dockerfile =
        std::fs::read_to_string(repo_root().join("deploy/Dockerfile")).expect("Dockerfile");
    let uid = pod["securityContext"]["runAsUser"].as_u64().expect("uid");
    assert!(
        dockerfile.contains(&format!("--uid {uid} ")),
        "Dockerfile uid {uid}"
    );
    assert!(
        dockerfile.contains(&format!("USER {uid}:")),
        "Dockerfile USER {uid}"
    );
    assert_eq!(pod["securityContext"]["fsGroup"].as_u64(), Some(uid));

    // Routing: every pod's scenes go to a Service that selects exactly that pod; the rest
    // to a Service over all pods.
    let ingress = find(&docs, "Ingress", "isoray");
    let annotations = &ingress["metadata"]["annotations"];
    assert_eq!(annotations["nginx.ingress.kubernetes.io/use-regex"], "true");
    for timeout in ["proxy-read-timeout", "proxy-send-timeout"] {
        let secs: u64 = annotations[format!("nginx.ingress.kubernetes.io/{timeout}")]
            .as_str()
            .expect(timeout)
            .parse()
            .expect("seconds");
        assert!(
            secs >= 3600,
            "{timeout} {secs}: websocket viewers stay for hours"
        );
    }
    assert_eq!(
        annotations["nginx.ingress.kubernetes.io/proxy-body-size"],
        "512m"
    );
    let paths = ingress["spec"]["rules"][0]["http"]["paths"]
        .as_array()
        .expect("paths");
    let backend_of = |path: &str| -> String {
        paths
            .iter()
            .find(|p| p["path"] == path)
            .unwrap_or_else(|| panic!("an Ingress path {path}"))["backend"]["service"]["name"]
            .as_str()
            .expect("service name")
            .to_string()
    };
    let sts_name = sts["metadata"]["name"].as_str().expect("name");
    for i in 0..replicas {
        let pod_name = format!("{sts_name}-{i}");
        isoray_server::placement::validate_shard(&pod_name).expect("a pod name is a shard name");
        let service = backend_of(&format!("/api/v1/scenes/{pod_name}_"));
        let selector = &find(&docs, "Service", &service)["spec"]["selector"];
        assert_eq!(
            selector["statefulset.kubernetes.io/pod-name"], pod_name,
            "{service} selects {pod_name} only"
        );
    }
    assert_eq!(
        paths.len() as u64,
        replicas + 1,
        "one path per shard plus the default"
    );
    let any = backend_of("/");
    let selector = &find(&docs, "Service", &any)["spec"]["selector"];
    assert!(selector.get("statefulset.kubernetes.io/pod-name").is_none());
    assert_eq!(
        selector["app"],
        sts["spec"]["selector"]["matchLabels"]["app"]
    );
}

/// deploy/compose.yaml against the Compose specification's JSON schema (check-jsonschema's
/// vendored copy, offline), and against deploy/nginx/isoray.conf, which it mounts unchanged:
/// one isoray service per shard the nginx file routes to, listening on that shard's address
/// inside the balancer's network namespace, each with its own store volume.
#[test]
fn compose_file_validates_and_matches_the_nginx_shards() {
    let file = repo_root().join("deploy/compose.yaml");
    let (passed, text) = validate(
        "check_jsonschema",
        "check-jsonschema",
        &["--builtin-schema", "vendor.compose-spec"],
        &file,
    );
    assert!(passed, "compose schema:\n{text}");

    let docs = documents(&file);
    let services = docs[0]["services"].as_object().expect("services");
    let conf = crate::deploy::nginx::shipped_conf();
    let shards = crate::deploy::nginx::shards_of(&conf);
    assert_eq!(shards.len(), 3, "three shards in the nginx file");
    let balancer = &services["balancer"];
    assert!(
        balancer["volumes"]
            .as_array()
            .expect("balancer volumes")
            .iter()
            .any(|v| v.as_str() == Some("./nginx/isoray.conf:/etc/nginx/conf.d/isoray.conf:ro")),
        "the balancer mounts the shipped nginx file: {balancer}"
    );
    assert_eq!(balancer["ports"][0], "8080:8080");
    assert!(conf.contains("listen 8080;"));
    let mut volumes = std::collections::BTreeSet::new();
    for (name, addr) in &shards {
        let s = &services[name.as_str()];
        assert_eq!(
            s["environment"]["ISORAY_SHARD"],
            name.as_str(),
            "{name}: {s}"
        );
        assert_eq!(
            s["environment"]["ISORAY_LISTEN"],
            addr.as_str(),
            "{name}: {s}"
        );
        assert_eq!(s["network_mode"], "service:balancer", "{name}");
        assert_eq!(s["build"]["dockerfile"], "deploy/Dockerfile", "{name}");
        let volume = s["volumes"][0].as_str().expect("a store volume");
        assert!(volume.ends_with(":/data"), "{volume}");
        assert_eq!(s["environment"]["ISORAY_DATA_DIR"], "/data");
        volumes.insert(volume.to_string());
    }
    assert_eq!(
        volumes.len(),
        shards.len(),
        "a volume per shard: {volumes:?}"
    );
    assert!(repo_root().join("deploy/Dockerfile").exists());
}
