//! Contract constants defined on both sides of the IPC boundary agree: the
//! wire's copies in `herb_ipc` and their sources in the simulation and the robot code.

use herb_core::heightmap::HEIGHT_RANGE_M;
use herb_core::{GridSpec, ObsLayout};
use herb_robot::kinematics::{DOF, LEFT_ARM};

#[test]
fn the_wire_carries_the_arm_joints_the_heights_and_the_grid_the_daemon_uses() {
    assert_eq!(herb_ipc::DOF, DOF);
    assert_eq!(LEFT_ARM.len(), herb_ipc::DOF);
    assert_eq!(herb_ipc::HEIGHT_RANGE_M, HEIGHT_RANGE_M);
    let obs = GridSpec::for_box(ObsLayout::CELL_M).unwrap();
    assert!(
        obs.len() <= herb_ipc::HEIGHTMAP_MAX_CELLS,
        "{} x {} observation cells do not fit a frame of {}",
        obs.nx,
        obs.ny,
        herb_ipc::HEIGHTMAP_MAX_CELLS
    );
}
