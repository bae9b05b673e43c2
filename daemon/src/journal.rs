//! The job journal: what `herbd` needs to finish a job after a crash, in one small file of its
//! state directory (`journal.dir`, by default systemd's `$STATE_DIRECTORY`).
//!
//! The job state machine describes its job as a [`JobRecord`] ([`crate::job::Job::journal`]);
//! the loop hands every changed record to the writer thread ([`spawn`]) over a wait-free ring,
//! and the writer makes the newest one durable: write `job.json.tmp`, fsync, rename over
//! `job.json`, fsync the folder. The file is the record's one encoding
//! ([`JobRecord::encode`], JSON, shared with the run log's snapshots). A job's end removes the
//! file. The loop never waits for the disk.
//!
//! At start, [`load`] reads the file: no file is no unfinished job; a file that does not parse,
//! is of another version or does not fit the catalog is a [`JournalError`], which `herbd`
//! reports before it sets the file aside ([`set_aside`]) and starts without a job, so a bad
//! journal never becomes a crash loop. A good one is resumed ([`crate::job::Job::recover`]) or
//! abandoned, as configured.

use crate::job::{JobRecord, JobRecordError};
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
/// Records in flight from the loop to the writer.
pub const RING: usize = 64;
/// The writer's poll period when nothing is pending.
const POLL: Duration = Duration::from_millis(2);

/// A journal that cannot be used (its file, and what is wrong with it) or kept.
#[derive(Debug, thiserror::Error)]
pub enum JournalError {
    /// The file cannot be read.
    #[error("job journal {path}: cannot read: {source}")]
    Read {
        /// The file.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// Its record does not decode, or does not describe a job that can be taken up.
    #[error("job journal {path}: {problem}")]
    Record {
        /// The file.
        path: PathBuf,
        /// What is wrong.
        problem: JobRecordError,
    },
    /// The journal's folder cannot be created.
    #[error("job journal folder {path}: {source}")]
    Folder {
        /// The folder.
        path: PathBuf,
        /// Why.
        source: std::io::Error,
    },
    /// The writer thread cannot be started.
    #[error("cannot start the journal writer: {0}")]
    Thread(std::io::Error),
}

impl JournalError {
    /// The file or folder at fault, if any.
    pub fn path(&self) -> Option<&Path> {
        match self {
            Self::Read { path, .. } | Self::Record { path, .. } | Self::Folder { path, .. } => {
                Some(path)
            }
            Self::Thread(_) => None,
        }
    }
}

/// The unfinished job in `dir`, if any (`Ok(None)`: no journal file).
pub fn load(dir: &Path, catalog_len: usize) -> Result<Option<JobRecord>, JournalError> {
    let path = dir.join(FILE);
    let bytes = match fs::read(&path) {
        Ok(b) => b,
        Err(e) if e.kind() == std::io::ErrorKind::NotFound => return Ok(None),
        Err(source) => return Err(JournalError::Read { path, source }),
    };
    JobRecord::decode(&bytes)
        .and_then(|r| r.check_job(catalog_len).map(|()| Some(r)))
        .map_err(|problem| JournalError::Record { path, problem })
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
pub fn write(dir: &Path, r: &JobRecord) -> std::io::Result<()> {
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
        f.write_all(&r.encode())?;
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
) -> Result<(rtrb::Producer<JobRecord>, JoinHandle<WriterReport>), JournalError> {
    fs::create_dir_all(&dir).map_err(|source| JournalError::Folder {
        path: dir.clone(),
        source,
    })?;
    // A temporary file left by a crash mid-write is not the journal.
    let _ = fs::remove_file(dir.join(TMP));
    let (tx, mut rx) = rtrb::RingBuffer::<JobRecord>::new(RING);
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
        .map_err(JournalError::Thread)?;
    Ok((tx, handle))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::job::ObjectPhase;

    fn dir(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("herb-journal-{}-{tag}", std::process::id()));
        let _ = fs::remove_dir_all(&d);
        fs::create_dir_all(&d).unwrap();
        d
    }

    fn job() -> JobRecord {
        JobRecord::fixture()
    }

    #[test]
    fn a_record_survives_the_file_and_a_job_end_removes_it() {
        let d = dir("roundtrip");
        assert_eq!(load(&d, 10).unwrap(), None);
        write(&d, &job()).unwrap();
        assert_eq!(load(&d, 10).unwrap(), Some(job()));
        assert!(!d.join(TMP).exists());
        write(&d, &JobRecord::NONE).unwrap();
        assert!(!d.join(FILE).exists());
        assert_eq!(load(&d, 10).unwrap(), None);
        // Removing twice is fine.
        write(&d, &JobRecord::NONE).unwrap();
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
                    .replace("\"version\": 2", "\"version\": 9")
                    .into_bytes(),
                "version 9",
            ),
        ];
        for (bytes, want) in cases {
            fs::write(d.join(FILE), &bytes).unwrap();
            let e = load(&d, 10).unwrap_err();
            assert_eq!(e.path(), Some(d.join(FILE).as_path()));
            assert!(e.to_string().contains(want), "{want}: {e}");
            let aside = set_aside(&d).unwrap();
            assert!(aside.is_file() && !d.join(FILE).exists());
            assert_eq!(load(&d, 10).unwrap(), None);
            fs::remove_file(aside).unwrap();
        }
        // A journal of the previous version (the journal's own encoding): named with its version.
        let v1 = br#"{"format": "herb-job-journal", "version": 1, "job_id": 7, "objects": [4],
        "order": null, "index": 0, "done": 0, "holding": false, "phase": "deciding",
        "placement": null}"#;
        fs::write(d.join(FILE), v1).unwrap();
        let e = load(&d, 10).unwrap_err();
        assert_eq!(e.path(), Some(d.join(FILE).as_path()));
        assert!(
            e.to_string().contains(
                "format \"herb-job-journal\" version 1 (expected \"herb-job\" version 2)"
            ),
            "{e}"
        );
        fs::remove_file(set_aside(&d).unwrap()).unwrap();
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
