//! Fuzzed payloads (proptest): every payload type is built from arbitrary bytes, as a reader
//! of shared memory or of a run log would see them, and validated. Nothing may panic, a
//! payload that validates must honour what validation promises (joint commands inside the
//! receiver's limits, job objects inside the catalog, heightmap cells finite and in range), and
//! bytes of the wrong length are refused.
//!
//! Budget: `PROPTEST_CASES` cases per property (256 by default, what CI runs);
//! `scripts/fuzz.sh` runs the same properties with a larger budget.

use herb_ipc::{
    CancelJobReply, CancelJobRequest, DOF, GripperCommand, GripperState, HEIGHT_RANGE_M, Header,
    HeightmapFrame, JointCommand, JointState, MAX_JOB_OBJECTS, PackJobReply, PackJobRequest,
    Payload, SimOutcome, SimReset, Status,
};
use proptest::prelude::*;

/// The catalog size the daemon runs with (24 BoxED types).
const CATALOG: usize = 24;

/// Bytes of `T`'s size: arbitrary, or a valid-looking base (version 1) with a few arbitrary
/// bytes written over it, so the fuzz reaches past the header check too.
fn payload_bytes<T: Payload>() -> impl Strategy<Value = Vec<u8>> {
    let n = size_of::<T>();
    prop_oneof![
        proptest::collection::vec(any::<u8>(), n),
        proptest::collection::vec((0..n, any::<u8>()), 0..12).prop_map(move |edits| {
            let mut b = vec![0u8; n];
            b[..4].copy_from_slice(&1u32.to_ne_bytes());
            for (i, v) in edits {
                b[i] = v;
            }
            b
        }),
    ]
}

fn from<T: Payload>(b: &[u8]) -> T {
    T::from_bytes(b).expect("the strategy makes bytes of the payload's size")
}

fn limits() -> ([f64; DOF], [f64; DOF]) {
    (
        [-1.7, -2.1, -3.0, -0.05, -3.0, -1.5, -3.0],
        [1.7, 1.0, 3.0, 2.6, 3.0, 2.0, 3.0],
    )
}

proptest! {
    #[test]
    fn wrong_lengths_are_refused(len in 0usize..4096) {
        prop_assume!(len != size_of::<JointCommand>());
        prop_assert!(JointCommand::from_bytes(&vec![0u8; len]).is_none());
    }

    #[test]
    fn joint_commands_that_validate_stay_within_the_limits(b in payload_bytes::<JointCommand>()) {
        let c: JointCommand = from(&b);
        let (lo, hi) = limits();
        if c.validate(&lo, &hi).is_ok() {
            for i in 0..DOF {
                prop_assert!(c.position[i] >= lo[i] && c.position[i] <= hi[i]);
                prop_assert!(c.velocity[i].is_finite() && c.acceleration[i].is_finite());
            }
        }
    }

    #[test]
    fn joint_and_gripper_states_never_panic(
        js in payload_bytes::<JointState>(),
        gs in payload_bytes::<GripperState>(),
        gc in payload_bytes::<GripperCommand>(),
    ) {
        let s: JointState = from(&js);
        if s.validate().is_ok() {
            prop_assert!(s.position.iter().all(|p| p.is_finite()));
        }
        let _ = from::<GripperState>(&gs).validate();
        let _ = from::<GripperCommand>(&gc).validate(CATALOG);
    }

    #[test]
    fn job_requests_that_validate_name_catalog_objects(b in payload_bytes::<PackJobRequest>()) {
        let r: PackJobRequest = from(&b);
        let objects = r.objects();
        prop_assert!(objects.len() <= MAX_JOB_OBJECTS);
        if r.validate(CATALOG).is_ok() {
            prop_assert!(!objects.is_empty() && r.job_id != 0);
            prop_assert!(objects.iter().all(|&t| (t as usize) < CATALOG));
        }
    }

    #[test]
    fn replies_statuses_and_the_rest_never_panic(
        a in payload_bytes::<PackJobReply>(),
        b in payload_bytes::<CancelJobRequest>(),
        c in payload_bytes::<CancelJobReply>(),
        d in payload_bytes::<Status>(),
        e in payload_bytes::<SimReset>(),
        f in payload_bytes::<SimOutcome>(),
    ) {
        let _ = from::<PackJobReply>(&a).validate();
        let _ = from::<CancelJobRequest>(&b).validate();
        let _ = from::<CancelJobReply>(&c).validate();
        let _ = from::<Status>(&d).validate();
        let _ = from::<SimReset>(&e).validate();
        let _ = from::<SimOutcome>(&f).validate();
    }

    #[test]
    fn heightmap_frames_that_validate_have_finite_cells_in_range(
        header in proptest::collection::vec(any::<u8>(), 64),
        cells in proptest::collection::vec((0usize..herb_ipc::HEIGHTMAP_MAX_CELLS, any::<u32>()), 0..16),
        base in prop_oneof![Just(None), (1u32..=224, 1u32..=224).prop_map(Some)],
    ) {
        let mut b = vec![0u8; size_of::<HeightmapFrame>()];
        b[..4].copy_from_slice(&1u32.to_ne_bytes());
        let h = header.len().min(b.len());
        b[..h].copy_from_slice(&header[..h]);
        let mut f: HeightmapFrame = from(&b);
        if let Some((nx, ny)) = base {
            // A plausible frame, so the cell check is reached.
            f.header = Header::at(1, 1);
            f.nx = nx;
            f.ny = ny;
            f.cell_m = 0.0015625;
        }
        for (i, bits) in cells {
            f.data[i] = f32::from_bits(bits);
        }
        let _ = f.validate_meta();
        if f.validate().is_ok() {
            let (lo, hi) = HEIGHT_RANGE_M;
            prop_assert!(f.cells().iter().all(|c| c.is_finite() && *c >= lo && *c <= hi));
        }
    }
}
