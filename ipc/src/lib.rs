//! HERB's IPC contract (`ipc/CONTRACT.md`; processes: `ARCHITECTURE.md`): every payload exchanged
//! between `herbd`, the hardware adapters and the clients, the service names, one validation
//! function per payload, the codes' operator words, and the iceoryx2 ports with the contract's
//! QoS ([`bus`]).
//!
//! Every payload is `#[repr(C)]`, fixed size, without heap or pointers, derives iceoryx2's
//! `ZeroCopySend` with an explicit, versioned type name, and starts with a [`Header`]
//! (protocol version, sequence number, monotonic stamp). All-zero bytes are a valid value of
//! every payload (numbers only), which lets large payloads be initialised in place in shared
//! memory ([`zeroed_in_place`]).
//!
//! Units: SI (m, rad, s); stamps are `CLOCK_MONOTONIC` nanoseconds, comparable between the
//! processes of one machine. Poses in [`Status`] are in the box frame B (z up, origin at the
//! centre of the inner floor); joint values are Baxter left-arm joints `s0 .. w2`.
//!
//! A receiver calls the payload's `validate` before using any field; an invalid payload is
//! counted and dropped, never acted on. [`Invalid`] names the field and the reason and does not
//! allocate, so a real-time loop can validate and count without formatting.

#![warn(missing_docs)]

pub mod bus;

macro_rules! payload {
    ($t:ty) => {
        impl Payload for $t {
            fn header(&self) -> &Header {
                &self.header
            }
        }
    };
}

/// Declares a wire enum: `repr(u32)` with the codes 0, 1, 2... in the order written (checked
/// at compile time), and its `from_code`, so that each enum lists its variants once.
macro_rules! wire_enum {
    (
        $(#[$meta:meta])*
        pub enum $name:ident ($what:literal) {
            $($(#[$vmeta:meta])* $variant:ident = $code:literal,)+
        }
    ) => {
        $(#[$meta])*
        #[derive(Debug, Clone, Copy, PartialEq, Eq)]
        #[repr(u32)]
        pub enum $name {
            $($(#[$vmeta])* $variant = $code,)+
        }

        impl $name {
            #[doc = concat!("The ", $what, " for a wire code, if defined.")]
            pub fn from_code(c: u32) -> Option<Self> {
                [$(Self::$variant),+].get(c as usize).copied()
            }
        }

        const _: () = {
            let mut next = 0u32;
            $(
                assert!($code == next, "wire codes are 0, 1, 2... in order");
                next += 1;
            )+
            let _ = next;
        };
    };
    // Each variant with a few words for an operator: `describe()` returns them.
    (
        $(#[$meta:meta])*
        pub enum $name:ident ($what:literal) {
            $($(#[$vmeta:meta])* $variant:ident = $code:literal => $words:literal,)+
        }
    ) => {
        wire_enum! {
            $(#[$meta])*
            pub enum $name ($what) {
                $($(#[$vmeta])* $variant = $code,)+
            }
        }

        impl $name {
            /// What it means, in a few words for an operator.
            pub fn describe(self) -> &'static str {
                match self {
                    $(Self::$variant => $words,)+
                }
            }
        }
    };
}

mod arm;
mod base;
mod camera;
mod decision;
mod job;
mod services;
mod sim;

pub use arm::*;
pub use base::*;
pub use camera::*;
pub use decision::*;
pub use job::*;
pub use services::*;
pub use sim::*;

#[cfg(test)]
mod tests {
    use super::*;
    use iceoryx2::prelude::*;
    use std::mem::MaybeUninit;

    fn js() -> JointState {
        JointState {
            header: Header::now(1),
            position: [0.1; DOF],
            velocity: [0.0; DOF],
        }
    }

    #[test]
    fn payload_bytes_round_trip_bit_for_bit() {
        let mut m = js();
        m.position[2] = f64::from_bits(0x7ff8_dead_beef_0001); // a NaN with a payload
        let b = m.as_bytes();
        assert_eq!(b.len(), size_of::<JointState>());
        let back = JointState::from_bytes(b).unwrap();
        assert_eq!(back.position[2].to_bits(), 0x7ff8_dead_beef_0001);
        assert_eq!(back.as_bytes(), b);
        assert!(JointState::from_bytes(&b[1..]).is_none(), "wrong length");
    }

    #[test]
    fn joint_state_rejects_nan_version_and_range() {
        assert_eq!(js().validate(), Ok(()));
        let mut m = js();
        m.position[3] = f64::NAN;
        assert_eq!(
            m.validate(),
            Err(Invalid::at("position", Reason::NotFinite, 3))
        );
        let mut m = js();
        m.header.version = PROTOCOL_VERSION + 1;
        assert_eq!(m.validate().unwrap_err().reason, Reason::WrongVersion);
        let mut m = js();
        m.velocity[0] = 100.0;
        assert_eq!(m.validate().unwrap_err().reason, Reason::OutOfRange);
        let mut m = js();
        m.header.seq = 0;
        assert_eq!(m.validate().unwrap_err().field, "header.seq");
    }

    #[test]
    fn joint_command_checks_the_receivers_limits() {
        let c = JointCommand {
            header: Header::now(5),
            position: [0.5; DOF],
            velocity: [0.0; DOF],
            acceleration: [0.0; DOF],
        };
        assert_eq!(c.validate(&[-1.0; DOF], &[1.0; DOF]), Ok(()));
        let mut upper = [1.0; DOF];
        upper[6] = 0.4;
        assert_eq!(
            c.validate(&[-1.0; DOF], &upper),
            Err(Invalid::at("position", Reason::OutOfRange, 6))
        );
        let mut bad = c;
        bad.acceleration[2] = f64::INFINITY;
        assert_eq!(
            bad.validate(&[-1.0; DOF], &[1.0; DOF]).unwrap_err().reason,
            Reason::NotFinite
        );
    }

    #[test]
    fn heightmap_frame_lengths_and_values() {
        let mut slot = Box::new(MaybeUninit::<HeightmapFrame>::uninit());
        let f = zeroed_in_place(&mut slot);
        assert_eq!(f.validate_meta().unwrap_err().field, "header.version");
        f.header = Header::now(1);
        assert_eq!(f.validate().unwrap_err().reason, Reason::BadLength);
        f.nx = 300;
        f.ny = 300; // 90000 cells > capacity
        f.cell_m = 0.0015625;
        assert_eq!(f.validate().unwrap_err().reason, Reason::BadLength);
        f.nx = 222;
        f.ny = 146;
        assert_eq!(f.validate(), Ok(()));
        assert_eq!(f.cells().len(), 222 * 146);
        f.data[222 * 146 - 1] = f32::NAN;
        assert_eq!(
            f.validate(),
            Err(Invalid::at("data", Reason::NotFinite, 222 * 146 - 1))
        );
        // Cells past nx * ny are not looked at.
        f.data[222 * 146 - 1] = 0.1;
        f.data[222 * 146] = f32::NAN;
        assert_eq!(f.validate(), Ok(()));
        f.data[5] = 2.0;
        assert_eq!(f.validate().unwrap_err().reason, Reason::OutOfRange);
        f.cell_m = f32::NAN;
        assert_eq!(f.validate_meta().unwrap_err().field, "cell_m");
    }

    #[test]
    fn pack_job_rejections() {
        assert_eq!(PackJobRequest::new(7, &[1, 2, 3]).validate(24), Ok(()));
        assert_eq!(
            PackJobRequest::new(7, &[]).validate(24),
            Err((RejectReason::Empty, 0))
        );
        assert_eq!(
            PackJobRequest::new(7, &[1, 24, 3]).validate(24),
            Err((RejectReason::UnknownObject, 1))
        );
        assert_eq!(
            PackJobRequest::new(0, &[1]).validate(24),
            Err((RejectReason::Malformed, 0))
        );
        let big: Vec<u16> = (0..65).map(|i| (i % 24) as u16).collect();
        assert_eq!(
            PackJobRequest::new(7, &big).validate(24),
            Err((RejectReason::TooMany, 65))
        );
        let mut r = PackJobRequest::new(7, &[1]);
        r.count = 1000;
        assert!(r.objects().is_empty());
        assert_eq!(r.validate(24), Err((RejectReason::TooMany, 1000)));
    }

    #[test]
    fn reply_status_and_gripper_codes() {
        let mut r = PackJobReply {
            header: Header::now(1),
            job_id: 3,
            accepted: 1,
            reason: 0,
            detail: 0,
            reserved: 0,
        };
        assert_eq!(r.validate(), Ok(RejectReason::None));
        r.reason = RejectReason::Busy as u32;
        assert!(r.validate().is_err(), "accepted with a reason");
        r.accepted = 0;
        assert_eq!(r.validate(), Ok(RejectReason::Busy));
        r.reason = RejectReason::NotReady as u32;
        assert_eq!(r.validate(), Ok(RejectReason::NotReady));
        r.reason = 99;
        assert_eq!(r.validate().unwrap_err().reason, Reason::UnknownCode);

        let g = GripperCommand {
            header: Header::now(1),
            job_id: 3,
            action: 1,
            object_type: 5,
        };
        assert_eq!(g.validate(24), Ok(GripperAction::Close));
        assert!(GripperCommand { action: 2, ..g }.validate(24).is_err());
        assert!(
            GripperCommand {
                object_type: 24,
                ..g
            }
            .validate(24)
            .is_err()
        );
        assert!(
            GripperCommand {
                object_type: NO_OBJECT,
                ..g
            }
            .validate(24)
            .is_ok()
        );

        let mut slot = MaybeUninit::<Status>::uninit();
        let s = zeroed_in_place(&mut slot);
        s.header = Header::now(1);
        assert_eq!(s.validate(), Ok(()));
        s.event = 42;
        assert_eq!(s.validate().unwrap_err().field, "event");
        s.event = 0;
        s.objects_done = 3;
        assert_eq!(s.validate().unwrap_err().field, "objects_done");
    }

    #[test]
    fn type_names_are_explicit_and_versioned() {
        // SAFETY: type_name has no preconditions for these types; it is unsafe only because
        // the trait as a whole is.
        let names = unsafe {
            [
                Header::type_name(),
                HeightmapFrame::type_name(),
                JointState::type_name(),
                JointCommand::type_name(),
                GripperCommand::type_name(),
                GripperState::type_name(),
                ArmStatus::type_name(),
                Status::type_name(),
                PackJobRequest::type_name(),
                PackJobReply::type_name(),
                CancelJobRequest::type_name(),
                CancelJobReply::type_name(),
                ConfirmPickRequest::type_name(),
                ConfirmPickReply::type_name(),
                CandidateReport::type_name(),
                DecisionReport::type_name(),
                SimReset::type_name(),
                SimObject::type_name(),
                CommandChecks::type_name(),
                SimOutcome::type_name(),
            ]
        };
        for n in names {
            let name = n.rsplit("::").next().unwrap();
            assert_eq!(n, format!("herb::v{PROTOCOL_VERSION}::{name}"));
            assert_eq!(wire_version_of(n), Some(PROTOCOL_VERSION));
        }
        assert_eq!(names[7], "herb::v2::Status");
    }

    #[test]
    fn service_prefix() {
        let s = Services::new("test/a1").unwrap();
        assert_eq!(s.joint_state(), "test/a1/joint_state");
        assert!(Services::new("").is_err());
        assert!(Services::new("/abs").is_err());
        assert!(Services::new("a b").is_err());
        assert_eq!(Services::default().status(), "herb/status");
    }

    #[test]
    fn samples_in_order_per_publisher_and_a_new_publisher_starts_over() {
        let h = |seq, stamp_ns| Header {
            seq,
            stamp_ns,
            ..Header::now(seq)
        };
        let mut o = InOrder::default();
        assert!(o.accept(7, &h(1, 100)));
        assert!(o.accept(7, &h(2, 100)), "same stamp, later sequence");
        assert!(!o.accept(7, &h(2, 200)), "repeated sequence");
        assert!(!o.accept(7, &h(1, 300)), "sequence backwards");
        assert!(!o.accept(7, &h(3, 50)), "stamp backwards");
        assert!(o.accept(7, &h(3, 300)), "refusals changed nothing");
        assert!(o.accept(9, &h(1, 400)), "a restarted publisher starts over");
        assert!(!o.accept(9, &h(1, 500)));
    }
}
