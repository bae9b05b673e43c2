//! What every payload shares: the protocol's constants, the [`Header`], why a payload is
//! refused ([`Invalid`]), the [`Payload`] trait, the checks the payloads' `validate` use, and
//! the order of a service's samples ([`InOrder`]).

use iceoryx2::prelude::*;

use std::mem::MaybeUninit;

/// The contract's wire version, carried in every header (a receiver rejects any other) and in
/// every payload's iceoryx2 type name (`herb::v2::<Name>`), so that a process built for another
/// version cannot open HERB's services and is told both versions ([`crate::bus::BusError`]).
/// Any change to a payload's layout or to what a field means raises it (`ipc/CONTRACT.md`,
/// "Versions"); the contract's test fails on a layout that changed under the same version.
/// Version 1 was the contract until 2026-12; version 2 added `Status.waiting_for`.
pub const PROTOCOL_VERSION: u32 = 2;

/// The wire version an iceoryx2 type name of the contract says (`herb::v<N>::<Name>`), if it
/// is one.
pub fn wire_version_of(type_name: &str) -> Option<u32> {
    type_name
        .strip_prefix("herb::v")?
        .split_once("::")?
        .0
        .parse()
        .ok()
}
/// Arm joints carried in joint messages (Baxter left arm).
pub const DOF: usize = 7;
/// Most cells a [`HeightmapFrame`] can carry (the 224 x 224 observation grid).
pub const HEIGHTMAP_MAX_CELLS: usize = 224 * 224;
/// Most objects in one [`PackJobRequest`].
pub const MAX_JOB_OBJECTS: usize = 64;
/// `object_type` value meaning "none".
pub const NO_OBJECT: u32 = u32::MAX;
/// Lowest and highest valid heightmap value (m), as `herb_sim::Heightmap::validate`.
pub const HEIGHT_RANGE_M: (f32, f32) = (-0.05, 1.0);
/// Largest plausible joint angle magnitude (rad); tighter limits are the receiver's.
pub const MAX_JOINT_ABS_RAD: f64 = 2.0 * std::f64::consts::PI;
/// Largest plausible joint speed (rad/s).
pub const MAX_JOINT_SPEED: f64 = 20.0;
/// `herbd` refuses a joint or gripper state stamped more than this past the start of the cycle
/// that reads it (ns), unless the clock, read when it was received, is already past the stamp.
pub const MAX_FUTURE_STAMP_NS: u64 = 1_000_000;
/// `herbd` repeats its current [`GripperCommand`] this often while a job runs (ns).
pub const GRIPPER_REPEAT_NS: u64 = 100_000_000;
/// `herbd` publishes a [`StatusEvent::Heartbeat`] this often (ns).
pub const HEARTBEAT_PERIOD_NS: u64 = 100_000_000;
/// The range of a heightmap's cell side (m) a frame may carry.
pub const CELL_M_RANGE: (f32, f32) = (0.0005, 0.02);
/// An arm adapter publishes its [`ArmStatus`] at least this often (ns).
pub const ARM_STATUS_PERIOD_NS: u64 = 100_000_000;

/// `CLOCK_MONOTONIC` now, in nanoseconds.
pub fn monotonic_ns() -> u64 {
    let mut ts = libc::timespec {
        tv_sec: 0,
        tv_nsec: 0,
    };
    // SAFETY: clock_gettime writes one timespec; CLOCK_MONOTONIC always exists on Linux.
    unsafe { libc::clock_gettime(libc::CLOCK_MONOTONIC, &mut ts) };
    ts.tv_sec as u64 * 1_000_000_000 + ts.tv_nsec as u64
}

/// Initialises `slot` to all-zero bytes (a valid value of every payload here) and returns it.
/// Used to fill loaned shared memory in place without building the value on the stack.
pub fn zeroed_in_place<T: Payload>(slot: &mut MaybeUninit<T>) -> &mut T {
    // SAFETY: `Payload` is implemented only for the `repr(C)` number-only types of this crate,
    // for which all-zero bytes are a valid value.
    unsafe {
        slot.as_mut_ptr().write_bytes(0, 1);
        slot.assume_init_mut()
    }
}

/// The common first field of every payload.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::Header")]
pub struct Header {
    /// [`PROTOCOL_VERSION`].
    pub version: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// Per-publisher sequence number, starting at 1.
    pub seq: u64,
    /// `CLOCK_MONOTONIC` ns when the content was produced (for a heightmap: captured).
    pub stamp_ns: u64,
}

impl Header {
    /// A header for message `seq` stamped `stamp_ns` (`CLOCK_MONOTONIC`).
    pub fn at(seq: u64, stamp_ns: u64) -> Self {
        Self {
            version: PROTOCOL_VERSION,
            reserved: 0,
            seq,
            stamp_ns,
        }
    }

    /// A header for message `seq`, stamped now.
    pub fn now(seq: u64) -> Self {
        Self::at(seq, monotonic_ns())
    }

    /// Checks the version and that seq and stamp are set.
    pub fn validate(&self) -> Result<(), Invalid> {
        if self.version != PROTOCOL_VERSION {
            return Err(Invalid::new("header.version", Reason::WrongVersion));
        }
        if self.seq == 0 {
            return Err(Invalid::new("header.seq", Reason::OutOfRange));
        }
        if self.stamp_ns == 0 {
            return Err(Invalid::new("header.stamp_ns", Reason::OutOfRange));
        }
        Ok(())
    }
}

/// Why a payload was rejected.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum Reason {
    /// A protocol version other than [`PROTOCOL_VERSION`].
    WrongVersion,
    /// NaN or infinite.
    NotFinite,
    /// A number outside its range.
    OutOfRange,
    /// A length or count that does not fit the payload or the grid.
    BadLength,
    /// An enumeration code that is not defined.
    UnknownCode,
}

/// A rejected payload: which field, and why. Does not allocate.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub struct Invalid {
    /// The field (dotted path).
    pub field: &'static str,
    /// The reason.
    pub reason: Reason,
    /// The offending index for array fields (0 otherwise).
    pub index: u32,
}

impl Invalid {
    /// A rejection of `field` for `reason`.
    pub const fn new(field: &'static str, reason: Reason) -> Self {
        Self {
            field,
            reason,
            index: 0,
        }
    }

    pub(crate) const fn at(field: &'static str, reason: Reason, index: usize) -> Self {
        Self {
            field,
            reason,
            index: index as u32,
        }
    }
}

impl std::fmt::Display for Invalid {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        write!(f, "{}[{}]: {:?}", self.field, self.index, self.reason)
    }
}

impl std::error::Error for Invalid {}

/// A payload of this crate: `repr(C)`, numbers only (all-zero bytes are a valid value), and no
/// padding (every field starts where the previous ends; `ipc/tests/contract_doc.rs` checks it
/// for every payload).
pub trait Payload: ZeroCopySend + Copy + std::fmt::Debug + 'static {
    /// The header.
    fn header(&self) -> &Header;

    /// The payload's bytes as on the wire (for run logs).
    fn as_bytes(&self) -> &[u8] {
        // SAFETY: a payload is `repr(C)`, made of numbers and without padding, so every one of
        // its `size_of` bytes is initialised.
        unsafe { std::slice::from_raw_parts((self as *const Self).cast::<u8>(), size_of::<Self>()) }
    }

    /// A payload from bytes written by [`Payload::as_bytes`]; `None` if the length differs.
    /// Any bytes make a value (all numbers; enums travel as `u32` codes): validate it.
    fn from_bytes(b: &[u8]) -> Option<Self> {
        if b.len() != size_of::<Self>() {
            return None;
        }
        // SAFETY: the length matches and every bit pattern is a valid payload (numbers only).
        Some(unsafe { std::ptr::read_unaligned(b.as_ptr().cast::<Self>()) })
    }
}

pub(crate) fn finite_all<T: Copy + Into<f64>>(field: &'static str, v: &[T]) -> Result<(), Invalid> {
    match v.iter().position(|x| !(*x).into().is_finite()) {
        Some(i) => Err(Invalid::at(field, Reason::NotFinite, i)),
        None => Ok(()),
    }
}

pub(crate) fn within<T: Copy + Into<f64>>(
    field: &'static str,
    v: &[T],
    lo: f64,
    hi: f64,
) -> Result<(), Invalid> {
    finite_all(field, v)?;
    match v.iter().position(|x| !(lo..=hi).contains(&(*x).into())) {
        Some(i) => Err(Invalid::at(field, Reason::OutOfRange, i)),
        None => Ok(()),
    }
}

pub(crate) fn flag(field: &'static str, v: u32) -> Result<(), Invalid> {
    if v <= 1 {
        Ok(())
    } else {
        Err(Invalid::new(field, Reason::UnknownCode))
    }
}

/// The order of one service's samples. From one publisher, each sample's sequence number and
/// stamp must be greater than the last accepted one's; a new publisher (a restarted adapter,
/// whose sequence starts over) is accepted and becomes the reference.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq)]
pub struct InOrder {
    last: Option<(u128, u64, u64)>,
}

impl InOrder {
    /// The last accepted sample: publisher, sequence number, stamp (for a run log's snapshot).
    pub fn last(&self) -> Option<(u128, u64, u64)> {
        self.last
    }

    /// An order check that last accepted `last` (a snapshot's).
    pub fn with_last(last: Option<(u128, u64, u64)>) -> Self {
        Self { last }
    }

    /// Whether a sample from `publisher` (iceoryx2's unique publisher id) with `header` comes
    /// after the last accepted one; a sample that repeats or goes back in sequence or stamp is
    /// refused (the caller drops and counts it) and changes nothing.
    pub fn accept(&mut self, publisher: u128, header: &Header) -> bool {
        let ok = match self.last {
            Some((p, seq, stamp)) if p == publisher => header.seq > seq && header.stamp_ns >= stamp,
            _ => true,
        };
        if ok {
            self.last = Some((publisher, header.seq, header.stamp_ns));
        }
        ok
    }
}
