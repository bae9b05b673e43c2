//! Following herbd's statuses: one job ([`JobWatch`]) or the whole cell ([`Statuses`]).

use crate::{BACK_WITHOUT_JOB_AFTER, DAEMON_LOST_AFTER, WatchError, ends_job};
use herb_ipc::bus::Sub;
use herb_ipc::{Status, StatusEvent};
use std::collections::VecDeque;
use std::time::{Duration, Instant};

/// How often [`JobWatch::next_event`] looks for statuses while none is queued.
const POLL: Duration = Duration::from_millis(5);

/// What following a job brings, in the order it happened.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum JobEvent {
    /// A (valid) status of the job: `Accepted`, `Decided`, `Placed`, `Fault`, ..., its
    /// heartbeats while it runs, and last the one that ends it (see [`crate::END_EVENTS`]).
    Status(Status),
    /// No status of the job for `silent_for` (more than [`DAEMON_LOST_AFTER`]): herbd is gone
    /// (killed, crashed). The watch now waits up to its `reconnect` time for herbd to come back
    /// with the job (a restarted herbd takes an unfinished job up from its journal). Not sent
    /// when `reconnect` is zero: the watch then ends with [`WatchError::DaemonLost`] at once.
    Lost {
        /// How long nothing was heard of the job.
        silent_for: Duration,
    },
    /// herbd is heard again with the job after [`JobEvent::Lost`]; the job's status follows.
    Back,
}

/// Follows one job's statuses to its end: [`crate::Client::watch`], [`crate::Client::pack`].
///
/// Statuses of other jobs and idle heartbeats are skipped, and so are invalid ones. The job
/// ends with its first status whose event is one of [`crate::END_EVENTS`]; statuses of the job
/// already queued behind it are still handed out, then the watch is finished. It ends early
/// with a [`WatchError`] when the deadline passes, when herbd has been silent for
/// [`DAEMON_LOST_AFTER`] and did not come back with the job within `reconnect`, or when it came
/// back heartbeating without the job for [`BACK_WITHOUT_JOB_AFTER`].
///
/// [`JobWatch::poll`] never blocks, so that a caller can read other services between calls;
/// [`JobWatch::next_event`], the [`Iterator`] and [`JobWatch::wait`] block. The watch reads
/// the client's status subscriber: while it is used, [`crate::Client::statuses`] would take
/// statuses from it.
pub struct JobWatch<'a> {
    status: &'a Sub<Status>,
    job_id: u64,
    deadline: Instant,
    reconnect: Duration,
    /// When a status of the job last came (or the watch began).
    heard: Instant,
    /// Since when herbd is taken as lost and waited for.
    lost_since: Option<Instant>,
    /// When a herbd that was lost first heartbeated without the job.
    back_without: Option<Instant>,
    last: Option<Status>,
    end: Option<Status>,
    pending: VecDeque<JobEvent>,
    /// An error found by the checks, returned after the events they queued.
    error: Option<WatchError>,
    /// The error that ended the watch.
    failed: Option<WatchError>,
    /// Between the checks at the start of a round and the end of its queued statuses.
    in_round: bool,
    finished: bool,
}

impl std::fmt::Debug for JobWatch<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("JobWatch")
            .field("job_id", &self.job_id)
            .field("deadline", &self.deadline)
            .field("reconnect", &self.reconnect)
            .field("lost_since", &self.lost_since)
            .field("last", &self.last)
            .field("end", &self.end)
            .field("finished", &self.finished)
            .finish_non_exhaustive()
    }
}

impl<'a> JobWatch<'a> {
    pub(crate) fn new(
        status: &'a Sub<Status>,
        job_id: u64,
        deadline: Instant,
        reconnect: Duration,
    ) -> Self {
        Self {
            status,
            job_id,
            deadline,
            reconnect,
            heard: Instant::now(),
            lost_since: None,
            back_without: None,
            last: None,
            end: None,
            pending: VecDeque::new(),
            error: None,
            failed: None,
            in_round: false,
            finished: false,
        }
    }

    /// The job followed.
    pub fn job_id(&self) -> u64 {
        self.job_id
    }

    /// The last status of the job received so far.
    pub fn latest(&self) -> Option<&Status> {
        self.last.as_ref()
    }

    /// The status that ended the job, once received.
    pub fn end(&self) -> Option<&Status> {
        self.end.as_ref()
    }

    /// Whether the watch is over: the job ended and its queued statuses were handed out, or
    /// an error was returned. [`JobWatch::poll`] then returns `Ok(None)`.
    pub fn is_finished(&self) -> bool {
        self.finished
    }

    /// The next event if one is there, without waiting: `Ok(None)` when nothing is queued now
    /// (or the watch is finished). Each round of calls starts with the checks (deadline,
    /// herbd lost, back without the job), then hands out the queued statuses one a call, until
    /// `Ok(None)` ends the round. An error ends the watch.
    pub fn poll(&mut self) -> Result<Option<JobEvent>, WatchError> {
        if self.finished {
            return Ok(None);
        }
        if !self.in_round {
            self.in_round = true;
            if let Err(e) = self.check() {
                self.error = Some(e);
            }
        }
        if let Some(ev) = self.pending.pop_front() {
            return Ok(Some(ev));
        }
        if let Some(e) = self.error.take() {
            self.finished = true;
            self.failed = Some(e.clone());
            return Err(e);
        }
        while let Ok(Some(sample)) = self.status.receive() {
            let s = *sample.payload();
            drop(sample);
            if s.validate().is_err() {
                continue;
            }
            if s.job_id != self.job_id {
                // A herbd heartbeating again after it was lost, without the job.
                if self.lost_since.is_some()
                    && self.back_without.is_none()
                    && s.event == StatusEvent::Heartbeat as u32
                {
                    self.back_without = Some(Instant::now());
                }
                continue;
            }
            self.back_without = None;
            self.heard = Instant::now();
            self.last = Some(s);
            if self.end.is_none() && ends_job(&s) {
                self.end = Some(s);
            }
            if self.lost_since.take().is_some() {
                self.pending.push_back(JobEvent::Status(s));
                return Ok(Some(JobEvent::Back));
            }
            return Ok(Some(JobEvent::Status(s)));
        }
        self.in_round = false;
        if self.end.is_some() {
            self.finished = true;
        }
        Ok(None)
    }

    /// The checks at the start of a round: the deadline, herbd silent (lost, waited for, given
    /// up), herbd back without the job.
    fn check(&mut self) -> Result<(), WatchError> {
        let job_id = self.job_id;
        if Instant::now() > self.deadline {
            return Err(WatchError::TimedOut { job_id });
        }
        let silent = self.heard.elapsed();
        if silent > DAEMON_LOST_AFTER && self.lost_since.is_none() && !self.reconnect.is_zero() {
            self.pending
                .push_back(JobEvent::Lost { silent_for: silent });
            self.lost_since = Some(Instant::now());
        }
        // Back, but idle: its journal did not have the job (none configured, or abandoned).
        if self
            .back_without
            .is_some_and(|t| t.elapsed() > BACK_WITHOUT_JOB_AFTER)
        {
            return Err(WatchError::CameBackWithoutJob { job_id });
        }
        let waited_out = self.lost_since.is_none_or(|t| t.elapsed() > self.reconnect);
        let silent = self.heard.elapsed();
        if silent > DAEMON_LOST_AFTER && waited_out {
            return Err(WatchError::DaemonLost {
                job_id,
                silent_for: silent,
            });
        }
        Ok(())
    }

    /// The next event, waiting for it (polling every 5 ms); `Ok(None)` once the watch is
    /// finished.
    pub fn next_event(&mut self) -> Result<Option<JobEvent>, WatchError> {
        loop {
            if let Some(ev) = self.poll()? {
                return Ok(Some(ev));
            }
            if self.finished {
                return Ok(None);
            }
            std::thread::sleep(POLL);
        }
    }

    /// Follows the job to its end and returns the status that ended it (or the error that
    /// ended the watch, also when it was returned before).
    pub fn wait(mut self) -> Result<Status, WatchError> {
        while self.next_event()?.is_some() {}
        match (self.end, self.failed) {
            (Some(end), _) => Ok(end),
            (None, Some(e)) => Err(e),
            // A watch finishes only at the job's end or on an error.
            (None, None) => Err(WatchError::TimedOut {
                job_id: self.job_id,
            }),
        }
    }
}

impl Iterator for JobWatch<'_> {
    type Item = Result<JobEvent, WatchError>;

    /// [`JobWatch::next_event`]: `None` once the watch is finished (after an error too).
    fn next(&mut self) -> Option<Self::Item> {
        self.next_event().transpose()
    }
}

/// The cell's statuses received since the last read, valid ones only, without waiting:
/// [`crate::Client::statuses`]. Ends when none is queued; a later call may bring more.
pub struct Statuses<'a> {
    pub(crate) status: &'a Sub<Status>,
}

impl std::fmt::Debug for Statuses<'_> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("Statuses").finish_non_exhaustive()
    }
}

impl Iterator for Statuses<'_> {
    type Item = Status;

    fn next(&mut self) -> Option<Status> {
        while let Ok(Some(sample)) = self.status.receive() {
            let s = *sample.payload();
            if s.validate().is_ok() {
                return Some(s);
            }
        }
        None
    }
}
