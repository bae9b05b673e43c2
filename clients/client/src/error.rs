//! The errors of [`Client`](crate::Client)'s calls, one type per call.

use herb_ipc::bus::BusError;
use herb_ipc::{BadPrefix, Fault, Invalid, RejectReason};
use std::time::Duration;

/// [`Client::connect`](crate::Client::connect) failed.
#[derive(Debug, thiserror::Error)]
pub enum ConnectError {
    /// The prefix cannot name services.
    #[error(transparent)]
    Prefix(#[from] BadPrefix),
    /// iceoryx2 could not open the node or the status subscriber.
    #[error(transparent)]
    Bus(#[from] BusError),
}

/// A job was not accepted: [`Client::submit`](crate::Client::submit),
/// [`Client::pack`](crate::Client::pack), [`Client::request`](crate::Client::request).
#[derive(Debug, thiserror::Error)]
pub enum SubmitError {
    /// The deadline passed without a reply: no herbd serves the prefix, or none answered.
    #[error("no reply from herbd (is it running with this prefix?)")]
    NoReply,
    /// The deadline passed while herbd answered `NotReady`; the fault is the last reason it
    /// gave.
    #[error("robot not ready: {}", .0.describe())]
    NotReady(Fault),
    /// herbd refused the job for a reason that is not retried (`Busy`, `Holding`, `Empty`,
    /// `TooMany`, `UnknownObject`, `Malformed`, `ShuttingDown`; see `ipc/CONTRACT.md` for the
    /// detail of each).
    #[error("rejected: {reason:?} (detail {detail})")]
    Rejected {
        /// herbd's reason.
        reason: RejectReason,
        /// Its detail: the held object's catalog type for `Holding` (or `NO_OBJECT`), the
        /// position of the bad index for `UnknownObject`, the count for `TooMany`.
        detail: u32,
    },
    /// herbd's reply failed validation.
    #[error("malformed reply: {0}")]
    MalformedReply(Invalid),
    /// iceoryx2 could not send the request.
    #[error("send: {0}")]
    Send(String),
    /// The caller's `stop` said to give up before herbd accepted the job
    /// ([`Client::submit_or_stop`](crate::Client::submit_or_stop)).
    #[error("stopped before herbd accepted the job")]
    Stopped {
        /// The last request reached herbd and got no reply within
        /// [`REPLY_WAIT`](crate::REPLY_WAIT): herbd may have taken the job after all (cancel it
        /// by its id to be sure). When `false`, herbd refused the job or none served the
        /// prefix: no job was started.
        unanswered: bool,
    },
    /// iceoryx2 could not open the pack-job client.
    #[error(transparent)]
    Bus(#[from] BusError),
}

/// A job could not be cancelled: [`Client::cancel`](crate::Client::cancel).
#[derive(Debug, thiserror::Error)]
pub enum CancelError {
    /// No herbd serves the prefix (the request found no server).
    #[error("no herbd serves this prefix")]
    NoServer,
    /// herbd did not reply within [`REPLY_WAIT`](crate::REPLY_WAIT).
    #[error("no reply from herbd")]
    NoReply,
    /// herbd answered `NoSuchJob`: no job with that id runs (it ended, or another one runs).
    #[error("job {job_id} is not running")]
    NotRunning {
        /// The job named in the request.
        job_id: u64,
    },
    /// herbd refused the cancel (`Malformed`, `ShuttingDown`).
    #[error("cancel refused: {0:?}")]
    Refused(RejectReason),
    /// herbd's reply failed validation.
    #[error("malformed reply: {0}")]
    MalformedReply(Invalid),
    /// iceoryx2 could not send the request.
    #[error("send: {0}")]
    Send(String),
    /// iceoryx2 could not open the cancel-job client.
    #[error(transparent)]
    Bus(#[from] BusError),
}

/// No heartbeat came: [`Client::status`](crate::Client::status),
/// [`Client::current_job`](crate::Client::current_job).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum StatusError {
    /// No heartbeat from herbd within the time allowed (it is not running under this prefix,
    /// or it hangs).
    #[error("no heartbeat from herbd")]
    NoHeartbeat,
}

/// Following a job ended before the job did: [`JobWatch`](crate::JobWatch).
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
pub enum WatchError {
    /// The deadline passed before the job ended.
    #[error("job {job_id} did not end before the deadline")]
    TimedOut {
        /// The job followed.
        job_id: u64,
    },
    /// herbd stayed silent (no status of the job for [`DAEMON_LOST_AFTER`](crate::DAEMON_LOST_AFTER))
    /// longer than the watch waits for it to come back.
    #[error(
        "daemon lost: no status from herbd for {:.1} s (it heartbeats at 10 Hz); job {job_id}",
        silent_for.as_secs_f64()
    )]
    DaemonLost {
        /// The job followed.
        job_id: u64,
        /// How long nothing was heard of the job.
        silent_for: Duration,
    },
    /// After it was lost, herbd heartbeats again without the job for
    /// [`BACK_WITHOUT_JOB_AFTER`](crate::BACK_WITHOUT_JOB_AFTER): it restarted without a job
    /// journal, or abandoned the job (`on_restart = "abandon"`).
    #[error("herbd came back without job {job_id} (no job journal, or the job was abandoned)")]
    CameBackWithoutJob {
        /// The job followed.
        job_id: u64,
    },
}
