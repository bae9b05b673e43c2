//! Reading a segment file back into a [`Log`]: the header, the snapshot it starts from, the
//! loop's records in order, and the frames the decisions were made on.

use super::error::{LogError, LogProblem};
use super::format::{
    Dec, Entry, FORMAT, FRAMING, Framed, MAGIC, RunHeader, Sent, decode_loop, decode_snapshot,
    frame_from, kind, read_record,
};
use crate::job::JobSnapshot;
use herb_ipc::HeightmapFrame;
use std::collections::{BTreeMap, HashMap};
use std::path::Path;

/// A segment read back.
#[derive(Debug)]
pub struct Log {
    /// The header.
    pub header: RunHeader,
    /// The machine's state at the start, and the requests sent before it (a later segment);
    /// `None` for a run's first segment.
    pub snapshot: Option<(Sent, JobSnapshot)>,
    /// The loop's records.
    pub entries: Vec<Entry>,
    /// Per decision request number: the digest of the frame it was decided on (`None`: none
    /// came in time).
    pub decision_frames: BTreeMap<u64, Option<u64>>,
    /// Frames by digest: header, grid and used cells.
    pub frames: HashMap<u64, Box<HeightmapFrame>>,
    /// Why the log ends early, if it does (a torn or corrupt record, dropped records).
    pub incomplete: Option<String>,
}

impl Log {
    /// Reads a segment file. A torn or corrupt tail is not an error: what comes before it is
    /// returned, with [`Log::incomplete`] saying where it ends.
    pub fn read(path: &Path) -> Result<Self, LogError> {
        let bad = |problem: LogProblem| LogError {
            path: path.to_path_buf(),
            problem,
        };
        let data = std::fs::read(path).map_err(|e| bad(LogProblem::Io(e)))?;
        if data.len() < 12 || &data[..8] != MAGIC {
            return Err(bad(LogProblem::NotALog));
        }
        let format = u32::from_le_bytes(data[8..12].try_into().unwrap());
        if format != FORMAT {
            return Err(bad(LogProblem::Format {
                found: format,
                reads: FORMAT,
            }));
        }
        let mut at = 12usize;
        let mut header = None;
        let mut log = Log {
            header: RunHeader {
                herbd: String::new(),
                cpu: String::new(),
                started_unix_s: 0,
                config_toml: String::new(),
                catalog: 0,
                policy: 0,
                sequence: 0,
                segment: 0,
            },
            snapshot: None,
            entries: Vec::new(),
            decision_frames: BTreeMap::new(),
            frames: HashMap::new(),
            incomplete: None,
        };
        let mut cycles = 0u64;
        let mut ended = false;
        while at < data.len() {
            let (k, payload) = match read_record(&data[at..]) {
                Framed::Record { kind, payload } => (kind, payload),
                Framed::Torn => {
                    log.incomplete = Some(format!("torn record after cycle {cycles}"));
                    break;
                }
                Framed::Corrupt => {
                    log.incomplete = Some(format!("corrupt record (CRC) after cycle {cycles}"));
                    break;
                }
            };
            at += FRAMING + payload.len();
            let mut d = Dec(payload);
            match k {
                kind::HEADER => {
                    header = Some(RunHeader::decode(payload).ok_or(bad(LogProblem::Header))?);
                }
                kind::SNAPSHOT => {
                    log.snapshot =
                        Some(decode_snapshot(payload).map_err(|e| bad(LogProblem::Snapshot(e)))?);
                }
                kind::END => {
                    ended = true;
                    break;
                }
                kind::GAP => {
                    let n = d.u64().unwrap_or(0);
                    log.incomplete = Some(format!(
                        "{n} records dropped after cycle {cycles} (the writer fell behind)"
                    ));
                    break;
                }
                kind::PLAN_FRAME => {
                    let (n, has, digest) = (|| Some((d.u64()?, d.bool()?, d.u64()?)))()
                        .ok_or_else(|| bad(LogProblem::PlanFrame))?;
                    log.decision_frames.insert(n, has.then_some(digest));
                }
                kind::FRAME_CELLS => {
                    let (digest, f) = (|| Some((d.u64()?, frame_from(d.bytes()?)?)))()
                        .ok_or_else(|| bad(LogProblem::Frame))?;
                    log.frames.insert(digest, f);
                }
                kind::CYCLE..=kind::TICK | kind::ARM | kind::DECISION | kind::CONFIRM => {
                    let e = decode_loop(k, payload).ok_or_else(|| bad(LogProblem::Malformed(k)))?;
                    if let Entry::Cycle(_) = e {
                        cycles += 1;
                    }
                    log.entries.push(e);
                }
                other => return Err(bad(LogProblem::UnknownKind(other))),
            }
        }
        if !ended && log.incomplete.is_none() {
            // Cut at a record's boundary: every record reads, but the writer never closed it.
            log.incomplete = Some(format!(
                "no end record after cycle {cycles} (herbd stopped without closing the log)"
            ));
        }
        log.header = header.ok_or_else(|| bad(LogProblem::NoHeader))?;
        Ok(log)
    }
}
