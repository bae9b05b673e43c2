//! How a placement was decided, for viewers.

use crate::base::*;
use iceoryx2::prelude::*;

/// Candidates a [`DecisionReport`] lists at most (the placement lattice's size).
pub const MAX_REPORTED_CANDIDATES: usize = 64;

/// One candidate placement a search rolled out (part of [`DecisionReport`]). Frame B, metres,
/// radians.
#[derive(Debug, Clone, Copy, PartialEq, Default, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::CandidateReport")]
pub struct CandidateReport {
    /// B x of the object's canonical origin.
    pub x: f32,
    /// B y.
    pub y: f32,
    /// Yaw about B z.
    pub yaw: f32,
    /// The rollout's return (the configured reward's, CS0.6 by default).
    pub ret: f32,
    /// Objects the rollout placed inside, the candidate's included.
    pub packed: u32,
    /// Bit 0: the rollout placed every object inside; bit 1: the candidate chosen.
    pub flags: u32,
}

/// How a placement was decided, for viewers (published by herbd's decision thread after each
/// decision; informational: the job's course is in [`Status`]).
#[derive(Debug, Clone, Copy, PartialEq, ZeroCopySend)]
#[repr(C)]
#[type_name("herb::v2::DecisionReport")]
pub struct DecisionReport {
    /// Header; the stamp is the decision's end.
    pub header: Header,
    /// The job.
    pub job_id: u64,
    /// The object's index in the packing order.
    pub object_index: u32,
    /// Its catalog type index.
    pub object_type: u32,
    /// 0: a placement policy; 1: the search.
    pub method: u32,
    /// Feasible candidates the placement lattice offered (the search's; 0 for a policy).
    pub feasible: u32,
    /// Rollouts the search's budget allowed (finished).
    pub allowed: u32,
    /// Candidates listed in `candidates`.
    pub count: u32,
    /// The placement decided: x, y, z (m), yaw (rad); zeros when there is none.
    pub pose: [f32; 4],
    /// 1 when a placement was decided.
    pub decided: u32,
    /// Reserved, zero.
    pub reserved: u32,
    /// The decision's latency, ns.
    pub decision_ns: u64,
    /// The candidates rolled out, in the prior's order (the first `count`).
    pub candidates: [CandidateReport; MAX_REPORTED_CANDIDATES],
}
payload!(DecisionReport);

impl DecisionReport {
    /// Header, codes, counts and finite numbers.
    pub fn validate(&self) -> Result<(), Invalid> {
        self.header.validate()?;
        flag("method", self.method)?;
        flag("decided", self.decided)?;
        if self.count as usize > MAX_REPORTED_CANDIDATES {
            return Err(Invalid::new("count", Reason::BadLength));
        }
        finite_all("pose", &self.pose)?;
        for c in self.candidates_listed() {
            finite_all("candidates", &[c.x, c.y, c.yaw, c.ret])?;
        }
        Ok(())
    }

    /// The candidates listed (the first `count`).
    pub fn candidates_listed(&self) -> &[CandidateReport] {
        &self.candidates[..(self.count as usize).min(MAX_REPORTED_CANDIDATES)]
    }
}
