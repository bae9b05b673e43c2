//! The job's state as it is kept outside the machine: one type, [`JobRecord`], and one encoding.
//!
//! A record says which job runs, its objects and their packing order, how far it got, where
//! the current object stands and where it was decided to go. The job journal
//! ([`crate::journal`]) keeps the running job's record so that a restarted daemon takes the job
//! up ([`Job::recover`](super::Job::recover)); a run log's later segment starts from a
//! [`JobSnapshot`](super::JobSnapshot) whose `job` is the last job's record, so that the replay
//! starts from the same state. Both write it with [`JobRecord::encode`] (JSON, tagged with
//! [`FORMAT`] and [`VERSION`]: people read state directories) and read it back with
//! [`JobRecord::decode`], which checks that it is consistent; a record of another format or
//! version is an error naming it.

use herb_ipc::MAX_JOB_OBJECTS;
use herb_robot::kinematics::DOF;
use serde::{Deserialize, Serialize};

/// The `format` tag of every encoded record.
pub const FORMAT: &str = "herb-job";
/// The version of the encoding: 2 since it is shared by the journal and the run log's
/// snapshots (version 1 was the journal's own, tagged `herb-job-journal`).
pub const VERSION: u32 = 2;

/// Where the current object stands (reported at restart; the resume itself reads the measured
/// robot state).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectPhase {
    /// No job runs (a run log's snapshot, between jobs).
    #[default]
    Idle,
    /// The job's objects are being ordered (Beam-3).
    Ordering,
    /// The current object's pick is being planned or its placement decided, nothing held.
    Deciding,
    /// The arm moves or grasps without an object in the gripper (to pick the current object,
    /// or away from the last placement).
    Moving,
    /// The current object is in the gripper (lifted, held at the lift pose until its placement
    /// is decided, carried to it, or being released).
    Carrying,
    /// Braking or holding after a fault, a stop or a restart.
    Halted,
}

/// The current object's decided placement and, once its place is planned, the arm
/// configuration that releases it there.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Placement {
    /// Index of the object in the order it belongs to.
    pub index: u16,
    /// Placement in B: x, y, z (m), yaw (rad).
    pub pose: [f32; 4],
    /// Joint configuration at which the gripper opens (rad), once the place is planned.
    pub release_q: Option<[f64; DOF]>,
}

/// A job as it is kept outside the machine. Fixed size, `Copy`: the loop builds one each cycle
/// without allocating. `job_id == 0` means no job runs; a run log's snapshot then still holds
/// the last job's objects, order and counts, which statuses between jobs report. Entries of
/// `objects` and `order` past `count` are not encoded (they read back as zeros).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JobRecord {
    /// Job id (0: none runs).
    pub job_id: u64,
    /// Objects in the job.
    pub count: u16,
    /// The objects as submitted (catalog types).
    pub objects: [u16; MAX_JOB_OBJECTS],
    /// Whether `order` holds the packing order yet.
    pub ordered: bool,
    /// The packing order (Beam-3's) once `ordered`; before, what the machine holds in its place
    /// (the journal: the objects as submitted).
    pub order: [u16; MAX_JOB_OBJECTS],
    /// Index of the current object in the order (objects before it are placed or skipped).
    pub index: u16,
    /// Objects placed.
    pub done: u16,
    /// The current object is believed to be in the gripper.
    pub holding: bool,
    /// The object in the gripper is held turned by a half turn (how its pick took it; its
    /// place turns it back).
    pub flip: bool,
    /// Where the current object stands.
    pub phase: ObjectPhase,
    /// The current object's placement, once decided.
    pub placement: Option<Placement>,
    /// The job waits for a client's confirmation before each grasp
    /// ([`herb_ipc::PackJobRequest::CONFIRM_PICKS`]).
    pub confirm_picks: bool,
}

/// A record that cannot be decoded, or that does not describe a job that can be taken up.
#[derive(Debug, thiserror::Error)]
pub enum JobRecordError {
    /// Not JSON of the record's shape.
    #[error("corrupt or truncated ({bytes} bytes): {cause}")]
    Corrupt {
        /// Length of what was read.
        bytes: usize,
        /// What the JSON parser says.
        cause: serde_json::Error,
    },
    /// Another format, or another version of this one.
    #[error("format {format:?} version {version} (expected {FORMAT:?} version {VERSION})")]
    Version {
        /// The format tag found.
        format: String,
        /// The version found.
        version: u32,
    },
    /// No job (a journal holds a running job).
    #[error("job_id 0")]
    NoJob,
    /// Too many objects, or none for a job.
    #[error("{0} objects (1..={MAX_JOB_OBJECTS})")]
    Objects(usize),
    /// An object type the catalog does not have.
    #[error("object type {object} not in the catalog ({catalog_len} types)")]
    NotInCatalog {
        /// The type.
        object: u16,
        /// Types in the catalog.
        catalog_len: usize,
    },
    /// The order is not as long as the objects.
    #[error("{order} objects in the order for {objects} objects")]
    OrderLength {
        /// Entries in the order.
        order: usize,
        /// Objects.
        objects: usize,
    },
    /// The packing order is not a permutation of the objects.
    #[error("order is not a permutation of the objects")]
    NotAPermutation,
    /// The counts do not fit the objects.
    #[error("done {done} and index {index} do not fit {count} objects")]
    Progress {
        /// Objects placed.
        done: u16,
        /// The current object's index.
        index: u16,
        /// Objects.
        count: usize,
    },
    /// An object believed held that is not a current object of the packing order.
    #[error("holding an object past the end of the order")]
    HoldingPastEnd,
    /// A placement with a non-finite number, or of another object.
    #[error("placement not finite or not the current object's")]
    Placement,
}

/// The encoding's layout (field order as written).
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct Encoded {
    format: String,
    version: u32,
    job_id: u64,
    objects: Vec<u16>,
    ordered: bool,
    order: Vec<u16>,
    index: u16,
    done: u16,
    holding: bool,
    /// Absent in records written before picks started ahead of their decisions: false.
    #[serde(default)]
    flip: bool,
    phase: ObjectPhase,
    placement: Option<Placement>,
    /// Absent in records written before pick confirmations: false.
    #[serde(default)]
    confirm_picks: bool,
}

/// The tag read first, whatever else the record holds (another version's layout differs).
#[derive(Deserialize)]
struct Tag {
    format: String,
    version: u32,
}

impl JobRecord {
    /// No job.
    pub const NONE: JobRecord = JobRecord {
        job_id: 0,
        count: 0,
        objects: [0; MAX_JOB_OBJECTS],
        ordered: false,
        order: [0; MAX_JOB_OBJECTS],
        index: 0,
        done: 0,
        holding: false,
        flip: false,
        phase: ObjectPhase::Idle,
        placement: None,
        confirm_picks: false,
    };

    fn len(&self) -> usize {
        (self.count as usize).min(MAX_JOB_OBJECTS)
    }

    /// The objects as submitted.
    pub fn objects(&self) -> &[u16] {
        &self.objects[..self.len()]
    }

    /// The packing order, once known.
    pub fn order(&self) -> Option<&[u16]> {
        self.ordered.then(|| &self.order[..self.len()])
    }

    /// One line for people: job, progress, the current object and where it stood.
    pub fn describe(&self) -> String {
        let current = self
            .order()
            .and_then(|o| o.get(self.index as usize))
            .map_or(String::new(), |t| format!(" (type {t})"));
        format!(
            "job {}: {}/{} placed, object {}/{}{current} {:?}{}",
            self.job_id,
            self.done,
            self.count,
            (self.index as usize + 1).min(self.count as usize),
            self.count,
            self.phase,
            if self.holding { ", held" } else { "" }
        )
    }

    /// The record's encoding: JSON with the format tag and version, the objects and the order
    /// as long as the job.
    pub fn encode(&self) -> Vec<u8> {
        let e = Encoded {
            format: FORMAT.into(),
            version: VERSION,
            job_id: self.job_id,
            objects: self.objects().to_vec(),
            ordered: self.ordered,
            order: self.order[..self.len()].to_vec(),
            index: self.index,
            done: self.done,
            holding: self.holding,
            flip: self.flip,
            phase: self.phase,
            placement: self.placement,
            confirm_picks: self.confirm_picks,
        };
        serde_json::to_vec_pretty(&e).expect("a record is always JSON")
    }

    /// A record from its encoding ([`JobRecord::encode`]), checked for consistency: the format
    /// and version, at most [`MAX_JOB_OBJECTS`] objects (at least one for a job), an order as
    /// long as the objects and, once known, a permutation of them, counts within the job, and a
    /// finite placement of the current object.
    pub fn decode(bytes: &[u8]) -> Result<Self, JobRecordError> {
        let corrupt = |cause| JobRecordError::Corrupt {
            bytes: bytes.len(),
            cause,
        };
        let tag: Tag = serde_json::from_slice(bytes).map_err(corrupt)?;
        if tag.format != FORMAT || tag.version != VERSION {
            return Err(JobRecordError::Version {
                format: tag.format,
                version: tag.version,
            });
        }
        let e: Encoded = serde_json::from_slice(bytes).map_err(corrupt)?;
        let n = e.objects.len();
        if n > MAX_JOB_OBJECTS || (n == 0 && e.job_id != 0) {
            return Err(JobRecordError::Objects(n));
        }
        if e.order.len() != n {
            return Err(JobRecordError::OrderLength {
                order: e.order.len(),
                objects: n,
            });
        }
        if e.ordered {
            let (mut a, mut b) = (e.objects.clone(), e.order.clone());
            a.sort_unstable();
            b.sort_unstable();
            if a != b {
                return Err(JobRecordError::NotAPermutation);
            }
        }
        if !(e.done <= e.index && e.index as usize <= n) {
            return Err(JobRecordError::Progress {
                done: e.done,
                index: e.index,
                count: n,
            });
        }
        if let Some(p) = &e.placement {
            let finite = p.pose.iter().all(|v| v.is_finite())
                && p.release_q.iter().flatten().all(|v| v.is_finite());
            if !finite || p.index != e.index {
                return Err(JobRecordError::Placement);
            }
        }
        let mut r = JobRecord::NONE;
        r.job_id = e.job_id;
        r.count = n as u16;
        r.objects[..n].copy_from_slice(&e.objects);
        r.ordered = e.ordered;
        r.order[..n].copy_from_slice(&e.order);
        r.index = e.index;
        r.done = e.done;
        r.holding = e.holding;
        r.flip = e.flip;
        r.phase = e.phase;
        r.placement = e.placement;
        r.confirm_picks = e.confirm_picks;
        Ok(r)
    }

    /// Whether the record describes a job that can be taken up with a catalog of
    /// `catalog_len` types: a job, every object in the catalog, and an object believed held
    /// only at a current object of the packing order.
    pub fn check_job(&self, catalog_len: usize) -> Result<(), JobRecordError> {
        if self.job_id == 0 {
            return Err(JobRecordError::NoJob);
        }
        if let Some(&object) = self.objects().iter().find(|&&t| t as usize >= catalog_len) {
            return Err(JobRecordError::NotInCatalog {
                object,
                catalog_len,
            });
        }
        if self.holding && (self.index >= self.count || !self.ordered) {
            return Err(JobRecordError::HoldingPastEnd);
        }
        Ok(())
    }
}

#[cfg(test)]
impl JobRecord {
    /// **Fixture** for the tests of the record and of the journal: a job of three objects,
    /// ordered, the second carried to its placement.
    pub(crate) fn fixture() -> JobRecord {
        let mut r = JobRecord::NONE;
        r.job_id = 7;
        r.count = 3;
        r.objects[..3].copy_from_slice(&[4, 5, 6]);
        r.ordered = true;
        r.order[..3].copy_from_slice(&[6, 4, 5]);
        r.index = 1;
        r.done = 1;
        r.holding = true;
        r.flip = true;
        r.confirm_picks = true;
        r.phase = ObjectPhase::Carrying;
        r.placement = Some(Placement {
            index: 1,
            pose: [0.01, -0.02, 0.05, 1.5],
            release_q: Some([0.1, -0.2, 0.3, 0.4, 0.5, 0.6, 0.1 + 0.2]),
        });
        r
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn job() -> JobRecord {
        JobRecord::fixture()
    }

    #[test]
    fn a_record_decodes_to_itself_bit_for_bit() {
        for r in [job(), JobRecord::NONE] {
            assert_eq!(JobRecord::decode(&r.encode()).unwrap(), r);
        }
        // Between jobs: the last job's progress, its order held whether final or not.
        let mut idle = job();
        idle.job_id = 0;
        idle.ordered = false;
        idle.order[..3].copy_from_slice(&[9, 9, 2]);
        idle.phase = ObjectPhase::Idle;
        assert_eq!(JobRecord::decode(&idle.encode()).unwrap(), idle);
        assert!(matches!(idle.check_job(10), Err(JobRecordError::NoJob)));
        job().check_job(10).unwrap();
    }

    #[test]
    fn another_version_is_named_before_its_layout_is_read() {
        let old = br#"{"format": "herb-job-journal", "version": 1, "job_id": 7, "order": null}"#;
        let e = JobRecord::decode(old).unwrap_err();
        assert!(
            e.to_string()
                .contains("\"herb-job-journal\" version 1 (expected \"herb-job\" version 2)"),
            "{e}"
        );
        let e = JobRecord::decode(b"{\"format\": \"herb-jo").unwrap_err();
        assert!(
            e.to_string().contains("corrupt or truncated (19 bytes)"),
            "{e}"
        );
    }
}
