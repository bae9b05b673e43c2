//! herbctl's words for what the cell did, the same in every command that prints them (tests
//! and scripts wait for them: keep them stable).

use herb_ipc::{Fault, JobState};

/// Faults that stop the arm's joint states: herbd does not see the arm, so it does not brake
/// it; the robot stopped on its own (disabled, e-stopped, in error, its middleware or its
/// adapter gone, a command refused by the adapter's jump guard).
pub(crate) fn arm_unseen(f: Fault) -> bool {
    matches!(
        f,
        Fault::RobotDisabled
            | Fault::RobotEStop
            | Fault::RobotError
            | Fault::MasterLost
            | Fault::RobotSilent
            | Fault::JointStateTimeout
            | Fault::CommandRefused
    )
}

/// The line for a `Braked` status: `fault` is the fault that stopped the job (the last
/// `Fault` status since the last `Resumed`), `None` for a stop herbd commanded without one (a
/// cancel).
pub(crate) fn stopped(fault: Option<Fault>) -> &'static str {
    match fault {
        Some(f) if arm_unseen(f) => {
            "halted: the robot stopped itself; herbd commands nothing until it is back"
        }
        _ => "braked: the arm stands still",
    }
}

/// How many objects are placed: `placed: 2 of 3 objects` (`, 1 skipped` when some were).
pub(crate) fn placed_count(placed: u32, total: u32, skipped: u32) -> String {
    let noun = if total == 1 { "object" } else { "objects" };
    if skipped == 0 {
        format!("placed: {placed} of {total} {noun}")
    } else {
        format!("placed: {placed} of {total} {noun}, {skipped} skipped")
    }
}

/// The command that cancels job `job` of the herbd under `prefix`.
pub(crate) fn cancel_command(prefix: &str, job: u64) -> String {
    format!("herbctl --prefix {prefix} cancel --job {job}")
}

/// The command that follows the herbd under `prefix`.
pub(crate) fn watch_command(prefix: &str) -> String {
    format!("herbctl --prefix {prefix} watch")
}

/// What a cancel did to the arm: from the job's state and fault `before` the cancel was
/// accepted (if known), whether a `Braked` status came after it, and the fault of the status
/// that ended the job.
pub(crate) fn cancel_outcome(
    before: Option<(JobState, Fault)>,
    braked: bool,
    end: Fault,
) -> String {
    let fault_before = before.map(|(_, f)| f);
    if let Some((JobState::Faulted, f)) = before {
        // Standing on a fault: cancelled where it stood, nothing commanded.
        return if arm_unseen(f) {
            format!(
                "it ended where the arm stood (halted: {}; herbd commanded nothing)",
                f.describe()
            )
        } else {
            format!(
                "it ended where the arm stood (stopped on a fault: {})",
                f.describe()
            )
        };
    }
    let stopped = if braked {
        "the arm braked and"
    } else {
        "the arm"
    };
    // A fault that came with the end: the retreat could not be planned.
    if end != Fault::None && Some(end) != fault_before {
        return format!(
            "{stopped} could not retreat ({}): it stands where it stopped",
            end.describe()
        );
    }
    format!("{stopped} retreated straight up")
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_robot_that_stopped_itself_is_halted_not_braked() {
        for f in [
            Fault::RobotDisabled,
            Fault::RobotEStop,
            Fault::RobotError,
            Fault::MasterLost,
            Fault::RobotSilent,
            Fault::JointStateTimeout,
            Fault::CommandRefused,
        ] {
            assert!(stopped(Some(f)).starts_with("halted: "), "{f:?}");
        }
        for f in [
            None,
            Some(Fault::Stop),
            Some(Fault::Gripper),
            Some(Fault::MissedGrasp),
        ] {
            assert_eq!(stopped(f), "braked: the arm stands still", "{f:?}");
        }
    }

    #[test]
    fn counts_read_as_counts() {
        assert_eq!(placed_count(2, 3, 0), "placed: 2 of 3 objects");
        assert_eq!(placed_count(2, 3, 1), "placed: 2 of 3 objects, 1 skipped");
        assert_eq!(placed_count(0, 1, 0), "placed: 0 of 1 object");
        assert_eq!(
            cancel_command("herb", 42),
            "herbctl --prefix herb cancel --job 42"
        );
    }

    #[test]
    fn a_cancel_says_what_the_arm_did() {
        let running = Some((JobState::Running, Fault::None));
        assert_eq!(
            cancel_outcome(running, true, Fault::None),
            "the arm braked and retreated straight up"
        );
        assert_eq!(
            cancel_outcome(None, false, Fault::None),
            "the arm retreated straight up"
        );
        // A fault from before a resume is not the retreat's.
        let resumed = Some((JobState::Running, Fault::MissedGrasp));
        assert_eq!(
            cancel_outcome(resumed, true, Fault::MissedGrasp),
            "the arm braked and retreated straight up"
        );
        assert_eq!(
            cancel_outcome(running, true, Fault::Unreachable),
            "the arm braked and could not retreat (a waypoint is out of the arm's reach): it \
             stands where it stopped"
        );
        let halted = Some((JobState::Faulted, Fault::RobotEStop));
        assert_eq!(
            cancel_outcome(halted, false, Fault::RobotEStop),
            "it ended where the arm stood (halted: robot e-stopped; herbd commanded nothing)"
        );
    }
}
