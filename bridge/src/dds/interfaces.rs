//! Network interfaces a DDS participant may use.
//!
//! `[dds] interfaces` names them (`["lo"]`) or gives their IPv4 addresses (`["127.0.0.1"]`).
//! Both backends get the same resolved list: RustDDS as the addresses its participant may join
//! multicast groups on, send from and advertise; Cyclone DDS as `General/Interfaces` in its domain
//! configuration. An empty list leaves the choice to the implementation.

use super::DdsError;
use std::net::{IpAddr, Ipv4Addr};

/// One resolved interface.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Interface {
    /// Its name (`lo`).
    pub name: String,
    /// Its IPv4 address.
    pub addr: Ipv4Addr,
    /// Whether it is the loopback interface.
    pub loopback: bool,
}

/// Resolves `wanted` (names or IPv4 addresses) against the machine's interfaces. `None` when
/// `wanted` is empty (the implementation's default); an error naming the entry when one is not
/// found or has no IPv4 address.
pub fn resolve(wanted: &[String]) -> Result<Option<Vec<Interface>>, DdsError> {
    if wanted.is_empty() {
        return Ok(None);
    }
    let have: Vec<Interface> = netdev::get_interfaces()
        .into_iter()
        .flat_map(|i| {
            let loopback = i.is_loopback();
            let name = i.name.clone();
            i.ipv4.into_iter().map(move |n| Interface {
                name: name.clone(),
                addr: n.addr(),
                loopback,
            })
        })
        .collect();
    pick(wanted, &have).map(Some)
}

/// Picks the interfaces `wanted` names out of `have` (the testable half of [`resolve`]).
fn pick(wanted: &[String], have: &[Interface]) -> Result<Vec<Interface>, DdsError> {
    let mut out: Vec<Interface> = Vec::new();
    for w in wanted {
        let w = w.trim();
        let by_addr = w.parse::<IpAddr>().ok();
        let found: Vec<&Interface> = have
            .iter()
            .filter(|i| match by_addr {
                Some(IpAddr::V4(a)) => i.addr == a,
                Some(IpAddr::V6(_)) => false,
                None => i.name == w,
            })
            .collect();
        if found.is_empty() {
            let mut names: Vec<String> = have
                .iter()
                .map(|i| format!("{} ({})", i.name, i.addr))
                .collect();
            names.dedup();
            return Err(DdsError::Setup {
                topic: "participant".into(),
                reason: format!(
                    "no interface `{w}` with an IPv4 address on this machine (have: {})",
                    names.join(", ")
                ),
            });
        }
        for f in found {
            if !out.contains(f) {
                out.push(f.clone());
            }
        }
    }
    Ok(out)
}

/// The parts of a Cyclone DDS domain configuration that pin it to `nets`.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct CycloneFragments {
    /// Goes inside `<General>`: `<Interfaces>` with each interface by address, multicast forced
    /// on for loopback (Linux's `lo` often lacks the MULTICAST flag, yet delivers multicast to
    /// local sockets), the interface's own setting otherwise.
    pub general: String,
    /// A `<Discovery>` element when every interface is loopback: well-known unicast ports per
    /// participant index and unicast discovery to 127.0.0.1, so participants on this machine
    /// find each other (and RustDDS, which announces itself the same way) even where loopback
    /// multicast does not work. Empty otherwise.
    pub discovery: String,
}

/// The Cyclone DDS configuration fragments for `nets`.
pub fn cyclone_xml(nets: &[Interface]) -> CycloneFragments {
    let mut general = String::from("<Interfaces>");
    for n in nets {
        let mc = if n.loopback { "true" } else { "default" };
        general.push_str(&format!(
            "<NetworkInterface address=\"{}\" multicast=\"{mc}\"/>",
            n.addr
        ));
    }
    general.push_str("</Interfaces>");
    let discovery = if !nets.is_empty() && nets.iter().all(|n| n.loopback) {
        "<Discovery><ParticipantIndex>auto</ParticipantIndex><MaxAutoParticipantIndex>40</MaxAutoParticipantIndex><Peers><Peer address=\"127.0.0.1\"/></Peers></Discovery>".to_string()
    } else {
        String::new()
    };
    CycloneFragments { general, discovery }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn iface(name: &str, addr: [u8; 4], loopback: bool) -> Interface {
        Interface {
            name: name.into(),
            addr: Ipv4Addr::from(addr),
            loopback,
        }
    }

    #[test]
    fn names_and_addresses_resolve_and_unknown_ones_are_named() {
        let have = [
            iface("lo", [127, 0, 0, 1], true),
            iface("eth0", [192, 0, 2, 2], false),
        ];
        let lo = pick(&["lo".into()], &have).unwrap();
        assert_eq!(lo, vec![have[0].clone()]);
        let by_addr = pick(&["192.0.2.2".into(), "eth0".into()], &have).unwrap();
        assert_eq!(by_addr, vec![have[1].clone()], "no duplicates");
        let e = pick(&["wlan7".into()], &have).unwrap_err().to_string();
        assert!(e.contains("wlan7") && e.contains("lo (127.0.0.1)"), "{e}");
        assert!(pick(&["::1".into()], &have).is_err());
    }

    #[test]
    fn loopback_is_found_on_this_machine() {
        let lo = resolve(&["lo".into()]).unwrap().unwrap();
        assert!(lo.iter().all(|i| i.loopback && i.addr.is_loopback()));
        assert_eq!(resolve(&[]).unwrap(), None);
    }

    #[test]
    fn cyclone_gets_loopback_with_multicast_forced_on() {
        let x = cyclone_xml(&[iface("lo", [127, 0, 0, 1], true)]);
        assert_eq!(
            x.general,
            "<Interfaces><NetworkInterface address=\"127.0.0.1\" multicast=\"true\"/></Interfaces>"
        );
        assert!(x.discovery.contains("<Peer address=\"127.0.0.1\"/>"));
        let eth = cyclone_xml(&[iface("eth0", [192, 0, 2, 2], false)]);
        assert!(eth.general.contains("multicast=\"default\""));
        assert_eq!(eth.discovery, "");
    }
}
