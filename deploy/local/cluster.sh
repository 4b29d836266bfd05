#!/usr/bin/env bash
# Three isoray processes behind Debian's nginx on this machine, with deploy/nginx/isoray.conf
# unchanged: the topology of deploy/compose.yaml and deploy/k8s, without containers.
#
#   deploy/local/cluster.sh            # then open http://127.0.0.1:8080/ ; Ctrl-C stops all
#
# Shards s0, s1, s2 listen on 127.0.0.1:8081..8083 with their own stores under
# $ISORAY_CLUSTER_DIR (default: a new temporary directory, kept on exit so restarts find
# their scenes when you pass it again). Extra arguments go to every isoray process, e.g.
# `--threads 1`. The binary is target/release/isoray (built if missing) or $ISORAY_BIN.
# nginx runs as this user with its own prefix, pid file and logs in the cluster directory;
# the access log (`logs/access.log`) names the upstream that served each request.
set -euo pipefail
root=$(cd "$(dirname "$0")/../.." && pwd)
bin=${ISORAY_BIN:-$root/target/release/isoray}
if [ ! -x "$bin" ]; then
  (cd "$root" && cargo build --release -p isoray-server --bin isoray)
fi
nginx=${ISORAY_NGINX:-$(command -v nginx || echo /usr/sbin/nginx)}
dir=${ISORAY_CLUSTER_DIR:-$(mktemp -d -t isoray-cluster.XXXXXX)}
mkdir -p "$dir/logs" "$dir/nginx-temp"
# nginx workers run as `nobody` when this runs as root: let them into the prefix.
chmod 755 "$dir"
echo "cluster directory: $dir"

pids=()
stop() {
  trap - INT TERM EXIT
  [ -f "$dir/nginx.pid" ] && kill "$(cat "$dir/nginx.pid")" 2>/dev/null || true
  for p in "${pids[@]}"; do kill "$p" 2>/dev/null || true; done
  wait 2>/dev/null || true
}
trap stop INT TERM EXIT

for k in 0 1 2; do
  mkdir -p "$dir/s$k"
  "$bin" --shard "s$k" --listen "127.0.0.1:808$((k + 1))" --data-dir "$dir/s$k" "$@" \
    > "$dir/logs/s$k.log" 2>&1 &
  pids+=($!)
done

# nginx's main context around the shipped http-context file.
cat > "$dir/nginx.conf" <<CONF
worker_processes 2;
pid $dir/nginx.pid;
error_log $dir/logs/error.log warn;
events { worker_connections 4096; }
http {
    client_body_temp_path $dir/nginx-temp/body;
    proxy_temp_path $dir/nginx-temp/proxy;
    fastcgi_temp_path $dir/nginx-temp/fastcgi;
    uwsgi_temp_path $dir/nginx-temp/uwsgi;
    scgi_temp_path $dir/nginx-temp/scgi;
    include $root/deploy/nginx/isoray.conf;
    access_log $dir/logs/access.log isoray;
}
CONF
"$nginx" -p "$dir" -c "$dir/nginx.conf" -g 'daemon off;' &
pids+=($!)

# Ready when every process answers /healthz through its own port and nginx answers.
for port in 8081 8082 8083 8080; do
  for _ in $(seq 600); do
    if curl -fsS "http://127.0.0.1:$port/healthz" >/dev/null 2>&1; then break; fi
    sleep 0.1
  done
  curl -fsS "http://127.0.0.1:$port/healthz" >/dev/null || { echo "port $port did not come up; logs in $dir/logs" >&2; exit 1; }
done
echo "isoray on http://127.0.0.1:8080/ (nginx -> s0 :8081, s1 :8082, s2 :8083); Ctrl-C stops"
wait -n "${pids[@]}" || true
echo "a process exited; stopping the cluster (logs in $dir/logs)" >&2
