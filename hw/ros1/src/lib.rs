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
    /// Not an IPv4 address (what ROS 1 and roslibrust take as `ROS_IP`).
    #[error("{key} = {ip:?}: expected an IPv4 address such as 10.0.0.5")]
    Ip {
        /// The configuration key (or environment variable).
        key: String,
        /// The value given.
        ip: String,
    },
    /// Not a host name a URI can carry.
    #[error("{key} = {host:?}: expected a host name (no spaces, '/' or ':')")]
    Hostname {
        /// The configuration key (or environment variable).
        key: String,
        /// The value given.
        host: String,
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

/// Checks the address this node is reached at (`ROS_IP`; `key` names it in the error): empty
/// (not set) or an IPv4 address.
pub fn check_ip(key: &str, ip: &str) -> Result<(), ConfigError> {
    if ip.is_empty() || ip.parse::<std::net::Ipv4Addr>().is_ok() {
        Ok(())
    } else {
        Err(ConfigError::Ip {
            key: key.to_owned(),
            ip: ip.to_owned(),
        })
    }
}

/// Checks the host name this node is reached at (`ROS_HOSTNAME`; `key` names it in the error):
/// empty (not set) or a name with no whitespace, `/` or `:` (it goes into `http://host:port`).
pub fn check_hostname(key: &str, host: &str) -> Result<(), ConfigError> {
    if host
        .chars()
        .any(|c| c.is_whitespace() || c == '/' || c == ':')
    {
        Err(ConfigError::Hostname {
            key: key.to_owned(),
            host: host.to_owned(),
        })
    } else {
        Ok(())
    }
}

/// What other ROS nodes (the robot, the camera's driver) are told to reach this node at; roslibrust
/// reads `ROS_HOSTNAME`, else `ROS_IP`, else takes the PC's hostname.
#[derive(Debug, Clone, PartialEq, Eq)]
pub enum Advertised {
    /// `ROS_HOSTNAME`.
    Hostname(String),
    /// `ROS_IP`.
    Ip(String),
    /// Neither: the PC's hostname, which the others must resolve.
    PcHostname,
}

impl std::fmt::Display for Advertised {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Self::Hostname(a) | Self::Ip(a) => f.write_str(a),
            Self::PcHostname => {
                f.write_str("this PC's hostname (set ros.ip or ros.hostname on a real cell)")
            }
        }
    }
}

impl Advertised {
    /// The address from an adapter's `[ros]` keys `ip` and `hostname` (validated: empty is not
    /// set), else from the environment (`env`: a variable's value; `/etc/herb/ros.env` under
    /// systemd). The keys override the environment; a hostname takes precedence over an IP,
    /// as in ROS; an empty variable counts as unset. An environment's value is checked as the
    /// keys are, the error naming the variable.
    pub fn choose(
        ip: &str,
        hostname: &str,
        env: impl Fn(&str) -> Option<String>,
    ) -> Result<Self, ConfigError> {
        if !hostname.is_empty() {
            return Ok(Self::Hostname(hostname.to_owned()));
        }
        if !ip.is_empty() {
            return Ok(Self::Ip(ip.to_owned()));
        }
        let set = |var: &str| env(var).filter(|v| !v.is_empty());
        if let Some(h) = set("ROS_HOSTNAME") {
            check_hostname("ROS_HOSTNAME (environment)", &h)?;
            return Ok(Self::Hostname(h));
        }
        if let Some(i) = set("ROS_IP") {
            check_ip("ROS_IP (environment)", &i)?;
            return Ok(Self::Ip(i));
        }
        Ok(Self::PcHostname)
    }

    /// [`Advertised::choose`] from the process's environment, then [`Advertised::apply`]: what
    /// an adapter calls at start, before its ROS side runs.
    ///
    /// # Safety
    ///
    /// As [`Advertised::apply`].
    pub unsafe fn set(ip: &str, hostname: &str) -> Result<Self, ConfigError> {
        let a = Self::choose(ip, hostname, |v| std::env::var(v).ok())?;
        // SAFETY: the caller's guarantee.
        unsafe { a.apply() };
        Ok(a)
    }

    /// Sets the process's `ROS_HOSTNAME` and `ROS_IP` so that roslibrust advertises `self` and
    /// nothing else: the chosen variable set, the other removed.
    ///
    /// # Safety
    ///
    /// Changes the environment ([`std::env::set_var`]): call it before the process starts any
    /// other thread (or while none reads or writes the environment).
    pub unsafe fn apply(&self) {
        // SAFETY: the caller's guarantee.
        unsafe {
            std::env::remove_var("ROS_HOSTNAME");
            std::env::remove_var("ROS_IP");
            match self {
                Self::Hostname(h) => std::env::set_var("ROS_HOSTNAME", h),
                Self::Ip(i) => std::env::set_var("ROS_IP", i),
                Self::PcHostname => {}
            }
        }
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
        assert!(check_ip("k", "").is_ok() && check_ip("k", "10.0.0.5").is_ok());
        assert!(check_hostname("k", "").is_ok() && check_hostname("k", "herb-pc.local").is_ok());
        for bad in ["herb-pc", "10.0.0", "::1"] {
            let e = check_ip("ros.ip", bad).unwrap_err().to_string();
            assert!(e.contains("ros.ip") && e.contains(bad), "{e}");
        }
        for bad in ["herb pc", "http://herb-pc", "herb-pc:11311"] {
            let e = check_hostname("ros.hostname", bad).unwrap_err().to_string();
            assert!(e.contains("ros.hostname") && e.contains(bad), "{e}");
        }
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

    #[test]
    fn the_keys_override_the_environment_and_a_hostname_comes_first() {
        let env = |h: &'static str, i: &'static str| {
            move |var: &str| Some(if var == "ROS_HOSTNAME" { h } else { i }.to_owned())
        };
        let ip = |a: &str| Advertised::Ip(a.into());
        let host = |a: &str| Advertised::Hostname(a.into());
        for (keys, (env_host, env_ip), want) in [
            (("10.0.0.5", "pc"), ("", ""), host("pc")),
            (("10.0.0.5", ""), ("robot-pc", "10.0.0.9"), ip("10.0.0.5")),
            (("", ""), ("robot-pc", "10.0.0.9"), host("robot-pc")),
            (("", ""), ("", "10.0.0.9"), ip("10.0.0.9")),
            (("", ""), ("", ""), Advertised::PcHostname),
        ] {
            let got = Advertised::choose(keys.0, keys.1, env(env_host, env_ip)).unwrap();
            assert_eq!(got, want, "{keys:?} {env_host:?} {env_ip:?}");
        }
        let e = Advertised::choose("", "", env("", "robot-pc")).unwrap_err();
        assert!(e.to_string().contains("ROS_IP (environment)"), "{e}");
        assert!(Advertised::PcHostname.to_string().contains("ros.ip"));
    }
}
