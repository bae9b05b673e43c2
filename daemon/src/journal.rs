//! The job journal: what `herbd` needs to finish a job after a crash, in one small file of its
//! state directory (`journal.dir`, by default systemd's `$STATE_DIRECTORY`).
//!
//! The job state machine describes its job as a [`JournalRecord`] ([`crate::job::Job::journal`]);
//! the loop hands every changed record to the writer thread ([`spawn`]) over a wait-free ring,
//! and the writer makes the newest one durable: write `job.json.tmp`, fsync, rename over
//! `job.json`, fsync the folder. A job's end removes the file. The loop never waits for the
//! disk.
//!
//! At start, [`load`] reads the file: no file is no unfinished job; a file that does not parse
//! or does not fit the catalog is a [`JournalError`], which `herbd` reports before it sets the
//! file aside ([`set_aside`]) and starts without a job, so a bad journal never becomes a crash
//! loop. A good one is resumed ([`crate::job::Job::recover`]) or abandoned, as configured.

use herb_ipc::MAX_JOB_OBJECTS;
use herb_robot::kinematics::DOF;
use serde::{Deserialize, Serialize};
use std::fs::{self, File};
use std::io::Write;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::thread::JoinHandle;
use std::time::Duration;

/// The journal's file name in its folder.
pub const FILE: &str = "job.json";
/// The file being written, renamed over [`FILE`] once durable.
const TMP: &str = "job.json.tmp";
/// `format` field of every journal file.
const FORMAT: &str = "herb-job-journal";
/// Version of the file's layout.
const VERSION: u32 = 1;
/// Records in flight from the loop to the writer.
pub const RING: usize = 64;
/// The writer's poll period when nothing is pending.
const POLL: Duration = Duration::from_millis(2);

/// Where the current object stands (reported at restart; the resume itself reads the measured
/// robot state).
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum ObjectPhase {
    /// The job's objects are being ordered (Beam-3).
    #[default]
    Ordering,
    /// Waiting for a heightmap, or deciding and planning the placement.
    Deciding,
    /// The arm moves or grasps without an object in the gripper (to pick the current object,
    /// or away from the last placement).
    Moving,
    /// The current object is in the gripper (carried to its placement, or being released).
    Carrying,
    /// Braking or holding after a fault, a stop or a restart.
    Halted,
}

/// The current object's decided placement and the arm configuration that releases it there.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Placement {
    /// Index of the object in the order it belongs to.
    pub index: u16,
    /// Placement in B: x, y, z (m), yaw (rad).
    pub pose: [f32; 4],
    /// Joint configuration at which the gripper opens (rad).
    pub release_q: [f64; DOF],
}

/// The running job as the journal keeps it. Fixed size, `Copy`: built by the loop each cycle
/// without allocating. `job_id == 0` means no job.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct JournalRecord {
    /// Job id (0: none).
    pub job_id: u64,
    /// Objects in the job.
    pub count: u16,
    /// The objects as submitted (catalog types).
    pub objects: [u16; MAX_JOB_OBJECTS],
    /// Whether `order` holds the packing order yet.
    pub ordered: bool,
    /// The packing order (Beam-3's).
    pub order: [u16; MAX_JOB_OBJECTS],
    /// Index of the current object in the order (objects before it are placed or skipped).
    pub index: u16,
    /// Objects placed.
    pub done: u16,
    /// The current object is believed to be in the gripper.
    pub holding: bool,
    /// Where the current object stands.
    pub phase: ObjectPhase,
    /// The current object's placement, once decided.
    pub placement: Option<Placement>,
}

impl JournalRecord {
    /// No job.
    pub const NONE: JournalRecord = JournalRecord {
        job_id: 0,
        count: 0,
        objects: [0; MAX_JOB_OBJECTS],
        ordered: false,
        order: [0; MAX_JOB_OBJECTS],
        index: 0,
        done: 0,
        holding: false,
        phase: ObjectPhase::Ordering,
        placement: None,
    };

    /// The objects as submitted.
    pub fn objects(&self) -> &[u16] {
        &self.objects[..(self.count as usize).min(MAX_JOB_OBJECTS)]
    }

    /// The packing order, once known.
    pub fn order(&self) -> Option<&[u16]> {
        self.ordered
            .then(|| &self.order[..(self.count as usize).min(MAX_JOB_OBJECTS)])
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
}

/// The file's layout (JSON, for people reading a state directory).
#[derive(Debug, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
struct OnDisk {
    format: String,
    version: u32,
    job_id: u64,
    objects: Vec<u16>,
    order: Option<Vec<u16>>,
    index: u16,
    done: u16,
    holding: bool,
    phase: ObjectPhase,
    placement: Option<Placement>,
}

impl OnDisk {
    fn of(r: &JournalRecord) -> Self {
        Self {
            format: FORMAT.into(),
            version: VERSION,
            job_id: r.job_id,
            objects: r.objects().to_vec(),
            order: r.order().map(<[u16]>::to_vec),
            index: r.index,
            done: r.done,
            holding: r.holding,
            phase: r.phase,
            placement: r.placement,
        }
    }

    /// The record, if the file is consistent and fits a catalog of `catalog_len` types.
    fn record(self, catalog_len: usize) -> Result<JournalRecord, String> {
        if self.format != FORMAT || self.version != VERSION {
            return Err(format!(
                "format {:?} version {} (expected {FORMAT:?} version {VERSION})",
                self.format, self.version
            ));
        }
        if self.job_id == 0 {
            return Err("job_id 0".into());
        }
        let n = self.objects.len();
        if n == 0 || n > MAX_JOB_OBJECTS {
            return Err(format!("{n} objects (1..={MAX_JOB_OBJECTS})"));
        }
        if let Some(t) = self.objects.iter().find(|&&t| t as usize >= catalog_len) {
            return Err(format!(
                "object type {t} not in the catalog ({catalog_len} types)"
            ));
        }
        let mut r = JournalRecord::NONE;
        r.job_id = self.job_id;
        r.count = n as u16;
        r.objects[..n].copy_from_slice(&self.objects);
        if let Some(order) = &self.order {
            let (mut a, mut b) = (self.objects.clone(), order.clone());
            a.sort_unstable();
            b.sort_unstable();
            if a != b {
                return Err("order is not a permutation of the objects".into());
            }
            r.ordered = true;
            r.order[..n].copy_from_slice(order);
        }
        if !(self.done <= self.index && self.index as usize <= n) {
            return Err(format!(
                "done {} and index {} do not fit {n} objects",
                self.done, self.index
            ));
        }
        if self.holding && (self.index as usize >= n || self.order.is_none()) {
            return Err("holding an object past the end of the order".into());
        }
        if let Some(p) = &self.placement {
            let finite =
                p.pose.iter().all(|v| v.is_finite()) && p.release_q.iter().all(|v| v.is_finite());
            if !finite || p.index != self.index {
                return Err("placement not finite or not the current object's".into());
            }
        }
        r.index = self.index;
        r.done = self.done;
        r.holding = self.holding;
        r.phase = self.phase;
        r.placement = self.placement;
        Ok(r)
    }
}

/// A journal file that cannot be used: which file, and what is wrong with it.
#[derive(Debug, Clone, PartialEq, Eq, thiserror::Error)]
#[error("job journal {path}: {what}")]
pub struct JournalError {
    /// The file.
    pub path: PathBuf,
    /// What is wrong.
    pub what: String,
}

/// The unfinished job in `dir`, if any (`Ok(None)`: no journal file).
pub fn load(dir: &Path, catalog_len: usize) -> Result<Option<JournalRecord>, JournalError> {
    let path = dir.join(FILE);
    let err = |what: String| JournalError {
        path: path.clone(),
        what,
    };
    let bytes = match fs::read(&path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(e) => return Err(err(format!("cannot read: {e}"))),
    };
    let disk: OnDisk = serde_json::from_slice(&bytes)
        .map_err(|e| err(format!("corrupt or truncated ({} bytes): {e}", bytes.len())))?;
    disk.record(catalog_len).map(Some).map_err(err)
}

/// Renames a journal that could not be used to `job.json.bad-<unix seconds>` beside it, so
/// the next start does not meet it again; returns the new name.
pub fn set_aside(dir: &Path) -> std::io::Result<PathBuf> {
    let secs = std::time::SystemTime::now()
        .duration_since(std::time::UNIX_EPOCH)
        .map_or(0, |d| d.as_secs());
    let to = dir.join(format!("{FILE}.bad-{secs}"));
    fs::rename(dir.join(FILE), &to)?;
    sync_dir(dir)?;
    Ok(to)
}

/// Makes `r` the journal in `dir` (atomically: temporary file, fsync, rename, fsync of the
/// folder), or removes the journal when `r` holds no job.
pub fn write(dir: &Path, r: &JournalRecord) -> std::io::Result<()> {
    let path = dir.join(FILE);
    if r.job_id == 0 {
        match fs::remove_file(&path) {
            Ok(()) => {}
            Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(()),
            Err(e) => return Err(e),
        }
    } else {
        let tmp = dir.join(TMP);
        let mut f = File::create(&tmp)?;
        let json = serde_json::to_vec_pretty(&OnDisk::of(r)).map_err(std::io::Error::other)?;
        f.write_all(&json)?;
        f.write_all(b"\n")?;
        f.sync_all()?;
        drop(f);
        fs::rename(&tmp, &path)?;
    }
    sync_dir(dir)
}

fn sync_dir(dir: &Path) -> std::io::Result<()> {
    File::open(dir)?.sync_all()
}

/// What the writer did, reported when it ends.
#[derive(Debug, Clone, Default, PartialEq, Eq)]
pub struct WriterReport {
    /// Journal files made durable (or removed at a job's end).
    pub writes: u64,
    /// Writes that failed (each distinct error is logged once when it first happens).
    pub failures: u64,
}

/// Starts the writer thread for `dir` (created if missing): the loop pushes records into the
/// returned ring; the thread writes the newest pending one, and the last one before it ends
/// once `stop` is set.
pub fn spawn(
    dir: PathBuf,
    stop: Arc<AtomicBool>,
) -> Result<(rtrb::Producer<JournalRecord>, JoinHandle<WriterReport>), String> {
    fs::create_dir_all(&dir).map_err(|e| format!("job journal folder {}: {e}", dir.display()))?;
    // A temporary file left by a crash mid-write is not the journal.
    let _ = fs::remove_file(dir.join(TMP));
    let (tx, mut rx) = rtrb::RingBuffer::<JournalRecord>::new(RING);
    let handle = std::thread::Builder::new()
        .name("herbd-journal".into())
        .spawn(move || {
            let mut report = WriterReport::default();
            let mut logged: Option<std::io::ErrorKind> = None;
            loop {
                let ending = stop.load(Ordering::Relaxed);
                let mut newest = None;
                while let Ok(r) = rx.pop() {
                    newest = Some(r);
                }
                if let Some(r) = newest {
                    match write(&dir, &r) {
                        Ok(()) => report.writes += 1,
                        Err(e) => {
                            report.failures += 1;
                            if logged != Some(e.kind()) {
                                logged = Some(e.kind());
                                crate::logfmt::log(
                                    "journal_write_failed",
                                    &[("dir", &dir.display()), ("error", &e)],
                                );
                            }
                        }
                    }
                } else if ending {
                    return report;
                } else {
                    std::thread::sleep(POLL);
                }
            }
        })
        .map_err(|e| format!("cannot start the journal writer: {e}"))?;
    Ok((tx, handle))
}

#[cfg(test)]
mod tests {
    use super::*;

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("herb-journal-{}-{tag}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    fn job() -> JournalRecord {
        let mut r = JournalRecord::NONE;
        r.job_id = 7;
        r.count = 3;
        r.objects[..3].copy_from_slice(&[4, 5, 6]);
        r.ordered = true;
        r.order[..3].copy_from_slice(&[6, 4, 5]);
        r.index = 1;
        r.done = 1;
        r.holding = true;
        r.phase = ObjectPhase::Carrying;
        r.placement = Some(Placement {
            index: 1,
            pose: [0.01, -0.02, 0.05, 1.5],
            release_q: [0.1, -0.2, 0.3, 0.4, 0.5, 0.6, 0.7],
        });
        r
    }

    #[test]
    fn a_record_survives_the_file_and_a_job_end_removes_it() {
        let d = dir("roundtrip");
        assert_eq!(load(&d, 10).unwrap(), None);
        write(&d, &job()).unwrap();
        assert_eq!(load(&d, 10).unwrap(), Some(job()));
        assert!(!d.join(TMP).exists());
        write(&d, &JournalRecord::NONE).unwrap();
        assert!(!d.join(FILE).exists());
        assert_eq!(load(&d, 10).unwrap(), None);
        // Removing twice is fine.
        write(&d, &JournalRecord::NONE).unwrap();
    }

    #[test]
    fn truncated_corrupt_or_inconsistent_journals_are_named_and_set_aside() {
        let d = dir("bad");
        write(&d, &job()).unwrap();
        let good = fs::read(d.join(FILE)).unwrap();
        let cases: Vec<(Vec<u8>, &str)> = vec![
            (good[..good.len() / 2].to_vec(), "truncated"),
            (b"\x00\xffgarbage".to_vec(), "corrupt"),
            (Vec::new(), "truncated"),
            (
                String::from_utf8(good.clone())
                    .unwrap()
                    .replace("\"done\": 1", "\"done\": 2")
                    .into_bytes(),
                "do not fit",
            ),
            (
                String::from_utf8(good.clone())
                    .unwrap()
                    .replace("\"version\": 1", "\"version\": 9")
                    .into_bytes(),
                "version 9",
            ),
        ];
        for (bytes, want) in cases {
            fs::write(d.join(FILE), &bytes).unwrap();
            let e = load(&d, 10).unwrap_err();
            assert_eq!(e.path, d.join(FILE));
            assert!(e.to_string().contains(want), "{want}: {e}");
            let aside = set_aside(&d).unwrap();
            assert!(aside.is_file() && !d.join(FILE).exists());
            assert_eq!(load(&d, 10).unwrap(), None);
            fs::remove_file(aside).unwrap();
        }
        // A type the catalog does not have.
        write(&d, &job()).unwrap();
        let e = load(&d, 6).unwrap_err();
        assert!(e.to_string().contains("not in the catalog"), "{e}");
        // An order that is not the objects'.
        let mut r = job();
        r.order[0] = 9;
        write(&d, &r).unwrap();
        assert!(
            load(&d, 10)
                .unwrap_err()
                .to_string()
                .contains("permutation")
        );
    }

    #[test]
    fn the_writer_keeps_the_newest_record_and_the_last_one_on_stop() {
        let d = dir("writer");
        let stop = Arc::new(AtomicBool::new(false));
        let (mut tx, h) = spawn(d.clone(), stop.clone()).unwrap();
        let mut r = job();
        for phase in [
            ObjectPhase::Deciding,
            ObjectPhase::Moving,
            ObjectPhase::Carrying,
        ] {
            r.phase = phase;
            tx.push(r).unwrap();
        }
        stop.store(true, Ordering::Relaxed);
        let report = h.join().unwrap();
        assert!(report.writes >= 1 && report.failures == 0, "{report:?}");
        assert_eq!(load(&d, 10).unwrap(), Some(r));
    }
}
