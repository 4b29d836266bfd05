//! Every process lists every scene: three `isoray` processes on loopback, the first told of
//! the other two (`--peers`), each holding a scene of its own. The first lists all three
//! scenes (and the built-in demos once); with one peer killed it still lists its own and the
//! live peer's, and names the dead one in `unreachable_shards`.

use super::*;

fn listed(base: &str) -> (Vec<String>, Vec<String>) {
    let r = get(base, "/api/v1/scenes");
    assert_eq!(r.status, 200, "{}", r.text());
    let v = json(&r);
    let ids = v["scenes"]
        .as_array()
        .expect("scenes")
        .iter()
        .map(|s| s["id"].as_str().expect("id").to_string())
        .collect();
    let down = v["unreachable_shards"]
        .as_array()
        .expect("unreachable_shards is always there")
        .iter()
        .map(|s| s.as_str().expect("url").to_string())
        .collect();
    (ids, down)
}

#[test]
fn every_process_lists_every_scene_and_names_a_shard_that_does_not_answer() {
    let dirs: Vec<_> = (0..3)
        .map(|_| tempfile::tempdir().expect("temp dir"))
        .collect();
    let path = |i: usize| dirs[i].path().to_str().expect("utf-8").to_string();
    let (b_dir, c_dir) = (path(1), path(2));
    let b = Process::spawn(&["--data-dir", &b_dir, "--shard", "b"], &[]);
    let c = Process::spawn(&["--data-dir", &c_dir, "--shard", "c"], &[]);
    let peers = format!("{},{}", b.base, c.base);
    let a_dir = path(0);
    let a = Process::spawn(
        &["--data-dir", &a_dir, "--shard", "a", "--peers", &peers],
        &[],
    );
    let (in_a, _) = create(&a.base);
    let (in_b, _) = create(&b.base);
    let (in_c, _) = create(&c.base);
    assert!(in_a.starts_with("a_") && in_b.starts_with("b_") && in_c.starts_with("c_"));

    // Before: the peers alone list only their own.
    let (ids, _) = listed(&b.base);
    assert!(ids.contains(&in_b) && !ids.contains(&in_a) && !ids.contains(&in_c));

    let (ids, down) = listed(&a.base);
    for id in [&in_a, &in_b, &in_c] {
        assert!(ids.contains(id), "{id} is listed by a: {ids:?}");
    }
    let mut unique = ids.clone();
    unique.sort();
    unique.dedup();
    assert_eq!(
        unique.len(),
        ids.len(),
        "each scene once (demos too): {ids:?}"
    );
    assert!(down.is_empty(), "every peer answered: {down:?}");
    // What peers ask each other: one process's own scenes.
    let local = json(&get(&a.base, "/api/v1/scenes?scope=local"));
    assert_eq!(
        local["scenes"]
            .as_array()
            .expect("scenes")
            .iter()
            .filter(|s| s["source"] == "stored")
            .count(),
        1
    );

    // Kill c: a still answers, with b's scene and its own, and names c.
    let c_base = c.base.clone();
    c.kill();
    let (ids, down) = listed(&a.base);
    assert!(ids.contains(&in_a) && ids.contains(&in_b), "{ids:?}");
    assert!(!ids.contains(&in_c), "c's scene is gone with c: {ids:?}");
    assert_eq!(down, vec![c_base], "the dead shard is named");
    a.kill();
    b.kill();
}
