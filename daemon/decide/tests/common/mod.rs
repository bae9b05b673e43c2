//! Shared helpers for the decision-core integration tests.
#![allow(dead_code)]

use herb_decide::DecideError;
use herb_decide::policy::{DecisionInput, PlanarPose, Policy};
use herb_sim::{Catalog, Heightmap, ObsLayout, TypeIdx};

/// One decision of `p` for object `t` over `hm` at step 0 (a zero observation), with `after`
/// the objects still to come.
pub fn decide(
    p: &mut dyn Policy,
    c: &Catalog,
    hm: &Heightmap,
    t: TypeIdx,
    after: &[TypeIdx],
) -> Result<PlanarPose, DecideError> {
    let obs = vec![0.0; ObsLayout::LEN];
    let remaining: Vec<TypeIdx> = std::iter::once(t).chain(after.iter().copied()).collect();
    p.decide(&DecisionInput {
        observation: &obs,
        heightmap: hm,
        object: t,
        shape: c.shape(t),
        step: 0,
        catalog: c,
        remaining: &remaining,
    })
}
