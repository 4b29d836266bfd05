//! Scene placement across several servers behind a load balancer.
//!
//! A stored scene lives on the disk of the server that created it. With `--shard NAME` the
//! server puts its own name in front of every scene id it creates (`NAME_<32 hex>`), so a
//! load balancer can send every later request for that scene — pushes, viewers, renders — to
//! the one server that holds it by looking at the path alone (deploy/nginx/isoray.conf maps
//! the prefix to an upstream; deploy/k8s/isoray.yaml routes it to a per-pod Service).
//! Creation itself (`POST /api/v1/scenes`) may go to any server: whichever answers names
//! itself in the id. ARCHITECTURE.md ("Scale-out") says why this beats hashing the id.
//!
//! A request that reaches a shard other than the one its id names was misrouted by the load
//! balancer; it is answered `421 Misdirected Request` naming both shards, not a bare 404.

use crate::random::random_hex;

/// Separates the shard name from the random part of a scene id. Shard names never contain
/// it (they are DNS labels, like Kubernetes pod names), and it is URL-safe.
pub const SHARD_SEPARATOR: char = '_';

/// Longest shard name: a DNS label.
pub const MAX_SHARD_LEN: usize = 63;

/// Checks a `--shard` name: 1–63 of `a-z`, `0-9` and `-`, starting and ending with a letter
/// or digit (a DNS label, so a Kubernetes pod name works as is).
pub fn validate_shard(name: &str) -> Result<(), String> {
    let ok_char = |c: char| c.is_ascii_lowercase() || c.is_ascii_digit() || c == '-';
    if name.is_empty() || name.len() > MAX_SHARD_LEN {
        return Err(format!(
            "--shard `{name}` must be 1 to {MAX_SHARD_LEN} characters long"
        ));
    }
    if let Some((at, c)) = name.char_indices().find(|&(_, c)| !ok_char(c)) {
        return Err(format!(
            "--shard `{name}`: character {c:?} at offset {at} is not one of a-z, 0-9 and -"
        ));
    }
    if name.starts_with('-') || name.ends_with('-') {
        return Err(format!(
            "--shard `{name}` must start and end with a letter or digit"
        ));
    }
    Ok(())
}

/// A fresh, unguessable scene id: 128 random bits as hex, after `SHARD_` when this server is
/// a shard.
pub fn new_scene_id(shard: Option<&str>) -> String {
    let random = random_hex(16);
    match shard {
        Some(name) => format!("{name}{SHARD_SEPARATOR}{random}"),
        None => random,
    }
}

/// The shard a scene id names, if it has the `SHARD_<hex>` form.
pub fn shard_of(id: &str) -> Option<&str> {
    let (shard, rest) = id.split_once(SHARD_SEPARATOR)?;
    (validate_shard(shard).is_ok() && !rest.is_empty()).then_some(shard)
}

/// Why a request for scene `id` should not have reached this server (`this_shard`), when
/// the id names another shard: the message of a `421 Misdirected Request`.
pub fn misrouted(this_shard: Option<&str>, id: &str) -> Option<String> {
    let this = this_shard?;
    let named = shard_of(id)?;
    (named != this).then(|| {
        format!(
            "scene `{id}` belongs to shard `{named}`, but this server is shard `{this}`: \
             the load balancer routed the request to the wrong server"
        )
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ids_carry_the_shard_and_128_random_bits() {
        let plain = new_scene_id(None);
        assert_eq!(plain.len(), 32);
        assert!(plain.bytes().all(|b| b.is_ascii_hexdigit()));
        assert_eq!(shard_of(&plain), None, "a plain id names no shard");

        let id = new_scene_id(Some("isoray-0"));
        assert_eq!(shard_of(&id), Some("isoray-0"));
        let random = id.strip_prefix("isoray-0_").expect("prefix");
        assert_eq!(random.len(), 32);
        assert_ne!(new_scene_id(Some("s0")), new_scene_id(Some("s0")));
    }

    #[test]
    fn shard_names_are_dns_labels() {
        for good in ["s0", "isoray-12", "a", &"x".repeat(63)] {
            validate_shard(good).unwrap_or_else(|e| panic!("{good}: {e}"));
        }
        for (bad, says) in [
            ("", "1 to 63"),
            (&"x".repeat(64), "1 to 63"),
            ("S0", "'S' at offset 0"),
            ("s_0", "'_' at offset 1"),
            ("s.0", "'.' at offset 1"),
            ("-s0", "start and end"),
            ("s0-", "start and end"),
        ] {
            let e = validate_shard(bad).expect_err(bad);
            assert!(e.contains(says), "{bad}: {e}");
        }
    }

    #[test]
    fn a_request_for_another_shard_is_misrouted() {
        assert_eq!(misrouted(Some("s0"), "s0_abc"), None);
        let m = misrouted(Some("s0"), "s1_abc").expect("misrouted");
        assert!(m.contains("shard `s1`") && m.contains("shard `s0`"), "{m}");
        assert_eq!(
            misrouted(None, "s1_abc"),
            None,
            "a lone server has no shard"
        );
        assert_eq!(
            misrouted(Some("s0"), "blobs"),
            None,
            "demo ids name no shard"
        );
        assert_eq!(misrouted(Some("s0"), "S1_abc"), None, "not a shard name");
    }
}
