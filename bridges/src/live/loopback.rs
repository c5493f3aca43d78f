//! Keeping a controller's ROS 2 traffic on this machine: the settings an external node's
//! process needs so that it talks to the twin over loopback only (unicast to 127.0.0.1, no
//! multicast, nothing leaves the machine), for the two DDS implementations ROS 2 users run:
//! Fast DDS (`rmw_fastrtps_cpp`, the default of the PyPI rclpy wheels) and Cyclone DDS.
//!
//! [`Loopback::write`] puts the two XML profiles into a folder and [`Loopback::environment`]
//! gives the variables to start the node with: `ROS_DOMAIN_ID`,
//! `ROS_AUTOMATIC_DISCOVERY_RANGE=LOCALHOST`, an empty `ROS_STATIC_PEERS`, `FASTDDS_DEFAULT_PROFILES_FILE` (a UDPv4
//! transport whitelisted to 127.0.0.1, no builtin transports, initial peer 127.0.0.1) and
//! `CYCLONEDDS_URI` (interface `lo`, multicast off, peer 127.0.0.1). The twin's own side is
//! [`super::LiveOptions::interface`] = 127.0.0.1.

use std::path::{Path, PathBuf};
use twin_core::error::Result;

/// The Fast DDS profile: one UDPv4 transport on 127.0.0.1, the default participant's only one.
pub const FASTDDS_PROFILE: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<!-- Fast DDS on loopback only (twin): UDPv4 on 127.0.0.1, no builtin transports (no shared
     memory, no multicast), discovery by unicast to 127.0.0.1. -->
<dds xmlns="http://www.eprosima.com">
  <profiles>
    <transport_descriptors>
      <transport_descriptor>
        <transport_id>twin_loopback_udp</transport_id>
        <type>UDPv4</type>
        <interfaceWhiteList>
          <address>127.0.0.1</address>
        </interfaceWhiteList>
      </transport_descriptor>
    </transport_descriptors>
    <participant profile_name="twin_loopback" is_default_profile="true">
      <rtps>
        <userTransports>
          <transport_id>twin_loopback_udp</transport_id>
        </userTransports>
        <useBuiltinTransports>false</useBuiltinTransports>
        <builtin>
          <metatrafficUnicastLocatorList>
            <locator>
              <udpv4>
                <address>127.0.0.1</address>
              </udpv4>
            </locator>
          </metatrafficUnicastLocatorList>
          <initialPeersList>
            <locator>
              <udpv4>
                <address>127.0.0.1</address>
              </udpv4>
            </locator>
          </initialPeersList>
        </builtin>
      </rtps>
    </participant>
  </profiles>
</dds>
"#;

/// The Cyclone DDS configuration: interface `lo`, no multicast, unicast discovery to 127.0.0.1.
pub const CYCLONEDDS_CONFIG: &str = r#"<?xml version="1.0" encoding="UTF-8"?>
<!-- Cyclone DDS on loopback only (twin): no multicast, unicast discovery to 127.0.0.1. -->
<CycloneDDS>
  <Domain Id="any">
    <General>
      <Interfaces>
        <NetworkInterface name="lo" multicast="false"/>
      </Interfaces>
      <AllowMulticast>false</AllowMulticast>
    </General>
    <Discovery>
      <Peers>
        <Peer address="127.0.0.1"/>
      </Peers>
      <ParticipantIndex>auto</ParticipantIndex>
      <MaxAutoParticipantIndex>20</MaxAutoParticipantIndex>
    </Discovery>
  </Domain>
</CycloneDDS>
"#;

/// The loopback settings of one DDS domain, with its profile files written.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Loopback {
    /// The DDS domain (`ROS_DOMAIN_ID`).
    pub domain_id: u16,
    /// The Fast DDS profile file.
    pub fastdds_profile: PathBuf,
    /// The Cyclone DDS configuration file.
    pub cyclonedds_config: PathBuf,
}

impl Loopback {
    /// Writes `fastdds-loopback.xml` and `cyclonedds-loopback.xml` into `dir` (atomically,
    /// replacing earlier copies) for `domain_id`.
    ///
    /// # Errors
    /// [`twin_core::Error::File`] when a file can't be written.
    pub fn write(dir: &Path, domain_id: u16) -> Result<Loopback> {
        let fastdds_profile = dir.join("fastdds-loopback.xml");
        let cyclonedds_config = dir.join("cyclonedds-loopback.xml");
        twin_core::fsio::write_atomic(&fastdds_profile, FASTDDS_PROFILE.as_bytes(), twin_core::fsio::Backup::None)?;
        twin_core::fsio::write_atomic(&cyclonedds_config, CYCLONEDDS_CONFIG.as_bytes(), twin_core::fsio::Backup::None)?;
        Ok(Loopback { domain_id, fastdds_profile, cyclonedds_config })
    }

    /// The environment of a node on this domain, loopback only (both DDS implementations).
    pub fn environment(&self) -> Vec<(String, String)> {
        vec![
            ("ROS_DOMAIN_ID".into(), self.domain_id.to_string()),
            ("ROS_AUTOMATIC_DISCOVERY_RANGE".into(), "LOCALHOST".into()),
            // No inherited static peers off this machine.
            ("ROS_STATIC_PEERS".into(), String::new()),
            ("FASTDDS_DEFAULT_PROFILES_FILE".into(), self.fastdds_profile.display().to_string()),
            ("CYCLONEDDS_URI".into(), format!("file://{}", self.cyclonedds_config.display())),
        ]
    }

    /// The twin's side of the same domain: [`super::LiveOptions`] on 127.0.0.1.
    pub fn live_options(&self, base: &super::LiveOptions) -> super::LiveOptions {
        super::LiveOptions {
            domain_id: self.domain_id,
            interface: std::net::IpAddr::V4(std::net::Ipv4Addr::LOCALHOST),
            ..base.clone()
        }
    }
}
