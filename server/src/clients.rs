//! Who a request comes from, for the per-client rate limits: the peer's address, or, when the
//! peer is a trusted proxy (`--trusted-proxy`), the client its `X-Forwarded-For` names.
//!
//! `X-Forwarded-For` is a list each proxy appends the address it received the request from
//! to, so its right end is the one written by the nearest proxy. The client is the rightmost
//! address that is not itself a trusted proxy: a client cannot choose its bucket by sending
//! the header itself, since whatever it writes lies to the left of what the trusted proxy
//! appends. A peer that is not trusted is the client, whatever it sends.

use axum::http::HeaderMap;
use std::net::IpAddr;

/// An address or a network (`IP` or `IP/PREFIX`).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Network {
    addr: IpAddr,
    prefix: u8,
}

impl Network {
    pub fn parse(text: &str) -> Result<Network, String> {
        let bad = || format!("--trusted-proxy `{text}`: not an IP address or IP/PREFIX network");
        let (addr, prefix) = match text.trim().split_once('/') {
            Some((a, p)) => (a, Some(p)),
            None => (text.trim(), None),
        };
        let addr: IpAddr = addr.parse().map_err(|_| bad())?;
        let bits = match addr {
            IpAddr::V4(_) => 32,
            IpAddr::V6(_) => 128,
        };
        let prefix = match prefix {
            Some(p) => p
                .parse::<u8>()
                .ok()
                .filter(|p| *p <= bits)
                .ok_or_else(bad)?,
            None => bits,
        };
        Ok(Network { addr, prefix })
    }

    pub fn contains(&self, ip: IpAddr) -> bool {
        let ip = canonical(ip);
        match (canonical(self.addr), ip) {
            (IpAddr::V4(net), IpAddr::V4(ip)) => {
                let mask = u32::MAX
                    .checked_shl(32 - u32::from(self.prefix))
                    .unwrap_or(0);
                u32::from(net) & mask == u32::from(ip) & mask
            }
            (IpAddr::V6(net), IpAddr::V6(ip)) => {
                let mask = u128::MAX
                    .checked_shl(128 - u32::from(self.prefix))
                    .unwrap_or(0);
                u128::from(net) & mask == u128::from(ip) & mask
            }
            (IpAddr::V4(_), IpAddr::V6(_)) | (IpAddr::V6(_), IpAddr::V4(_)) => false,
        }
    }
}

/// An IPv4 address mapped into IPv6 (`::ffff:a.b.c.d`, as a dual-stack socket reports it) as
/// the IPv4 address.
fn canonical(ip: IpAddr) -> IpAddr {
    match ip {
        IpAddr::V6(v6) => v6.to_ipv4_mapped().map_or(ip, IpAddr::V4),
        IpAddr::V4(_) => ip,
    }
}

/// The trusted proxies of `--trusted-proxy`, parsed (the config checked them at startup).
pub fn trusted(list: &[String]) -> Vec<Network> {
    list.iter().filter_map(|t| Network::parse(t).ok()).collect()
}

/// The client a request from `peer` comes from (see the module's notes).
pub fn client_address(peer: IpAddr, headers: &HeaderMap, trusted: &[Network]) -> IpAddr {
    let is_trusted = |ip: IpAddr| trusted.iter().any(|n| n.contains(ip));
    if !is_trusted(peer) {
        return canonical(peer);
    }
    let mut client = canonical(peer);
    // Every X-Forwarded-For header, in order, as one list; read from the right.
    let forwarded: Vec<&str> = headers
        .get_all("x-forwarded-for")
        .iter()
        .filter_map(|v| v.to_str().ok())
        .flat_map(|v| v.split(','))
        .map(str::trim)
        .collect();
    for hop in forwarded.iter().rev() {
        let Ok(ip) = hop.parse::<IpAddr>() else {
            // Not an address (`unknown`, garbage): nothing left of it can be believed.
            break;
        };
        client = canonical(ip);
        if !is_trusted(client) {
            break;
        }
    }
    client
}

#[cfg(test)]
mod tests {
    use super::*;

    fn headers(xff: &[&str]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for v in xff {
            h.append("x-forwarded-for", v.parse().expect("header value"));
        }
        h
    }

    fn ip(s: &str) -> IpAddr {
        s.parse().expect("ip")
    }

    #[test]
    fn networks_match_by_prefix() {
        let n = Network::parse("10.1.0.0/16").expect("network");
        assert!(n.contains(ip("10.1.200.3")));
        assert!(!n.contains(ip("10.2.0.1")));
        assert!(n.contains(ip("::ffff:10.1.0.9")), "v4-mapped v6");
        assert!(Network::parse("127.0.0.1")
            .expect("host")
            .contains(ip("127.0.0.1")));
        assert!(Network::parse("::/0")
            .expect("all v6")
            .contains(ip("2001:db8::1")));
        for bad in ["10.0.0.0/33", "nonsense", "10.0.0.1/x", ""] {
            assert!(Network::parse(bad).is_err(), "{bad}");
        }
    }

    #[test]
    fn forwarded_addresses_count_only_from_trusted_proxies() {
        let proxy = vec![Network::parse("127.0.0.1").expect("proxy")];
        // Untrusted peer: its header is ignored.
        assert_eq!(
            client_address(ip("192.0.2.7"), &headers(&["203.0.113.5"]), &proxy),
            ip("192.0.2.7")
        );
        // Trusted peer: the rightmost untrusted hop; what the client prepended is ignored.
        assert_eq!(
            client_address(ip("127.0.0.1"), &headers(&["6.6.6.6, 203.0.113.5"]), &proxy),
            ip("203.0.113.5")
        );
        // Two headers are one list; trusted hops are skipped.
        assert_eq!(
            client_address(
                ip("127.0.0.1"),
                &headers(&["198.51.100.1", "127.0.0.1"]),
                &proxy
            ),
            ip("198.51.100.1")
        );
        // No header, or garbage: the proxy itself.
        assert_eq!(
            client_address(ip("127.0.0.1"), &headers(&[]), &proxy),
            ip("127.0.0.1")
        );
        assert_eq!(
            client_address(ip("127.0.0.1"), &headers(&["unknown"]), &proxy),
            ip("127.0.0.1")
        );
    }
}
