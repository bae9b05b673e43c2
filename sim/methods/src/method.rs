//! The ways Table I places objects, named once for the CLI, the bindings and the tables.

use herb_decide::Order;
use herb_sim::RewardMode;
use herb_sim::catalog::Catalog;
use herb_sim::eval::Replay;
use herb_sim::lattice::Lattice;
use herb_sim::reserve::Reserve;
use herb_sim::teacher::{GeoLookahead, LatticeRule, Lookahead};

/// A placement method: a decision-core policy, a replay of the humans, random actions, one of
/// the lattice rules (the teachers and their baselines), or the search.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Method {
    /// HERB: HERB's Beam-3 order ([`Order::HERB`], default) and an ONNX placement policy.
    Herb,
    /// The PackIt SO(2) heuristic, largest first (default order).
    Blbf,
    /// Human order, the humans' planar placements.
    Human,
    /// Human order, the humans' full orientations.
    HumanPose,
    /// Human order, uniform random actions.
    Random,
    /// The humans' recorded poses checked against the success volume, without physics.
    HumanRecorded,
    /// The PackIt heuristic with its rotation search over the 24 axis-aligned orientations
    /// ([`herb_decide::PackitSo3`]), largest first (default order).
    PackitSo3,
    /// Behaviour cloning with a squared-error loss (`training/bc.py`), human order, each
    /// participant scored by the model trained without them.
    BcMse,
    /// Behaviour cloning with a mixture density network (`training/bc.py`), human order, each
    /// participant scored by the model trained without them.
    BcMdn,
    /// The BLBF rule restricted to the placement lattice (largest first by default).
    LatticeBlbf,
    /// The lookahead teacher: the best of k lattice candidates by the return of a lattice-BLBF
    /// rollout to the episode's end (HERB's order by default).
    Lookahead,
    /// The lattice BLBF rule keeping room for later objects (HERB's order by default).
    LatticeReserve,
    /// The geometric lookahead teacher: the best of k lattice candidates by a physics-free
    /// lattice-BLBF rollout (HERB's order by default).
    GeoLookahead,
    /// The search: lattice candidates in lattice BLBF's order, the best by the return of a
    /// rollout to the job's end in a twin built from the heightmap, within a budget
    /// ([`herb_search`]; HERB's order by default).
    Search,
}

impl Method {
    /// Every method, in the order of the tables.
    pub const ALL: [Method; 14] = [
        Self::Herb,
        Self::Blbf,
        Self::Human,
        Self::HumanPose,
        Self::Random,
        Self::HumanRecorded,
        Self::PackitSo3,
        Self::BcMse,
        Self::BcMdn,
        Self::LatticeBlbf,
        Self::Lookahead,
        Self::LatticeReserve,
        Self::GeoLookahead,
        Self::Search,
    ];

    /// Name on the command line, in the bindings and in the tables.
    pub fn name(&self) -> &'static str {
        match self {
            Self::Herb => "herb",
            Self::Blbf => "blbf",
            Self::Human => "human",
            Self::HumanPose => "human-pose",
            Self::Random => "random",
            Self::HumanRecorded => "human-recorded",
            Self::PackitSo3 => "packit-so3",
            Self::BcMse => "bc-mse",
            Self::BcMdn => "bc-mdn",
            Self::LatticeBlbf => "lattice-blbf",
            Self::Lookahead => "lookahead",
            Self::LatticeReserve => "lattice-reserve",
            Self::GeoLookahead => "geo-lookahead",
            Self::Search => "search",
        }
    }

    /// The label of this method's rows in the tables: the name, except for the humans' rows,
    /// which say whether they are physics replays or the recorded poses.
    pub fn label(&self) -> &'static str {
        match self {
            Self::Human => "human replay (planar)",
            Self::HumanPose => "human replay (full pose)",
            Self::HumanRecorded => "human (recorded poses)",
            Self::PackitSo3 => "packit SO(3)",
            Self::BcMse => "BC-MSE (participants held out)",
            Self::BcMdn => "BC-MDN (participants held out)",
            _ => self.name(),
        }
    }

    /// The packing world's replay this method is (`None` for the deciding methods).
    pub fn replay(&self) -> Option<Replay> {
        match self {
            Self::Human => Some(Replay::Human),
            Self::HumanPose => Some(Replay::HumanPose),
            Self::Random => Some(Replay::Random),
            Self::HumanRecorded => Some(Replay::HumanRecorded),
            _ => None,
        }
    }

    /// The object order of this method's rows: `chosen` if given, else largest first for the
    /// BLBF rules and HERB's ([`Order::HERB`]) for the others; `None` for the replays (human order).
    pub fn order(&self, chosen: Option<Order>) -> Option<Order> {
        if self.replay().is_some() {
            return None;
        }
        Some(match (chosen, self) {
            (Some(o), _) => o,
            (None, Self::Blbf | Self::LatticeBlbf | Self::PackitSo3) => Order::Largest,
            (None, Self::BcMse | Self::BcMdn) => Order::Human,
            (None, _) => Order::HERB,
        })
    }

    /// The two ONNX files of a behaviour-cloning method in `dir`: the model that scores the even
    /// participants (trained on the odd ones) and the one that scores the odd participants
    /// (`training/bc.py` writes them); `None` for the other methods.
    pub fn bc_models(&self, dir: &std::path::Path) -> Option<[std::path::PathBuf; 2]> {
        let kind = match self {
            Self::BcMse => "mse",
            Self::BcMdn => "mdn",
            _ => return None,
        };
        Some(["even", "odd"].map(|p| dir.join(format!("bc-{kind}-heldout-{p}.onnx"))))
    }

    /// True for the lattice rules ([`Self::lattice_rule`]).
    pub fn is_lattice_rule(&self) -> bool {
        matches!(
            self,
            Self::LatticeBlbf | Self::Lookahead | Self::LatticeReserve | Self::GeoLookahead
        )
    }

    /// A fresh lattice rule for a lattice method (`None` for the others): the teachers weigh
    /// `k` candidates, the lookahead teacher by `reward` over `horizon` objects (all when
    /// `None`).
    pub fn lattice_rule(
        &self,
        catalog: &Catalog,
        k: usize,
        reward: RewardMode,
        horizon: Option<usize>,
    ) -> Option<LatticeRule> {
        Some(match self {
            Self::LatticeBlbf => LatticeRule::Blbf(Box::new(Lattice::new(catalog))),
            Self::Lookahead => {
                let t = Lookahead::new(catalog, k, reward);
                LatticeRule::Lookahead(Box::new(match horizon {
                    Some(h) => t.with_horizon(h),
                    None => t,
                }))
            }
            Self::LatticeReserve => {
                LatticeRule::Reserve(Box::new((Lattice::new(catalog), Reserve::new())))
            }
            Self::GeoLookahead => LatticeRule::Geo(Box::new(GeoLookahead::new(catalog, k))),
            _ => return None,
        })
    }
}

impl std::fmt::Display for Method {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Method {
    type Err = herb_decide::NameError;

    fn from_str(s: &str) -> Result<Self, Self::Err> {
        herb_decide::order::parse_name("method", s, &Self::ALL, Self::name)
    }
}
