//! Reverse proxies the operator trusts (`serve --trusted-proxy CIDR`): behind one, every
//! request comes from the proxy's address, and the client's is in `X-Forwarded-For`. That
//! header is anyone's to write, so it is read only from a connection whose peer is a
//! trusted proxy, and only as far as trusted proxies appended to it: the client is the
//! rightmost address that is not a trusted proxy (nginx's `real_ip_recursive`, Caddy's
//! `trusted_proxies`). What the client itself put before that is ignored.
//!
//! The address found this way is the one rate limits, budget shares and the audit log
//! count ([`super::auth::peer`]). Connections are still capped by their TCP peer, except
//! that a trusted proxy is not held to the per-address cap (it carries every client's
//! connections); the total cap applies to it as to anyone.

use std::net::IpAddr;

use axum::http::HeaderMap;
use ipnet::IpNet;

/// The trusted proxies' networks; empty: trust none (the default).
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct TrustedProxies(Vec<IpNet>);

impl TrustedProxies {
    /// Networks as `10.0.0.0/8`, `fd00::/8` or a bare address (`10.0.0.5`, one host).
    pub fn parse<S: AsRef<str>>(items: &[S]) -> Result<TrustedProxies, String> {
        items
            .iter()
            .map(|s| {
                let s = s.as_ref().trim();
                s.parse::<IpNet>()
                    .or_else(|_| s.parse::<IpAddr>().map(IpNet::from))
                    .map_err(|_| {
                        format!("--trusted-proxy {s:?} is not an address or a CIDR network")
                    })
            })
            .collect::<Result<Vec<_>, _>>()
            .map(TrustedProxies)
    }

    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// Whether `ip` is a trusted proxy (an IPv4-mapped IPv6 address counts as its IPv4).
    pub fn contains(&self, ip: IpAddr) -> bool {
        let ip = ip.to_canonical();
        self.0.iter().any(|n| n.contains(&ip))
    }

    /// The client's address: `peer`, unless `peer` is a trusted proxy and
    /// `X-Forwarded-For` names an address that is not (the rightmost such). A malformed
    /// entry ends the walk there: what lies left of it is no proxy's word.
    pub fn client(&self, peer: IpAddr, headers: &HeaderMap) -> IpAddr {
        if !self.contains(peer) {
            return peer;
        }
        let mut client = peer;
        // Several headers are one list, in order.
        // Split as bytes: a client's own entry with bytes that are not ASCII must not hide
        // the entries a proxy appended to the same line.
        let hops = headers
            .get_all("x-forwarded-for")
            .iter()
            .flat_map(|v| v.as_bytes().split(|&b| b == b','))
            .map(|hop| std::str::from_utf8(hop).unwrap_or(""))
            .collect::<Vec<_>>();
        for hop in hops.iter().rev() {
            match parse_hop(hop) {
                Some(ip) if self.contains(ip) => client = ip,
                Some(ip) => return ip,
                None => return client,
            }
        }
        client
    }
}

/// One `X-Forwarded-For` entry: an address, possibly with a port (`1.2.3.4:5678`,
/// `[2001:db8::1]:443`).
fn parse_hop(hop: &str) -> Option<IpAddr> {
    let hop = hop.trim();
    if let Ok(ip) = hop.parse::<IpAddr>() {
        return Some(ip.to_canonical());
    }
    hop.parse::<std::net::SocketAddr>()
        .ok()
        .map(|s| s.ip().to_canonical())
}

#[cfg(test)]
mod tests {
    use super::*;
    use axum::http::HeaderValue;

    fn xff(values: &[&str]) -> HeaderMap {
        let mut h = HeaderMap::new();
        for v in values {
            h.append("x-forwarded-for", HeaderValue::from_str(v).unwrap());
        }
        h
    }

    fn ip(s: &str) -> IpAddr {
        s.parse().unwrap()
    }

    #[test]
    fn the_client_is_the_rightmost_address_no_trusted_proxy_owns() {
        let t = TrustedProxies::parse(&["10.0.0.0/8", "192.0.2.7"]).unwrap();
        let proxy = ip("10.1.2.3");
        // Not from a proxy: the header is the client's to write, and ignored.
        assert_eq!(
            t.client(ip("198.51.100.9"), &xff(&["1.1.1.1"])),
            ip("198.51.100.9")
        );
        // From a proxy: the address it appended.
        assert_eq!(t.client(proxy, &xff(&["203.0.113.5"])), ip("203.0.113.5"));
        // A client's own forged entries lie left of what the proxy appended.
        assert_eq!(
            t.client(proxy, &xff(&["1.1.1.1, 203.0.113.5"])),
            ip("203.0.113.5")
        );
        // Chains of trusted proxies are walked; several headers are one list.
        assert_eq!(
            t.client(proxy, &xff(&["203.0.113.5, 192.0.2.7", "10.9.9.9"])),
            ip("203.0.113.5")
        );
        // Ports and IPv6 brackets; IPv4-mapped addresses as IPv4.
        assert_eq!(
            t.client(proxy, &xff(&["203.0.113.5:4711"])),
            ip("203.0.113.5")
        );
        assert_eq!(
            t.client(proxy, &xff(&["[2001:db8::1]:443"])),
            ip("2001:db8::1")
        );
        assert!(t.contains(ip("::ffff:10.0.0.1")));
        // No header, or one only of proxies: the nearest proxy.
        assert_eq!(t.client(proxy, &HeaderMap::new()), proxy);
        assert_eq!(t.client(proxy, &xff(&["10.2.2.2"])), ip("10.2.2.2"));
        // Garbage stops the walk where it is.
        assert_eq!(t.client(proxy, &xff(&["203.0.113.5, junk"])), proxy);
        // A client's bytes that are not ASCII do not hide what the proxy appended.
        let mut h = HeaderMap::new();
        h.append(
            "x-forwarded-for",
            HeaderValue::from_bytes(b"\xff\xfe, 203.0.113.8").unwrap(),
        );
        assert_eq!(t.client(proxy, &h), ip("203.0.113.8"));
        // Trusting none (the default) reads no header.
        let none = TrustedProxies::default();
        assert_eq!(none.client(proxy, &xff(&["203.0.113.5"])), proxy);
    }

    #[test]
    fn networks_and_hosts_parse_and_nonsense_is_refused() {
        assert!(TrustedProxies::parse(&["10.0.0.0/8", "::1", "fd00::/8"]).is_ok());
        let e = TrustedProxies::parse(&["10.0.0.0/33"]).unwrap_err();
        assert!(e.contains("10.0.0.0/33"), "{e}");
        assert!(TrustedProxies::parse(&["proxy.example"]).is_err());
    }
}
