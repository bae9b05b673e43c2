//! In which order an episode's objects are packed: HERB's Beam-3 over the human transition
//! model, or one of the reference orders of Table I.

use crate::error::{DecideError, NameError, Result};
use crate::sequence::{SequenceModel, beam3, beam3_last};
use herb_core::{Catalog, TypeIdx};
use rand::SeedableRng;
use rand::seq::SliceRandom;
use rand_chacha::ChaCha8Rng;

/// A Beam-3 reading: orders objects with the sequence model.
pub type BeamSearch = fn(&SequenceModel, &[TypeIdx]) -> Result<Vec<TypeIdx>>;

/// How the objects of an episode are ordered.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Hash)]
pub enum Order {
    /// HERB's order: Beam-3 over the human transition model as Algorithm 1 writes it, every
    /// search rooted at `<start>` ([`beam3`]). Name `beam3` (alias `beam3-start`, its name
    /// before, kept for one release).
    Beam3,
    /// The other reading of Beam-3, each search rooted at the last object chosen
    /// ([`beam3_last`]); HERB's order before, kept for comparison. Name `beam3-last`.
    Beam3Last,
    /// The human order.
    Human,
    /// Largest hull volume first (ties: catalog order).
    Largest,
    /// A uniform random permutation (seeded per episode).
    Random,
}

impl Order {
    /// HERB's order ([`Order::Beam3`]): herbd's planner, the HERB rows of Table I and the
    /// training environments order episodes with it.
    pub const HERB: Order = Self::Beam3;

    /// Every order.
    pub const ALL: [Order; 5] = [
        Self::Beam3,
        Self::Beam3Last,
        Self::Human,
        Self::Largest,
        Self::Random,
    ];

    /// Old names still accepted, with the order they name: `beam3-start` is [`Order::Beam3`]
    /// (HERB's order was named so before it took the name `beam3`). Kept for one release.
    pub const ALIASES: [(&'static str, Order); 1] = [("beam3-start", Self::Beam3)];

    /// The Beam-3 reading of this order ([`beam3_last`] or [`beam3`]), `None` for the
    /// orders that do not use the sequence model.
    pub fn beam_search(&self) -> Option<BeamSearch> {
        match self {
            Self::Beam3Last => Some(beam3_last),
            Self::Beam3 => Some(beam3),
            Self::Human | Self::Largest | Self::Random => None,
        }
    }

    /// True for the orders that need the sequence model (the Beam-3 readings).
    pub fn uses_sequence_model(&self) -> bool {
        self.beam_search().is_some()
    }

    /// Name used on the command line, in the bindings and in tables. Parsing also accepts the
    /// alias [`Order::ALIASES`].
    pub fn name(&self) -> &'static str {
        match self {
            Self::Beam3 => "beam3",
            Self::Beam3Last => "beam3-last",
            Self::Human => "human",
            Self::Largest => "largest",
            Self::Random => "random",
        }
    }

    /// Orders `objects` (given in the human order). `model` is needed for Beam-3.
    pub fn order(
        &self,
        catalog: &Catalog,
        model: Option<&SequenceModel>,
        objects: &[TypeIdx],
        seed: u64,
    ) -> Result<Vec<TypeIdx>> {
        if objects.is_empty() {
            return Err(DecideError::EmptyObjectList);
        }
        if let Some(search) = self.beam_search() {
            let m = model.ok_or_else(|| DecideError::SequenceModel {
                origin: self.name().into(),
                message: "no sequence model loaded".into(),
            })?;
            return search(m, objects);
        }
        match self {
            Self::Beam3Last | Self::Beam3 => unreachable!("ordered by beam_search above"),
            Self::Human => Ok(objects.to_vec()),
            Self::Largest => {
                let mut v = objects.to_vec();
                v.sort_by(|&a, &b| {
                    catalog
                        .shape(b)
                        .volume
                        .total_cmp(&catalog.shape(a).volume)
                        .then(a.cmp(&b))
                });
                Ok(v)
            }
            Self::Random => {
                let mut v = objects.to_vec();
                v.shuffle(&mut ChaCha8Rng::seed_from_u64(seed));
                Ok(v)
            }
        }
    }
}

impl std::fmt::Display for Order {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.write_str(self.name())
    }
}

impl std::str::FromStr for Order {
    type Err = NameError;

    fn from_str(s: &str) -> std::result::Result<Self, NameError> {
        match Self::ALIASES.iter().find(|(alias, _)| *alias == s) {
            Some(&(_, order)) => Ok(order),
            None => parse_name("order", s, &Self::ALL, Self::name),
        }
    }
}

/// The member of `all` whose `name` is `s`; else an error naming `what` and listing the names.
pub fn parse_name<T: Copy>(
    what: &'static str,
    s: &str,
    all: &[T],
    name: fn(&T) -> &'static str,
) -> std::result::Result<T, NameError> {
    all.iter()
        .copied()
        .find(|t| name(t) == s)
        .ok_or_else(|| NameError::Unknown {
            what,
            name: s.to_owned(),
            expected: all.iter().map(name).collect(),
        })
}
