//! Connecting to the master and reading subscriptions, the same way in every adapter.

use roslibrust::ros1::{NodeHandle, Subscriber};
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Duration;

/// Wait between attempts to reach the master at start.
pub const CONNECT_RETRY: Duration = Duration::from_millis(500);

/// Registers node `name` with the master at `master_uri`, retrying every [`CONNECT_RETRY`]
/// until it answers (said once through `say`, the adapter's log, e.g.
/// `|m| herb_adapter::log!("herb-camera: {m}")`); `None` if `stop` is set first.
pub async fn connect(
    master_uri: &str,
    name: &str,
    say: impl Fn(std::fmt::Arguments<'_>),
    stop: &AtomicBool,
) -> Option<NodeHandle> {
    let mut told = false;
    loop {
        if stop.load(Ordering::Relaxed) {
            return None;
        }
        match NodeHandle::new(master_uri, name).await {
            Ok(nh) => {
                say(format_args!(
                    "connected to the ROS master at {master_uri} as {name}"
                ));
                return Some(nh);
            }
            Err(e) if !told => {
                say(format_args!(
                    "ROS master {master_uri} not reachable ({e}); retrying"
                ));
                told = true;
            }
            Err(_) => {}
        }
        tokio::time::sleep(CONNECT_RETRY).await;
    }
}

/// What a subscription yielded.
#[derive(Debug)]
pub enum Next<T> {
    /// A message.
    Msg(T),
    /// This side fell behind: so many messages were skipped (the reader goes on).
    Lagged(u64),
    /// Undecodable (the error's text).
    Bad(String),
    /// The subscription ended.
    Closed,
}

/// The next item of `s`. roslibrust 0.26 does not export its subscriber's error type; its
/// `Lagged(n)` variant is told apart by its debug form (the version is pinned).
pub async fn next<T: roslibrust::RosMessageType>(s: &mut Subscriber<T>) -> Next<T> {
    match s.next().await {
        Some(Ok(m)) => Next::Msg(m),
        Some(Err(e)) => {
            let debug = format!("{e:?}");
            match debug
                .strip_prefix("Lagged(")
                .and_then(|r| r.strip_suffix(')'))
                .and_then(|n| n.parse().ok())
            {
                Some(n) => Next::Lagged(n),
                None => Next::Bad(e.to_string()),
            }
        }
        None => Next::Closed,
    }
}

/// What the master says of this node, asked every few hundred milliseconds.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum MasterView {
    /// The master answered and lists this node as subscribed to the topic asked about.
    Registered,
    /// The master answered but does not know this node: it restarted. Every publisher and
    /// subscriber must be registered again (a new node handle).
    Forgotten,
    /// The master did not answer in time.
    Lost,
}

/// Asks `master` (within `timeout`) whether node `node` is still subscribed to `topic`.
pub async fn master_view(
    master: &roslibrust::ros1::MasterClient,
    topic: &str,
    node: &str,
    timeout: Duration,
) -> MasterView {
    match tokio::time::timeout(timeout, master.get_system_state()).await {
        Ok(Ok(state)) if state.is_subscribed(topic, node) => MasterView::Registered,
        Ok(Ok(_)) => MasterView::Forgotten,
        _ => MasterView::Lost,
    }
}

/// A topic and its message type, as the master registers it.
pub type Topic = (String, &'static str);

/// Topic `name` of message type `T`.
pub fn topic_of<T: roslibrust::RosMessageType>(name: &str) -> Topic {
    (name.to_owned(), T::DESCRIPTION.ros_type_name)
}

/// A registration the master refused or did not answer.
#[derive(Debug, thiserror::Error)]
pub enum RegisterError {
    /// Registering as a subscriber failed.
    #[error("register subscriber {topic}: {source}")]
    Subscriber {
        /// The topic.
        topic: String,
        /// The master client's error.
        source: roslibrust::ros1::RosMasterError,
    },
    /// Registering as a publisher failed.
    #[error("register publisher {topic}: {source}")]
    Publisher {
        /// The topic.
        topic: String,
        /// The master client's error.
        source: roslibrust::ros1::RosMasterError,
    },
}

/// Registers this node's topics again with a master that forgot it (it restarted), keeping the
/// node and its connections: peers that are still connected stay connected, and peers that
/// register later are told about this node. Returns whether the master already knew a
/// publisher of one of the `subscribed` topics: such a peer registered before this call and
/// may not have been connected (the caller then registers anew if nothing arrives).
pub async fn announce_again(
    master: &roslibrust::ros1::MasterClient,
    subscribed: &[Topic],
    published: &[Topic],
) -> Result<bool, RegisterError> {
    let mut known = false;
    for (topic, ty) in subscribed {
        let publishers = master
            .register_subscriber(topic.as_str(), *ty)
            .await
            .map_err(|source| RegisterError::Subscriber {
                topic: topic.clone(),
                source,
            })?;
        known |= !publishers.is_empty();
    }
    for (topic, ty) in published {
        master
            .register_publisher(topic.as_str(), *ty)
            .await
            .map_err(|source| RegisterError::Publisher {
                topic: topic.clone(),
                source,
            })?;
    }
    Ok(known)
}
