//! The wire says its version: a process of another contract version that opens one of HERB's
//! services gets an error naming both versions, not iceoryx2's type-size mismatch. Tried with
//! the `Status` of wire version 1 (144 bytes, before `waiting_for`), as an older client has it,
//! against a service created by this version, and the other way round.

use herb_ipc::bus::Bus;
use herb_ipc::{Header, PROTOCOL_VERSION, Payload, Services, Status, wire_version_of};
use iceoryx2::prelude::*;

/// `Status` as wire version 1 laid it out: the header, then 120 bytes of fields (its last
/// field `attempt` at 140), 144 bytes in all.
#[derive(Debug, Clone, Copy, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v1::Status")]
struct StatusV1 {
    header: Header,
    fields: [u64; 15],
}

impl Payload for StatusV1 {
    fn header(&self) -> &Header {
        &self.header
    }
}

fn services(tag: &str) -> Services {
    Services::new(&format!("version{}{tag}", std::process::id())).unwrap()
}

#[test]
fn the_old_status_is_another_size_under_another_name() {
    assert_eq!(size_of::<StatusV1>(), 144);
    assert_ne!(size_of::<StatusV1>(), size_of::<Status>());
    assert_eq!(PROTOCOL_VERSION, 2);
    assert_eq!(wire_version_of("herb::v1::Status"), Some(1));
    assert_eq!(wire_version_of("herb::v12::X"), Some(12));
    assert_eq!(wire_version_of("other::v1::Status"), None);
    assert_eq!(wire_version_of("herb::vx::Status"), None);
}

#[test]
fn an_old_client_is_told_both_versions() {
    let s = services("old");
    // herbd of this version publishes its status.
    let daemon = Bus::open("version-daemon", &s).unwrap();
    let _status = daemon.publisher::<Status>(&s.status()).unwrap();
    // A client of version 1 subscribes.
    let client = Bus::open("version-client", &s).unwrap();
    let e = client
        .subscriber::<StatusV1>(&s.status())
        .expect_err("an old client cannot open the new status");
    assert_eq!(e.versions, Some((1, PROTOCOL_VERSION)), "{e}");
    let text = e.to_string();
    assert!(
        text.contains("wire version mismatch")
            && text.contains("speaks HERB wire version 1")
            && text.contains("process of version 2")
            && text.contains("herb::v2::Status"),
        "{text}"
    );
    assert!(!text.to_lowercase().contains("size"), "{text}");
}

#[test]
fn a_new_client_of_an_old_daemon_is_told_both_versions() {
    let s = services("new");
    let daemon = Bus::open("version-old-daemon", &s).unwrap();
    let _status = daemon.publisher::<StatusV1>(&s.status()).unwrap();
    let client = Bus::open("version-new-client", &s).unwrap();
    let e = client
        .subscriber::<Status>(&s.status())
        .expect_err("a new client cannot open the old status");
    assert_eq!(e.versions, Some((PROTOCOL_VERSION, 1)), "{e}");
    assert!(e.to_string().contains("herb::v1::Status"), "{e}");
}

#[test]
fn the_same_version_opens_and_another_error_stays_itself() {
    let s = services("same");
    let a = Bus::open("version-a", &s).unwrap();
    let _p = a.publisher::<Status>(&s.status()).unwrap();
    let b = Bus::open("version-b", &s).unwrap();
    assert!(b.subscriber::<Status>(&s.status()).is_ok());
    // A second publisher on a one-publisher service fails for its own reason, not a version.
    let _cmd = a
        .publisher::<herb_ipc::JointCommand>(&s.joint_command())
        .unwrap();
    let e = b
        .publisher::<herb_ipc::JointCommand>(&s.joint_command())
        .expect_err("one publisher");
    assert_eq!(e.versions, None, "{e}");
}
