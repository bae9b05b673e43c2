//! A Rust client of `herbd`, HERB's packing controller, over iceoryx2 shared memory: what
//! `ipc/CONTRACT.md` ("A job, seen by a client") asks of a client, in one place, for `herbctl`,
//! the end-to-end tests and other Rust programs. The Python client (`clients/python`) is its
//! counterpart for other languages.
//!
//! - [`Client::connect`] opens a node under a service prefix and subscribes to herbd's
//!   `status` at once, so that every status of a job submitted afterwards is received.
//! - [`Client::submit`] sends a pack job and retries it by the contract's rules: while no herbd
//!   serves the prefix (every [`NO_SERVER_RETRY`]), when no reply came within [`REPLY_WAIT`]
//!   (sent again), and while herbd answers `NotReady` (every [`NOT_READY_RETRY`], the reason
//!   handed to the caller each time); every other rejection is returned at once, and the
//!   deadline ends it all. [`Client::submit_or_stop`] also gives up between tries when the
//!   caller says so (Ctrl-C before the job was accepted). [`Client::pack`] submits and returns
//!   a [`JobWatch`] on the same deadline.
//! - [`Client::watch`] follows one job's statuses to its end, through a daemon restart: when
//!   herbd falls silent for [`DAEMON_LOST_AFTER`] it waits up to a `reconnect` time for herbd
//!   to come back with the job (a restarted herbd takes it up from its journal), and gives up
//!   when herbd comes back without it. [`Client::statuses`] reads the whole cell's statuses.
//! - [`Client::status`] is one snapshot (herbd's heartbeat), [`Client::current_job`] the job
//!   it runs, [`Client::cancel`] cancels one.
//!
//! **Job ids.** The client chooses a job's id ([`new_job_id`], or its own, non-zero) and every
//! try of a submission carries the same one; herbd echoes it in its reply and in every status
//! of the job, which is how a client tells its job's statuses from others'. herbd does not
//! remember ids: it answers each request on its own, so should the reply to an accepted
//! request be lost, the request sent again is answered `Busy` (the job itself runs), and
//! [`Client::submit`] returns that rejection.
//!
//! ```no_run
//! use herb_client::{Client, JobEvent, PackOptions, StatusEvent};
//!
//! let client = Client::connect("herb")?;
//! // Catalog type indices (positions in models/objects.toml), not BoxED ids.
//! let mut job = client.pack(&[1, 3], &PackOptions::default(), |why| {
//!     eprintln!("robot not ready: {}; waiting", why.describe())
//! })?;
//! for event in &mut job {
//!     match event? {
//!         JobEvent::Status(s) if s.event == StatusEvent::Placed as u32 => {
//!             println!("placed: {} of {} objects", s.objects_done, s.objects_total)
//!         }
//!         JobEvent::Lost { silent_for } => println!("herbd silent for {silent_for:?}"),
//!         _ => {}
//!     }
//! }
//! let end = job.end().expect("followed to its end");
//! println!("job {}: {:?}", job.job_id(), StatusEvent::from_code(end.event));
//! # Ok::<(), Box<dyn std::error::Error>>(())
//! ```

#![warn(missing_docs)]

mod error;
pub mod view;
mod watch;

pub use error::{CancelError, ConnectError, StatusError, SubmitError, WatchError};
pub use herb_ipc::{Fault, JobState, RejectReason, Status, StatusEvent};
pub use watch::{JobEvent, JobWatch, Statuses};

use herb_ipc::bus::{Bus, BusError, CancelClient, ConfirmClient, JobClient, Sub};
use herb_ipc::{
    CancelJobRequest, ConfirmPickRequest, PackJobReply, PackJobRequest, Services, monotonic_ns,
};
use std::cell::OnceCell;
use std::time::{Duration, Instant};

/// herbd heartbeats at 10 Hz: a client that hears nothing of it for this long (five periods)
/// takes it as gone (killed, crashed: a killed herbd cannot send a last message).
pub const DAEMON_LOST_AFTER: Duration = Duration::from_millis(500);
/// A herbd that was lost and heartbeats again without the job for this long has not taken
/// the job up (no journal, or `on_restart = "abandon"`): the job is gone.
pub const BACK_WITHOUT_JOB_AFTER: Duration = Duration::from_secs(3);
/// How long a request waits for herbd's reply before it is sent again (a pack job) or given
/// up (a cancel).
pub const REPLY_WAIT: Duration = Duration::from_secs(2);
/// Between tries of a pack job while no herbd serves the prefix.
pub const NO_SERVER_RETRY: Duration = Duration::from_millis(100);
/// Between tries of a pack job while herbd answers `NotReady`.
pub const NOT_READY_RETRY: Duration = Duration::from_millis(200);
/// The events that end a job, as a client following it sees them: done, failed, cancelled,
/// and herbd's `Shutdown` (after SIGINT/SIGTERM) while it runs.
pub const END_EVENTS: [StatusEvent; 4] = [
    StatusEvent::JobDone,
    StatusEvent::JobFailed,
    StatusEvent::JobCancelled,
    StatusEvent::Shutdown,
];

/// How often a reply is looked for.
const REPLY_POLL: Duration = Duration::from_millis(2);
/// How often [`Client::submit_or_stop`] asks its `stop` while it waits between tries.
pub const STOP_POLL: Duration = Duration::from_millis(20);
/// How often [`Client::status`] looks for a heartbeat.
const STATUS_POLL: Duration = Duration::from_millis(20);
/// How often [`Client::current_job`] looks for a heartbeat.
const CURRENT_JOB_POLL: Duration = Duration::from_millis(10);

/// A fresh, non-zero job id: the low 32 bits of the monotonic clock (ns), shifted, with this
/// process's id in the low 16 bits, odd (what herbctl and the Python client use).
pub fn new_job_id() -> u64 {
    ((monotonic_ns() & 0xffff_ffff) << 16) | (std::process::id() as u64 & 0xffff) | 1
}

/// Whether status `s` ends its job (its event is one of [`END_EVENTS`]).
pub fn ends_job(s: &Status) -> bool {
    StatusEvent::from_code(s.event).is_some_and(|e| END_EVENTS.contains(&e))
}

/// How [`Client::pack`] submits and follows a job.
#[derive(Debug, Clone, PartialEq)]
pub struct PackOptions {
    /// The job's id; `None`: a [`new_job_id`].
    pub job_id: Option<u64>,
    /// Submitting and following together end after this long.
    pub timeout: Duration,
    /// How long to wait for a lost herbd to come back with the job; zero gives up at once.
    pub reconnect: Duration,
}

impl Default for PackOptions {
    /// A new id, 900 s, 60 s: herbctl's defaults.
    fn default() -> Self {
        Self {
            job_id: None,
            timeout: Duration::from_secs(900),
            reconnect: Duration::from_secs(60),
        }
    }
}

/// What one try of a pack-job request brought.
enum Exchange {
    /// No server connected: no herbd serves the prefix.
    NoServer,
    /// Sent, and no reply within [`REPLY_WAIT`].
    Silent,
    Reply(PackJobReply),
}

/// A client of the herbd serving one prefix: its node, its subscriber to herbd's `status`
/// (opened by [`Client::connect`]) and, once used, its pack-job and cancel-job clients. Not
/// `Send` (iceoryx2's ports): open one per thread.
pub struct Client {
    bus: Bus,
    status: Sub<Status>,
    jobs: OnceCell<JobClient>,
    cancels: OnceCell<CancelClient>,
    confirms: OnceCell<ConfirmClient>,
}

impl std::fmt::Debug for Client {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Client")
            .field("prefix", &self.bus.services().prefix())
            .finish_non_exhaustive()
    }
}

/// Sleeps `d`, or less once `stop` returns `true` (asked every [`STOP_POLL`]).
fn pause(d: Duration, stop: &mut impl FnMut() -> bool) {
    let t0 = Instant::now();
    while t0.elapsed() < d && !stop() {
        std::thread::sleep(STOP_POLL.min(d.saturating_sub(t0.elapsed())));
    }
}

/// `now + d`, or far in the future if that cannot be represented.
fn after(d: Duration) -> Instant {
    let now = Instant::now();
    now.checked_add(d)
        .unwrap_or_else(|| now + Duration::from_secs(100 * 365 * 86_400))
}

impl Client {
    /// The iceoryx2 node name [`Client::connect`] uses.
    pub const DEFAULT_NAME: &'static str = "herb-client";

    /// Connects to the herbd serving `prefix` (`herb` by default, herbd's `ipc_prefix`): opens
    /// a node named [`Client::DEFAULT_NAME`] and subscribes to `status`. herbd need not run
    /// yet: the services are opened with the contract's settings (or created with them).
    pub fn connect(prefix: &str) -> Result<Self, ConnectError> {
        Self::connect_as(prefix, Self::DEFAULT_NAME)
    }

    /// [`Client::connect`] with node name `name` (how the process shows in iceoryx2's node
    /// list, e.g. `herbctl`).
    pub fn connect_as(prefix: &str, name: &str) -> Result<Self, ConnectError> {
        let services = Services::new(prefix)?;
        let bus = Bus::open(name, &services)?;
        let status = bus.subscriber::<Status>(&services.status())?;
        Ok(Self {
            bus,
            status,
            jobs: OnceCell::new(),
            cancels: OnceCell::new(),
            confirms: OnceCell::new(),
        })
    }

    /// The node, to open other services of the prefix (heightmaps, simulated outcomes...).
    pub fn bus(&self) -> &Bus {
        &self.bus
    }

    /// The service names under the client's prefix.
    pub fn services(&self) -> &Services {
        self.bus.services()
    }

    fn jobs(&self) -> Result<&JobClient, BusError> {
        if let Some(c) = self.jobs.get() {
            return Ok(c);
        }
        let c = self.bus.job_client()?;
        Ok(self.jobs.get_or_init(|| c))
    }

    fn cancels(&self) -> Result<&CancelClient, BusError> {
        if let Some(c) = self.cancels.get() {
            return Ok(c);
        }
        let c = self.bus.cancel_client()?;
        Ok(self.cancels.get_or_init(|| c))
    }

    /// One try: sends `request` and waits [`REPLY_WAIT`] for the reply.
    fn exchange(jobs: &JobClient, request: PackJobRequest) -> Result<Exchange, SubmitError> {
        let pending = jobs
            .send_copy(request)
            .map_err(|e| SubmitError::Send(format!("{e:?}")))?;
        if pending.number_of_server_connections() == 0 {
            return Ok(Exchange::NoServer);
        }
        let t0 = Instant::now();
        while t0.elapsed() < REPLY_WAIT {
            if let Ok(Some(r)) = pending.receive() {
                return Ok(Exchange::Reply(*r.payload()));
            }
            std::thread::sleep(REPLY_POLL);
        }
        Ok(Exchange::Silent)
    }

    /// Sends `request` as it is and returns herbd's reply, whatever it says: waits for a
    /// server (every [`NO_SERVER_RETRY`]) and sends the request again when no reply came
    /// within [`REPLY_WAIT`], until `deadline` ([`SubmitError::NoReply`]). For requests
    /// [`Client::submit`] would not build (a test's malformed ones); `NotReady` is returned,
    /// not retried.
    pub fn request(
        &self,
        request: &PackJobRequest,
        deadline: Instant,
    ) -> Result<PackJobReply, SubmitError> {
        let jobs = self.jobs()?;
        loop {
            if Instant::now() > deadline {
                return Err(SubmitError::NoReply);
            }
            match Self::exchange(jobs, *request)? {
                Exchange::NoServer => std::thread::sleep(NO_SERVER_RETRY),
                Exchange::Silent => {}
                Exchange::Reply(r) => return Ok(r),
            }
        }
    }

    /// Submits job `job_id` (non-zero) of catalog type indices `objects` and returns once herbd
    /// accepted it, retrying by the contract's rules until `deadline`:
    ///
    /// - no herbd serves the prefix: tried again every [`NO_SERVER_RETRY`];
    /// - no reply within [`REPLY_WAIT`]: sent again;
    /// - `NotReady`: `on_not_ready` is called with the reason (the reply's detail, a
    ///   [`Fault`]; `JointStateTimeout` if it names none) and the job sent again after
    ///   [`NOT_READY_RETRY`];
    /// - any other rejection: returned at once ([`SubmitError::Rejected`]).
    ///
    /// Each try is a new request (stamped when sent) with the same job id. At the deadline:
    /// [`SubmitError::NotReady`] with the last reason if herbd said so, else
    /// [`SubmitError::NoReply`].
    pub fn submit(
        &self,
        job_id: u64,
        objects: &[u16],
        deadline: Instant,
        on_not_ready: impl FnMut(Fault),
    ) -> Result<(), SubmitError> {
        self.submit_or_stop(job_id, objects, 0, deadline, on_not_ready, || false)
    }

    /// [`Client::submit`], given up once `stop` returns `true` ([`SubmitError::Stopped`]):
    /// for a caller that stops on a signal (herbctl on Ctrl-C). `stop` is asked before each
    /// try and every [`STOP_POLL`] while waiting between tries; a try under way (up to
    /// [`REPLY_WAIT`]) is finished first, so a job herbd accepted is returned as accepted,
    /// never dropped by the stop (the caller then cancels it). `flags`: the request's
    /// [`PackJobRequest::flags`] (e.g. [`PackJobRequest::CONFIRM_PICKS`]).
    pub fn submit_or_stop(
        &self,
        job_id: u64,
        objects: &[u16],
        flags: u32,
        deadline: Instant,
        mut on_not_ready: impl FnMut(Fault),
        mut stop: impl FnMut() -> bool,
    ) -> Result<(), SubmitError> {
        let jobs = self.jobs()?;
        let mut not_ready: Option<Fault> = None;
        // Whether the last request reached a server and went unanswered.
        let mut unanswered = false;
        loop {
            if stop() {
                return Err(SubmitError::Stopped { unanswered });
            }
            if Instant::now() > deadline {
                return Err(match not_ready {
                    Some(f) => SubmitError::NotReady(f),
                    None => SubmitError::NoReply,
                });
            }
            let mut request = PackJobRequest::new(job_id, objects);
            request.flags = flags;
            let reply = match Self::exchange(jobs, request)? {
                Exchange::NoServer => {
                    unanswered = false;
                    pause(NO_SERVER_RETRY, &mut stop);
                    continue;
                }
                Exchange::Silent => {
                    unanswered = true;
                    continue;
                }
                Exchange::Reply(r) => r,
            };
            unanswered = false;
            match reply.validate() {
                Ok(RejectReason::None) => return Ok(()),
                Ok(RejectReason::NotReady) => {
                    let why = Fault::from_code(reply.detail).unwrap_or(Fault::JointStateTimeout);
                    not_ready = Some(why);
                    on_not_ready(why);
                    pause(NOT_READY_RETRY, &mut stop);
                }
                Ok(reason) => {
                    return Err(SubmitError::Rejected {
                        reason,
                        detail: reply.detail,
                    });
                }
                Err(e) => return Err(SubmitError::MalformedReply(e)),
            }
        }
    }

    /// Submits a job ([`Client::submit`]) and returns the [`JobWatch`] that follows it, both
    /// within `options.timeout`.
    pub fn pack(
        &self,
        objects: &[u16],
        options: &PackOptions,
        on_not_ready: impl FnMut(Fault),
    ) -> Result<JobWatch<'_>, SubmitError> {
        let deadline = after(options.timeout);
        let job_id = options.job_id.unwrap_or_else(new_job_id);
        self.submit(job_id, objects, deadline, on_not_ready)?;
        Ok(self.watch(job_id, deadline, options.reconnect))
    }

    /// Follows job `job_id` from now until it ends, or `deadline`; waits up to `reconnect`
    /// for a herbd that fell silent to come back with the job (see [`JobWatch`]).
    pub fn watch(&self, job_id: u64, deadline: Instant, reconnect: Duration) -> JobWatch<'_> {
        JobWatch::new(&self.status, job_id, deadline, reconnect)
    }

    /// The cell's statuses (every job's, heartbeats included; invalid ones skipped) received
    /// since the last read, without waiting.
    pub fn statuses(&self) -> Statuses<'_> {
        Statuses {
            status: &self.status,
        }
    }

    /// The newest heartbeat of the first statuses that bring one, polling every `poll`, for
    /// up to `within`. A heartbeat stamped more than [`DAEMON_LOST_AFTER`] ago (a long-lived
    /// client's queue) does not count.
    fn heartbeat(&self, within: Duration, poll: Duration) -> Result<Status, StatusError> {
        let t0 = Instant::now();
        while t0.elapsed() < within {
            let fresh = |s: &Status| {
                monotonic_ns().saturating_sub(s.header.stamp_ns)
                    <= DAEMON_LOST_AFTER.as_nanos() as u64
            };
            if let Some(s) = self
                .statuses()
                .filter(|s| s.event == StatusEvent::Heartbeat as u32 && fresh(s))
                .last()
            {
                return Ok(s);
            }
            std::thread::sleep(poll);
        }
        Err(StatusError::NoHeartbeat)
    }

    /// One snapshot of herbd: its next heartbeat (10 Hz), waited for up to `timeout`. Between
    /// jobs its `fault` says why a job would be refused now (`None`: ready).
    pub fn status(&self, timeout: Duration) -> Result<Status, StatusError> {
        self.heartbeat(timeout, STATUS_POLL)
    }

    /// The job herbd runs, from its next heartbeat (waited for up to `within`); `None` when
    /// idle.
    pub fn current_job(&self, within: Duration) -> Result<Option<u64>, StatusError> {
        let s = self.heartbeat(within, CURRENT_JOB_POLL)?;
        Ok((s.job_id != 0).then_some(s.job_id))
    }

    /// Asks herbd to cancel job `job_id` and returns once it accepted (a repeat while the
    /// cancel proceeds is accepted again). Sent once: no server is [`CancelError::NoServer`],
    /// no reply within [`REPLY_WAIT`] [`CancelError::NoReply`]. herbd then brakes, lifts the
    /// gripper and ends the job `JobCancelled`: follow it with [`Client::watch`].
    pub fn cancel(&self, job_id: u64) -> Result<(), CancelError> {
        let reply = ask(self.cancels()?, CancelJobRequest::new(job_id))?;
        control_verdict(job_id, reply.validate())
    }

    /// Tells herbd that the object its job `job_id` waits for ([`StatusEvent::AwaitingObject`]:
    /// `object_index`, try `attempt`) is at the pick station: the arm descends and grasps it.
    /// Sent once, as [`Client::cancel`]; `NotAwaited` (another object or try, or a job not
    /// submitted with [`PackJobRequest::CONFIRM_PICKS`]) comes back as
    /// [`CancelError::Refused`].
    pub fn confirm_pick(
        &self,
        job_id: u64,
        object_index: u32,
        attempt: u32,
    ) -> Result<(), CancelError> {
        let confirms = match self.confirms.get() {
            Some(c) => c,
            None => {
                let c = self.bus.confirm_client()?;
                self.confirms.get_or_init(|| c)
            }
        };
        let reply = ask(
            confirms,
            ConfirmPickRequest::new(job_id, object_index, attempt),
        )?;
        control_verdict(job_id, reply.validate())
    }
}

/// Sends `request` once on a job-control service (cancel, confirm) and waits up to
/// [`REPLY_WAIT`] for the reply.
fn ask<Req, Rep>(
    client: &iceoryx2::port::client::Client<iceoryx2::prelude::ipc::Service, Req, (), Rep, ()>,
    request: Req,
) -> Result<Rep, CancelError>
where
    Req: iceoryx2::prelude::ZeroCopySend + std::fmt::Debug + Copy,
    Rep: iceoryx2::prelude::ZeroCopySend + std::fmt::Debug + Copy,
{
    let pending = client
        .send_copy(request)
        .map_err(|e| CancelError::Send(format!("{e:?}")))?;
    if pending.number_of_server_connections() == 0 {
        return Err(CancelError::NoServer);
    }
    let t0 = Instant::now();
    loop {
        if let Ok(Some(r)) = pending.receive() {
            return Ok(*r.payload());
        }
        if t0.elapsed() > REPLY_WAIT {
            return Err(CancelError::NoReply);
        }
        std::thread::sleep(REPLY_POLL);
    }
}

/// A job-control reply's reason as the caller's result.
fn control_verdict(
    job_id: u64,
    reason: Result<RejectReason, herb_ipc::Invalid>,
) -> Result<(), CancelError> {
    match reason {
        Ok(RejectReason::None) => Ok(()),
        Ok(RejectReason::NoSuchJob) => Err(CancelError::NotRunning { job_id }),
        Ok(reason) => Err(CancelError::Refused(reason)),
        Err(e) => Err(CancelError::MalformedReply(e)),
    }
}
