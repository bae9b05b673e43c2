//! The decision worker and the planner driven by arbitrary policy outputs (proptest): a policy
//! that returns any three numbers (NaN, infinities, out of range, or plausible), decided on an
//! empty box (`DecisionCore`, as herbd's worker decides) and planned as herbd plans it
//! (`PlannerCore`: IK, Ruckig). Whatever the output, either it is refused with a fault or every
//! setpoint of its plan is inside the configured joint limits with finite speeds and
//! accelerations; an action outside `[-1, 1]^3` or not finite is always refused as a decision
//! fault, never placed. The same for a held object's place planned from any pose.
//!
//! Budget: `PROPTEST_CASES` cases (a quarter of proptest's default 256 in CI, each case plans
//! a whole pick and place); `scripts/fuzz.sh` runs more.

use herb_core::frames::{BOX_HALF_X, BOX_HALF_Y};
use herb_core::observation::ObsLayout;
use herb_core::paths::MeshSource;
use herb_core::{Catalog, GridSpec, TypeIdx};
use herb_daemon::config::Config;
use herb_daemon::decision::DecisionCore;
use herb_daemon::plan::{DecisionRequest, Motion, MotionPlan, Request, Response};
use herb_daemon::planner::PlannerCore;
use herb_decide::{DecisionInput, Order, PlanarPose, Policy, SequenceModel};
use herb_ipc::{Fault, HeightmapFrame, MAX_JOB_OBJECTS};
use herb_robot::kinematics::LEFT_TOP_DOWN_NOMINAL;
use proptest::prelude::*;
use std::path::Path;
use std::sync::Arc;

/// A policy that answers with a fixed placement, whatever it is shown (a test fixture), given
/// as a normalised action: x and y over the box's half sides, the yaw over pi (the generated
/// values reach past the box and are not always finite).
struct Scripted([f32; 3]);

impl Policy for Scripted {
    fn name(&self) -> &str {
        "scripted (fixture)"
    }
    fn begin_episode(&mut self, _seed: u64) {}
    fn decide(&mut self, _input: &DecisionInput) -> herb_decide::Result<PlanarPose> {
        let [x, y, t] = self.0;
        Ok(PlanarPose {
            x: x * BOX_HALF_X,
            y: y * BOX_HALF_Y,
            theta: t * std::f32::consts::PI,
        })
    }
    fn needs_observation(&self) -> bool {
        false
    }
}

/// The catalog (primitives), built once for every case.
fn catalog() -> Arc<Catalog> {
    static CATALOG: std::sync::OnceLock<Arc<Catalog>> = std::sync::OnceLock::new();
    CATALOG
        .get_or_init(|| Arc::new(Catalog::builtin(&MeshSource::None("fixture".into())).unwrap()))
        .clone()
}

fn config() -> Config {
    let mut cfg = Config::default();
    cfg.models.sequence = Path::new(env!("CARGO_MANIFEST_DIR")).join("../models/sequence.json");
    cfg
}

/// An empty box's heightmap, as the camera publishes it.
fn empty_frame() -> Box<HeightmapFrame> {
    let spec = GridSpec::for_box(ObsLayout::CELL_M).unwrap();
    Box::new(HeightmapFrame {
        header: herb_ipc::Header::at(1, 2),
        nx: spec.nx as u32,
        ny: spec.ny as u32,
        cell_m: ObsLayout::CELL_M,
        objects: 0,
        data: [0.0; herb_ipc::HEIGHTMAP_MAX_CELLS],
    })
}

/// Any f32: every bit pattern (NaN, infinities, subnormals), or a plausible action value.
fn any_f32() -> impl Strategy<Value = f32> {
    prop_oneof![
        any::<u32>().prop_map(f32::from_bits),
        -1.0f32..=1.0,
        Just(f32::NAN),
        Just(f32::INFINITY),
        Just(-1.0000001f32),
    ]
}

/// Plans `motion` of object `object` to `pose` with `core` and checks the outcome (module
/// docs): `None` when planned (every setpoint checked), the fault when refused.
fn check_plan(
    core: &mut PlannerCore,
    cfg: &Config,
    object: u16,
    motion: Motion,
    pose: [f32; 4],
) -> Result<Option<Fault>, TestCaseError> {
    let buf = Box::new(MotionPlan::with_capacity(cfg.trajectory_samples()));
    let r = Request::Plan {
        index: 0,
        object,
        from: LEFT_TOP_DOWN_NOMINAL,
        motion,
        pose,
        buf,
    };
    match core.handle(r) {
        Response::Planned(plan) => {
            let (lo, hi) = (cfg.limits.lower, cfg.limits.upper);
            for i in 0..plan.setpoints.len() {
                let s = plan.setpoints.get(i).unwrap();
                for j in 0..lo.len() {
                    prop_assert!(
                        s.position[j] >= lo[j] - 1e-9 && s.position[j] <= hi[j] + 1e-9,
                        "sample {i} joint {j} at {} outside [{}, {}]",
                        s.position[j],
                        lo[j],
                        hi[j]
                    );
                    prop_assert!(s.velocity[j].is_finite() && s.acceleration[j].is_finite());
                }
            }
            prop_assert!(plan.pose.iter().all(|v| v.is_finite()));
            Ok(None)
        }
        Response::Failed { fault, .. } => Ok(Some(fault)),
        _ => Err(TestCaseError::fail("unexpected response to a plan request")),
    }
}

/// Decides object `object` (a one-object job) with a policy answering `action`, then plans its
/// pick and place there: the decision's fault, or the plan's outcome.
fn decide_and_plan(
    cfg: &Config,
    object: u16,
    action: [f32; 3],
) -> Result<Option<Fault>, TestCaseError> {
    let mut decider = DecisionCore::with_policy(cfg, catalog(), Box::new(Scripted(action)));
    let mut order = [0u16; MAX_JOB_OBJECTS];
    order[0] = object;
    let req = DecisionRequest {
        job_id: 1,
        index: 0,
        order,
        count: 1,
        after_stamp_ns: 0,
    };
    let d = decider.decide(&req, &empty_frame(), None);
    match d.outcome {
        Err(f) => Ok(Some(f)),
        Ok(pose) => {
            let mut core = PlannerCore::new(cfg, catalog()).unwrap();
            check_plan(&mut core, cfg, object, Motion::PickAndPlace, pose)
        }
    }
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(
        (ProptestConfig::default().cases / 4).max(1)
    ))]

    #[test]
    fn any_policy_output_is_planned_within_the_limits_or_refused(
        action in [any_f32(), any_f32(), any_f32()],
        object in 0u16..24,
    ) {
        let cfg = config();
        // Refused: a value not finite, or a position past the box (a yaw of any size is
        // wrapped into (-pi, pi] and planned).
        let valid = action.iter().all(|a| a.is_finite())
            && action[..2].iter().all(|a| (-1.0..=1.0).contains(a));
        let outcome = decide_and_plan(&cfg, object, action)?;
        if !valid {
            prop_assert_eq!(outcome, Some(Fault::Decision), "action {:?}", action);
        }
    }

    #[test]
    fn any_held_placement_is_planned_within_the_limits_or_refused(
        pose in [any_f32(), any_f32(), any_f32(), any_f32()],
        object in 0u16..24,
    ) {
        let cfg = config();
        let mut core = PlannerCore::new(&cfg, catalog()).unwrap();
        for flip in [false, true] {
            check_plan(&mut core, &cfg, object, Motion::Place { flip }, pose)?;
        }
    }
}

/// The properties above are not vacuous: a plausible action is planned, and its plan is
/// checked sample by sample like any other.
#[test]
fn a_plausible_action_is_planned_and_checked() {
    let cfg = config();
    for object in [0u16, 1, 11] {
        let outcome =
            decide_and_plan(&cfg, object, [0.2, -0.3, 0.5]).unwrap_or_else(|e| panic!("{e}"));
        assert_eq!(
            outcome, None,
            "object {object}: a plausible action was refused"
        );
    }
}

/// herbd orders a job with HERB's Beam-3 (`Order::HERB`: every search from `<start>`, as
/// Algorithm 1 writes it), and keeps a recovered job's order as given.
#[test]
fn jobs_are_ordered_with_herbs_beam3_and_recovered_ones_kept_as_given() {
    let cfg = config();
    let catalog = catalog();
    let model = SequenceModel::load(&cfg.models.sequence, &catalog).unwrap();
    let mut core = PlannerCore::new(&cfg, catalog.clone()).unwrap();
    let job: Vec<u16> = vec![20, 3, 3, 11, 7, 0, 15, 22, 9, 1, 18];
    let types: Vec<TypeIdx> = job.iter().map(|&t| TypeIdx(t)).collect();
    let ids = |v: Vec<TypeIdx>| v.iter().map(|t| t.0).collect::<Vec<u16>>();
    let herb = ids(Order::HERB
        .order(&catalog, Some(&model), &types, 0)
        .unwrap());
    // The job tells the two readings apart, so the check below says which one herbd uses.
    let other = ids(Order::Beam3Last
        .order(&catalog, Some(&model), &types, 0)
        .unwrap());
    assert_ne!(herb, other);
    for (ordered, want) in [(false, herb), (true, job.clone())] {
        let mut objects = [0u16; MAX_JOB_OBJECTS];
        objects[..job.len()].copy_from_slice(&job);
        let r = core.handle(Request::Order {
            job_id: 7,
            objects,
            count: job.len(),
            ordered,
        });
        match r {
            Response::Ordered {
                job_id,
                order,
                count,
            } => {
                assert_eq!(job_id, 7);
                assert_eq!(&order[..count], &want[..], "ordered: {ordered}");
            }
            _ => panic!("the job was not ordered (ordered: {ordered})"),
        }
    }
}
