//! Opening HERB's services with one set of quality-of-service settings.
//!
//! iceoryx2 lets the first process that creates a service fix its limits, and checks the
//! limits later processes ask for against them; every process therefore opens every service
//! through these functions, so start order never matters. Publishers never block (safe
//! overflow: a full subscriber queue drops its oldest sample), and each pub-sub service keeps
//! its last sample for late subscribers (history 1), so a restarted daemon sees the current
//! heightmap at once. Room is left for peers that were killed and not yet cleaned up.

use crate::{
    CancelJobReply, CancelJobRequest, ConfirmPickReply, ConfirmPickRequest, PackJobReply,
    PackJobRequest, Payload, Services,
};
use iceoryx2::node::NodeView;
use iceoryx2::port::publisher::Publisher;
use iceoryx2::port::subscriber::Subscriber;
use iceoryx2::port::{client::Client, server::Server};
use iceoryx2::prelude::*;
use iceoryx2::service::static_config::messaging_pattern::MessagingPattern as StaticPattern;

/// A publisher of HERB payload `T`.
pub type Pub<T> = Publisher<ipc::Service, T, ()>;
/// A subscriber of HERB payload `T`.
pub type Sub<T> = Subscriber<ipc::Service, T, ()>;
/// The pack-job server (herbd).
pub type JobServer = Server<ipc::Service, PackJobRequest, (), PackJobReply, ()>;
/// A pack-job client.
pub type JobClient = Client<ipc::Service, PackJobRequest, (), PackJobReply, ()>;
/// The cancel-job server (herbd).
pub type CancelServer = Server<ipc::Service, CancelJobRequest, (), CancelJobReply, ()>;
/// A cancel-job client.
pub type CancelClient = Client<ipc::Service, CancelJobRequest, (), CancelJobReply, ()>;
/// The pick-confirmation server (herbd).
pub type ConfirmServer = Server<ipc::Service, ConfirmPickRequest, (), ConfirmPickReply, ()>;
/// A pick-confirmation client.
pub type ConfirmClient = Client<ipc::Service, ConfirmPickRequest, (), ConfirmPickReply, ()>;

/// A failure to open a node, service or port, with what was being opened.
#[derive(Debug, thiserror::Error)]
#[error("iceoryx2: {what}: {message}")]
pub struct BusError {
    /// What was being opened.
    pub what: String,
    /// iceoryx2's error, or the versions that do not match.
    pub message: String,
    /// The service was created by a process of another wire version: (this process's, the
    /// service's) [`crate::PROTOCOL_VERSION`].
    pub versions: Option<(u32, u32)>,
}

fn err(what: &str, e: impl std::fmt::Debug) -> BusError {
    BusError {
        what: what.to_owned(),
        message: format!("{e:?}"),
        versions: None,
    }
}

/// The payload type names of the existing service `name` with messaging `pattern` (the
/// request's and the response's for request-response), as its creator registered them.
fn existing_type_names(name: &ServiceName, pattern: MessagingPattern) -> Vec<String> {
    let Ok(Some(d)) = ipc::Service::details(name, Config::global_config(), pattern) else {
        return Vec::new();
    };
    match d.static_details.messaging_pattern() {
        StaticPattern::PublishSubscribe(p) => {
            vec![p.message_type_details().payload.type_name().to_string()]
        }
        StaticPattern::RequestResponse(r) => vec![
            r.request_message_type_details()
                .payload
                .type_name()
                .to_string(),
            r.response_message_type_details()
                .payload
                .type_name()
                .to_string(),
        ],
        _ => Vec::new(),
    }
}

/// The iceoryx2 type name of payload `T` (`herb::v2::Status`).
fn type_name<T: Payload>() -> &'static str {
    // SAFETY: `type_name` reads a constant; it is unsafe only because the trait as a whole is.
    unsafe { <T as ZeroCopySend>::type_name() }
}

/// `e`, iceoryx2's failure to open service `name`, made into the versions' mismatch when the
/// service's payloads carry another wire version than ours (`our_type`'s): e.g. "herbd and this program
/// speak different versions of HERB's wire: this program 2, the service 1 (type
/// herb::v1::Status)".
fn open_err(
    name: &str,
    sn: &ServiceName,
    pattern: MessagingPattern,
    our_type: &str,
    e: impl std::fmt::Debug,
) -> BusError {
    let ours = crate::wire_version_of(our_type).unwrap_or(crate::PROTOCOL_VERSION);
    for t in existing_type_names(sn, pattern) {
        match crate::wire_version_of(&t) {
            Some(theirs) if theirs != ours => {
                return BusError {
                    what: name.to_owned(),
                    message: format!(
                        "wire version mismatch: this program speaks HERB wire version {ours}, the \
                         service was created by a process of version {theirs} (payload type \
                         {t}); run herbd, the adapters and the clients of one release \
                         (ipc/CONTRACT.md, \"Versions\")"
                    ),
                    versions: Some((ours, theirs)),
                };
            }
            _ => {}
        }
    }
    err(name, e)
}

/// The quality of service of a publish-subscribe service, which every process opening it must
/// request alike (`ipc/CONTRACT.md` lists them for clients in other languages).
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Qos {
    /// Publishers the service takes at most.
    pub max_publishers: usize,
    /// Subscribers it takes at most.
    pub max_subscribers: usize,
    /// Samples a new subscriber receives from before it connected.
    pub history_size: usize,
    /// Samples queued per subscriber; the oldest is overwritten when full (safe overflow).
    pub subscriber_max_buffer_size: usize,
    /// Samples a subscriber may hold at once.
    pub subscriber_max_borrowed_samples: usize,
    /// Processes (iceoryx2 nodes) the service takes at most.
    pub max_nodes: usize,
    /// A full subscriber queue drops its oldest sample (never blocks the publisher).
    pub safe_overflow: bool,
}

/// Processes a service takes at most (iceoryx2's default, set explicitly).
pub const MAX_NODES: usize = 20;

/// The settings of a request-response service (pack job, cancel job), which every process
/// opening it must request alike. They are iceoryx2 0.10's defaults, set explicitly so that
/// the contract states them.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct RequestQos {
    /// Clients at most.
    pub max_clients: usize,
    /// Servers at most (one daemon per prefix).
    pub max_servers: usize,
    /// Processes at most.
    pub max_nodes: usize,
    /// Requests a client may have awaiting a response.
    pub max_active_requests_per_client: usize,
    /// Responses a pending request buffers.
    pub max_response_buffer_size: usize,
    /// Requests a client may loan at once.
    pub max_loaned_requests: usize,
    /// Responses a client may hold at once per pending request.
    pub max_borrowed_responses_per_pending_response: usize,
    /// A full server queue drops the oldest request; a full response buffer the oldest
    /// response.
    pub safe_overflow: bool,
}

/// The settings of both request-response services.
pub const REQUEST_QOS: RequestQos = RequestQos {
    max_clients: REQUEST_MAX_CLIENTS,
    max_servers: 1,
    max_nodes: MAX_NODES,
    max_active_requests_per_client: 4,
    max_response_buffer_size: 2,
    max_loaned_requests: 2,
    max_borrowed_responses_per_pending_response: 2,
    safe_overflow: true,
};

/// The QoS of the publish-subscribe service whose name ends in `leaf` (a [`Services`] name).
///
/// One publisher for the services that command the robot or speak for it (joint and gripper
/// commands from herbd, joint and gripper states and the arm status from the arm's adapter), so no second process
/// can drive the arm or impersonate it; four for the others. Queues: 256 for events a client
/// must not lose while polling at 50 Hz (status, outcome), 2 for the 200 KB heightmap frames
/// (only the newest matters), 16 for the rest.
pub fn qos(leaf: &str) -> Qos {
    const SOLE: [&str; 5] = [
        "/joint_command",
        "/gripper_command",
        "/joint_state",
        "/gripper_state",
        "/arm_status",
    ];
    let depth = if leaf.ends_with("/status") || leaf.ends_with("/outcome") {
        256
    } else if leaf.ends_with("/heightmap") {
        2
    } else {
        16
    };
    Qos {
        max_publishers: if SOLE.iter().any(|s| leaf.ends_with(s)) {
            1
        } else {
            4
        },
        max_subscribers: 8,
        history_size: 1,
        subscriber_max_buffer_size: depth,
        subscriber_max_borrowed_samples: 2,
        max_nodes: MAX_NODES,
        safe_overflow: true,
    }
}

/// Clients each request-response service (pack job, cancel job) takes at most; each takes one
/// server (one daemon per prefix).
pub const REQUEST_MAX_CLIENTS: usize = 8;

/// The iceoryx2 node name of the daemon serving `prefix`: how a second daemon finds it.
pub fn daemon_node_name(prefix: &str) -> String {
    format!("herbd@{prefix}")
}

/// The process ids of live nodes called `name`, this process's own excluded.
pub fn live_nodes_named(name: &str) -> Result<Vec<u32>, BusError> {
    // iceoryx2's own notices ("No config file was loaded": its config, not HERB's) stay quiet.
    set_log_level(LogLevel::Error);
    let me = std::process::id();
    let mut found = Vec::new();
    Node::<ipc::Service>::list(Config::global_config(), |state| {
        if let NodeState::Alive(view) = state
            && let Some(d) = view.details()
            && d.name().as_str() == name
        {
            let pid = d.process_id().value() as u32;
            if pid != me {
                found.push(pid);
            }
        }
        CallbackProgression::Continue
    })
    .map_err(|e| err("node list", e))?;
    Ok(found)
}

/// A node and the service names of one HERB instance. Not `Send`: open one per thread.
pub struct Bus {
    node: Node<ipc::Service>,
    services: Services,
}

impl std::fmt::Debug for Bus {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Bus")
            .field("services", &self.services)
            .finish()
    }
}

/// How long opening a service waits for another process that is creating or removing it at
/// the same moment (iceoryx2's default is 1 s). On a loaded machine, herbd restarting while a
/// client's last port on a service goes away took longer than 1 s in CI and herbd refused to
/// start (`HangsInCreation`); a cell whose processes all start at boot is as loaded.
pub const CREATION_TIMEOUT: std::time::Duration = std::time::Duration::from_secs(10);

impl Bus {
    /// Opens a node named `name` for the services under `services`, first removing what dead
    /// processes left behind. iceoryx2 does not take over SIGINT/SIGTERM (the processes handle
    /// them), and logs only errors. A service another process is creating or removing at the
    /// same moment is waited for up to [`CREATION_TIMEOUT`].
    pub fn open(name: &str, services: &Services) -> Result<Self, BusError> {
        set_log_level(LogLevel::Error);
        let node_name: NodeName = name.try_into().map_err(|e| err(name, e))?;
        let mut config = Config::global_config().clone();
        config.global.creation_timeout = config.global.creation_timeout.max(CREATION_TIMEOUT);
        let node = NodeBuilder::new()
            .name(&node_name)
            .config(&config)
            .signal_handling_mode(SignalHandlingMode::Disabled)
            .create::<ipc::Service>()
            .map_err(|e| err("node", e))?;
        // Ports of processes that died without closing them (SIGKILL, a crash) would hold the
        // one publisher slot of a robot service: remove them before opening any.
        node.try_cleanup_dead_nodes();
        Ok(Self {
            node,
            services: services.clone(),
        })
    }

    /// The service names.
    pub fn services(&self) -> &Services {
        &self.services
    }

    fn pubsub<T: Payload>(
        &self,
        name: &str,
    ) -> Result<
        iceoryx2::service::port_factory::publish_subscribe::PortFactory<ipc::Service, T, ()>,
        BusError,
    > {
        let sn: ServiceName = name.try_into().map_err(|e| err(name, e))?;
        let q = qos(name);
        self.node
            .service_builder(&sn)
            .publish_subscribe::<T>()
            .max_publishers(q.max_publishers)
            .max_subscribers(q.max_subscribers)
            .history_size(q.history_size)
            .subscriber_max_buffer_size(q.subscriber_max_buffer_size)
            .subscriber_max_borrowed_samples(q.subscriber_max_borrowed_samples)
            .max_nodes(q.max_nodes)
            .enable_safe_overflow(q.safe_overflow)
            .open_or_create()
            .map_err(|e| {
                open_err(
                    name,
                    &sn,
                    MessagingPattern::PublishSubscribe,
                    type_name::<T>(),
                    e,
                )
            })
    }

    /// A publisher on service `name` (one of [`Services`]'s names).
    pub fn publisher<T: Payload>(&self, name: &str) -> Result<Pub<T>, BusError> {
        self.pubsub::<T>(name)?
            .publisher_builder()
            .max_loaned_samples(2)
            .backpressure_strategy(BackpressureStrategy::DiscardData)
            .create()
            .map_err(|e| err(name, e))
    }

    /// A subscriber on service `name`.
    pub fn subscriber<T: Payload>(&self, name: &str) -> Result<Sub<T>, BusError> {
        self.pubsub::<T>(name)?
            .subscriber_builder()
            .create()
            .map_err(|e| err(name, e))
    }

    /// A request-response service of HERB (herbd is its one server).
    fn request_response<Q: Payload, R: Payload>(
        &self,
        name: &str,
    ) -> Result<
        iceoryx2::service::port_factory::request_response::PortFactory<ipc::Service, Q, (), R, ()>,
        BusError,
    > {
        let sn: ServiceName = name.try_into().map_err(|e| err(name, e))?;
        let q = REQUEST_QOS;
        self.node
            .service_builder(&sn)
            .request_response::<Q, R>()
            .max_clients(q.max_clients)
            .max_servers(q.max_servers) // one daemon per prefix
            .max_nodes(q.max_nodes)
            .max_active_requests_per_client(q.max_active_requests_per_client)
            .max_response_buffer_size(q.max_response_buffer_size)
            .max_loaned_requests(q.max_loaned_requests)
            .max_borrowed_responses_per_pending_response(
                q.max_borrowed_responses_per_pending_response,
            )
            .enable_safe_overflow_for_requests(q.safe_overflow)
            .enable_safe_overflow_for_responses(q.safe_overflow)
            .open_or_create()
            .map_err(|e| {
                open_err(
                    name,
                    &sn,
                    MessagingPattern::RequestResponse,
                    type_name::<Q>(),
                    e,
                )
            })
    }

    /// The pack-job server.
    pub fn job_server(&self) -> Result<JobServer, BusError> {
        let name = self.services.pack_job();
        self.request_response(&name)?
            .server_builder()
            .create()
            .map_err(|e| err(&name, e))
    }

    /// A pack-job client.
    pub fn job_client(&self) -> Result<JobClient, BusError> {
        let name = self.services.pack_job();
        self.request_response(&name)?
            .client_builder()
            .create()
            .map_err(|e| err(&name, e))
    }

    /// The cancel-job server.
    pub fn cancel_server(&self) -> Result<CancelServer, BusError> {
        let name = self.services.cancel_job();
        self.request_response(&name)?
            .server_builder()
            .create()
            .map_err(|e| err(&name, e))
    }

    /// A cancel-job client.
    pub fn cancel_client(&self) -> Result<CancelClient, BusError> {
        let name = self.services.cancel_job();
        self.request_response(&name)?
            .client_builder()
            .create()
            .map_err(|e| err(&name, e))
    }

    /// The pick-confirmation server.
    pub fn confirm_server(&self) -> Result<ConfirmServer, BusError> {
        let name = self.services.confirm_pick();
        self.request_response(&name)?
            .server_builder()
            .create()
            .map_err(|e| err(&name, e))
    }

    /// A pick-confirmation client.
    pub fn confirm_client(&self) -> Result<ConfirmClient, BusError> {
        let name = self.services.confirm_pick();
        self.request_response(&name)?
            .client_builder()
            .create()
            .map_err(|e| err(&name, e))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Every node HERB opens waits [`CREATION_TIMEOUT`] for a service in creation or removal,
    /// not iceoryx2's default second.
    #[test]
    fn a_bus_waits_longer_than_iceoryx2s_default_for_a_service_in_flux() {
        let services = Services::new(&format!("bustest{}", std::process::id())).unwrap();
        let bus = Bus::open("bus-test", &services).unwrap();
        assert_eq!(bus.node.config().global.creation_timeout, CREATION_TIMEOUT);
        assert!(CREATION_TIMEOUT > Config::default().global.creation_timeout);
    }
}
