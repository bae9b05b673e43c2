//! The ROS 1 side shared by HERB's ROS adapters (`herb-baxter`, `herb-camera`).
//!
//! - **Messages**: the vendored definitions under `msgs/` (Baxter's `baxter_core_msgs` exactly
//!   as Rethink Robotics published them, and the `std_msgs` and `sensor_msgs` types used),
//!   compiled to Rust types at build time by roslibrust's generator: no ROS installation is
//!   needed to build or run. Each type carries its ROS MD5 sum (`RosMessageType::DESCRIPTION.md5sum`);
//!   a test checks them against the robot's.

#![warn(missing_docs)]

/// The generated message types, one module per package (`baxter_core_msgs`, `std_msgs`,
/// `sensor_msgs`), re-exported at the crate root.
#[allow(missing_docs, unused_imports, clippy::all)]
mod generated {
    include!(concat!(env!("OUT_DIR"), "/messages.rs"));
}
pub use generated::*;
pub use roslibrust::RosMessageType;

pub mod node;
pub mod time;

/// A configuration value that is not a usable master URI or ROS name.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum ConfigError {
    /// Not `http://host:port`.
    #[error("{key} = {uri:?}: expected http://host:port")]
    MasterUri {
        /// The configuration key.
        key: String,
        /// The value given.
        uri: String,
    },
    /// Not an absolute ROS name.
    #[error("{key} = {name:?}: expected an absolute ROS name (/ then letters, digits, _ and /)")]
    Name {
        /// The configuration key.
        key: String,
        /// The value given.
        name: String,
    },
}

/// Checks a master URI from a configuration (`key` names it in the error): `http://host:port`.
pub fn check_master_uri(key: &str, uri: &str) -> Result<(), ConfigError> {
    let rest = uri.strip_prefix("http://").unwrap_or("");
    match rest.rsplit_once(':') {
        Some((host, port)) if !host.is_empty() && port.parse::<u16>().is_ok_and(|p| p > 0) => {
            Ok(())
        }
        _ => Err(ConfigError::MasterUri {
            key: key.to_owned(),
            uri: uri.to_owned(),
        }),
    }
}

/// Checks a global ROS name from a configuration (a topic or a node; `key` names it in the
/// error): `/` first, then letters, digits, `_` and `/`.
pub fn check_name(key: &str, name: &str) -> Result<(), ConfigError> {
    let rest = name.strip_prefix('/').unwrap_or("");
    if !rest.is_empty()
        && rest.starts_with(|c: char| c.is_ascii_alphabetic())
        && rest
            .chars()
            .all(|c| c.is_ascii_alphanumeric() || c == '_' || c == '/')
    {
        Ok(())
    } else {
        Err(ConfigError::Name {
            key: key.to_owned(),
            name: name.to_owned(),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn master_uris_and_names_are_checked() {
        assert!(check_master_uri("k", "http://127.0.0.1:11311").is_ok());
        assert!(check_master_uri("k", "http://robot.local:11311").is_ok());
        for bad in [
            "localhost:11311",
            "http://:11311",
            "http://host",
            "http://host:0",
            "http://h:x",
        ] {
            let e = check_master_uri("ros.master_uri", bad)
                .unwrap_err()
                .to_string();
            assert!(e.contains("ros.master_uri"), "{bad}: {e}");
        }
        assert!(check_name("k", "/robot/joint_states").is_ok());
        for bad in ["robot/state", "/", "/a b", "/9lives", ""] {
            assert!(
                check_name("topics.x", bad)
                    .unwrap_err()
                    .to_string()
                    .contains("topics.x"),
                "{bad}"
            );
        }
    }
}
