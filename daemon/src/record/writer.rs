//! The writer side of the run log: the loop's end ([`Recorder`], wait-free, no allocation), the
//! writer thread that encodes and writes the records, and the segment files (rotation between
//! jobs, deletion of the oldest beyond `keep_mb`).

use super::RecordError;
use super::format::{
    Enc, FORMAT, LoopRec, MAGIC, RunHeader, Sent, encode_loop, encode_snapshot, frame_bytes, kind,
    write_record,
};
use crate::job::JobSnapshot;
use std::collections::HashSet;
use std::io::{BufWriter, Write};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc;
use std::time::Duration;

/// Records the loop's ring holds (about 8 s of a 1 kHz loop with its two states per cycle).
const LOOP_RING: usize = 32 * 1024;
/// How often the writer drains the rings and flushes.
const WRITER_PERIOD: Duration = Duration::from_millis(100);

/// The loop's end of the recorder: pushes never block or allocate.
pub struct Recorder {
    tx: rtrb::Producer<LoopRec>,
    snaps: rtrb::Producer<(Sent, JobSnapshot)>,
    want_snapshot: Arc<AtomicBool>,
    dropped: u64,
}

impl Recorder {
    /// Records `r` (dropped and counted if the writer is behind).
    pub fn push(&mut self, r: LoopRec) {
        if self.dropped > 0 {
            match self.tx.push(LoopRec::Gap {
                dropped: self.dropped,
            }) {
                Ok(()) => self.dropped = 0,
                Err(_) => {
                    self.dropped += 1;
                    return;
                }
            }
        }
        if self.tx.push(r).is_err() {
            self.dropped += 1;
        }
    }

    /// The writer asks for a snapshot (its segment is full): the loop gives one between jobs.
    pub fn wants_snapshot(&self) -> bool {
        self.want_snapshot.load(Ordering::Relaxed)
    }

    /// Records the machine's snapshot, taken with `before` requests sent so far: the writer
    /// starts a new segment with it.
    pub fn snapshot(&mut self, before: Sent, s: JobSnapshot) {
        if self.snaps.push((before, s)).is_ok() {
            self.want_snapshot.store(false, Ordering::Relaxed);
            self.push(LoopRec::Snapshot);
        }
    }
}

/// Where and how much to record.
#[derive(Debug, Clone)]
pub struct RecordOptions {
    /// The folder of the segment files.
    pub dir: PathBuf,
    /// A segment is closed, between jobs, past this size (bytes).
    pub segment_bytes: u64,
    /// The oldest segments are deleted beyond this total (bytes).
    pub keep_bytes: u64,
}

/// A frame a decision was made on, on its way to the writer.
type PlanFrame = (u64, Option<Box<[u8]>>);

/// A running recorder: the loop's end, the decision worker's frame log, and the writer thread.
pub struct Recording {
    /// For the loop.
    pub recorder: Recorder,
    /// For the decision worker ([`crate::decision::spawn`]).
    pub frames: crate::decision::FrameLog,
    /// The writer; set `stop` and join it after the loop ended. Returns the segment files.
    pub writer: std::thread::JoinHandle<Result<Vec<PathBuf>, RecordError>>,
    /// Tells the writer to drain, flush, sync and end.
    pub stop: Arc<AtomicBool>,
}

/// Starts recording into `opts.dir` (created if needed): the first segment is opened (and its
/// header written) before this returns, so a bad folder is reported at start.
pub fn start(opts: RecordOptions, header: RunHeader) -> Result<Recording, RecordError> {
    std::fs::create_dir_all(&opts.dir).map_err(|source| RecordError::Folder {
        path: opts.dir.clone(),
        source,
    })?;
    let (tx, mut rx) = rtrb::RingBuffer::<LoopRec>::new(LOOP_RING);
    let (snaps, mut snaps_rx) = rtrb::RingBuffer::<(Sent, JobSnapshot)>::new(2);
    let (ftx, frx) = mpsc::channel::<PlanFrame>();
    let want = Arc::new(AtomicBool::new(false));
    let stop = Arc::new(AtomicBool::new(false));
    let mut seg = Segment::open(&opts.dir, &header)?;
    let (want_w, stop_w) = (want.clone(), stop.clone());
    let writer = std::thread::Builder::new()
        .name("herbd-record".into())
        .spawn(move || -> Result<Vec<PathBuf>, RecordError> {
            let mut header = header;
            let mut files = vec![seg.path.clone()];
            loop {
                let last = stop_w.load(Ordering::Relaxed);
                // Frames first: a frame is sent before the response that used it.
                while let Ok((n, f)) = frx.try_recv() {
                    seg.plan_frame(n, f.as_deref())?;
                }
                while let Ok(r) = rx.pop() {
                    if let LoopRec::Snapshot = r {
                        while let Ok((n, f)) = frx.try_recv() {
                            seg.plan_frame(n, f.as_deref())?;
                        }
                        let Ok((before, s)) = snaps_rx.pop() else {
                            continue;
                        };
                        seg.close()?;
                        header.segment += 1;
                        seg = Segment::open(&opts.dir, &header)?;
                        seg.write(kind::SNAPSHOT, &encode_snapshot(before, &s))?;
                        files.push(seg.path.clone());
                        prune(&mut files, opts.keep_bytes);
                        continue;
                    }
                    let (k, p) = encode_loop(&r);
                    seg.write(k, &p)?;
                }
                seg.flush()?;
                if seg.bytes > opts.segment_bytes {
                    want_w.store(true, Ordering::Relaxed);
                }
                if last {
                    seg.close()?;
                    return Ok(files);
                }
                std::thread::sleep(WRITER_PERIOD);
            }
        })
        .map_err(RecordError::Thread)?;
    let frames: crate::decision::FrameLog = Box::new(move |n, f| {
        let _ = ftx.send((n, f.map(frame_bytes)));
    });
    Ok(Recording {
        recorder: Recorder {
            tx,
            snaps,
            want_snapshot: want,
            dropped: 0,
        },
        frames,
        writer,
        stop,
    })
}

/// Deletes the oldest segments (never the current, last one) while the total exceeds `keep`.
fn prune(files: &mut Vec<PathBuf>, keep: u64) {
    let size = |p: &Path| std::fs::metadata(p).map(|m| m.len()).unwrap_or(0);
    while files.len() > 1 && files.iter().map(|p| size(p)).sum::<u64>() > keep {
        let old = files.remove(0);
        let _ = std::fs::remove_file(&old);
    }
}

/// An open segment file.
struct Segment {
    path: PathBuf,
    w: BufWriter<std::fs::File>,
    bytes: u64,
    seen: HashSet<u64>,
}

impl Segment {
    fn open(dir: &Path, h: &RunHeader) -> Result<Self, RecordError> {
        let path = dir.join(format!("RUN-{}-{:04}.log", h.started_unix_s, h.segment));
        let f = match std::fs::File::create(&path) {
            Ok(f) => f,
            Err(source) => return Err(RecordError::Segment { path, source }),
        };
        let mut s = Self {
            path,
            w: BufWriter::with_capacity(1 << 20, f),
            bytes: 0,
            seen: HashSet::new(),
        };
        s.raw(MAGIC)?;
        s.raw(&FORMAT.to_le_bytes())?;
        s.write(kind::HEADER, &h.encode())?;
        Ok(s)
    }

    fn err(&self, source: std::io::Error) -> RecordError {
        RecordError::Segment {
            path: self.path.clone(),
            source,
        }
    }

    fn raw(&mut self, b: &[u8]) -> Result<(), RecordError> {
        self.w.write_all(b).map_err(|e| self.err(e))?;
        self.bytes += b.len() as u64;
        Ok(())
    }

    fn write(&mut self, k: u8, p: &[u8]) -> Result<(), RecordError> {
        let n = write_record(&mut self.w, k, p).map_err(|e| self.err(e))?;
        self.bytes += n;
        Ok(())
    }

    /// The frame request `n` was served with; its cells the first time in this segment.
    fn plan_frame(&mut self, n: u64, f: Option<&[u8]>) -> Result<(), RecordError> {
        let digest = f.map_or(0, crate::digest::of);
        if let Some(b) = f
            && self.seen.insert(digest)
        {
            let mut e = Enc::default();
            e.u64(digest).bytes(b);
            self.write(kind::FRAME_CELLS, &e.0)?;
        }
        let mut e = Enc::default();
        e.u64(n).u8(f.is_some() as u8).u64(digest);
        self.write(kind::PLAN_FRAME, &e.0)
    }

    fn flush(&mut self) -> Result<(), RecordError> {
        self.w.flush().map_err(|e| self.err(e))
    }

    /// Ends the segment with its end record, then flushes and syncs it.
    fn close(&mut self) -> Result<(), RecordError> {
        self.write(kind::END, &[])?;
        self.flush()?;
        self.w.get_ref().sync_all().map_err(|e| self.err(e))
    }
}
