//! The candidate placement policy: an ONNX network that scores the placement lattice's
//! candidates (`herb_core::lattice`, `herb_core::features`), run by tract.
//!
//! # Model I/O contract (the candidate contract)
//!
//! Three inputs, `f32`, in this order: `context` `[1, CONTEXT_LEN]`, `candidates`
//! `[1, MAX_CANDIDATES, CANDIDATE_LEN]`, `mask` `[1, MAX_CANDIDATES]` (1 for a real candidate,
//! 0 for padding), filled by [`herb_core::features::DecisionFeatures`]; one output `logits`
//! `[1, MAX_CANDIDATES]`. The policy takes the real candidate with the highest logit (the
//! padding is masked again here, whatever the model does) and returns its placement as an
//! action. Loading checks names, types and shapes and refuses a model that differs, naming
//! what differs; a corrupt file is an error, never a panic.
//!
//! # No feasible placement
//!
//! When the lattice holds no feasible placement (nothing fits between the walls below the
//! height limit), [`Policy::decide`] returns [`DecideError::NoFeasiblePlacement`]: the
//! evaluation ends the episode as a failure with that reason and herbd ends the job with it.
//! No NaN and no placement over a wall ever leaves.

use crate::error::{DecideError, ModelReadError, Result};
use crate::policy::{DecisionInput, PlanarPose, Policy};
use herb_core::features::{CANDIDATE_LEN, CONTEXT_LEN, CandidateLayout, DecisionFeatures};
use herb_core::lattice::{Lattice, MAX_CANDIDATES, Placement};
use herb_core::{Catalog, Heightmap, TypeIdx};
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tract_onnx::prelude::*;

/// The input names of the candidate contract, in order.
pub const INPUT_NAMES: [&str; 3] = [
    CandidateLayout::CONTEXT_NAME,
    CandidateLayout::CANDIDATES_NAME,
    CandidateLayout::MASK_NAME,
];

fn input_shapes() -> [Vec<usize>; 3] {
    [
        vec![1, CONTEXT_LEN],
        vec![1, MAX_CANDIDATES, CANDIDATE_LEN],
        vec![1, MAX_CANDIDATES],
    ]
}

/// A loaded candidate policy with its lattice and input buffers.
pub struct CandidatePolicy {
    path: PathBuf,
    state: TypedSimpleState,
    inputs: [Arc<Tensor>; 3],
    lattice: Lattice,
    feats: DecisionFeatures,
    logits: Vec<f32>,
    fma: i64,
    bytes: usize,
}

impl std::fmt::Debug for CandidatePolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("CandidatePolicy")
            .field("path", &self.path)
            .field("fma", &self.fma)
            .finish()
    }
}

fn model_err(path: &Path, message: impl std::fmt::Display) -> DecideError {
    DecideError::Model {
        path: path.to_owned(),
        message: message.to_string(),
    }
}

impl CandidatePolicy {
    /// Loads, checks and optimises the model at `path`; the lattice is sized for `catalog`.
    pub fn load(path: &Path, catalog: &Catalog) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|source| DecideError::Io {
            path: path.to_owned(),
            source,
        })?;
        Self::from_bytes(path, &bytes, catalog)
    }

    /// As [`CandidatePolicy::load`] from the file's bytes (`path` names it in errors).
    pub fn from_bytes(path: &Path, bytes: &[u8], catalog: &Catalog) -> Result<Self> {
        let loaded = std::panic::catch_unwind(|| plan(bytes));
        let (state, fma) = match loaded {
            Ok(r) => r.map_err(|e| model_err(path, e))?,
            Err(_) => return Err(model_err(path, "the ONNX parser failed on this file")),
        };
        let shapes = input_shapes();
        let mk = |s: &[usize]| Tensor::zero::<f32>(s).map(Arc::new);
        let inputs = [mk(&shapes[0]), mk(&shapes[1]), mk(&shapes[2])];
        let [a, b, c] = inputs;
        Ok(Self {
            path: path.to_owned(),
            state,
            inputs: [
                a.map_err(|e| model_err(path, e))?,
                b.map_err(|e| model_err(path, e))?,
                c.map_err(|e| model_err(path, e))?,
            ],
            lattice: Lattice::new(catalog),
            feats: DecisionFeatures::default(),
            logits: Vec::with_capacity(MAX_CANDIDATES),
            fma,
            bytes: bytes.len(),
        })
    }

    /// Multiply-accumulates per decision, from tract's cost model (-1 if unknown).
    pub fn fma(&self) -> i64 {
        self.fma
    }

    /// Size of the ONNX file (bytes).
    pub fn file_bytes(&self) -> usize {
        self.bytes
    }

    /// The candidate placement for `next` over `hm`, with `after` the objects still to come:
    /// the lattice, the features, the network, the masked argmax.
    pub fn choose(
        &mut self,
        catalog: &Catalog,
        hm: &Heightmap,
        next: TypeIdx,
        after: &[TypeIdx],
    ) -> Result<Placement> {
        let n = self
            .feats
            .compute(&mut self.lattice, catalog, hm, next, after);
        if n == 0 {
            return Err(DecideError::NoFeasiblePlacement);
        }
        self.infer()?;
        let best = self.logits[..n]
            .iter()
            .enumerate()
            .filter(|(_, v)| v.is_finite())
            .max_by(|a, b| a.1.total_cmp(b.1))
            .map(|(i, _)| i)
            .ok_or_else(|| model_err(&self.path, "no finite logit for any candidate"))?;
        Ok(self.feats.placements[best])
    }

    /// The network's logits for explicit inputs (the contract's layouts; for parity tests and
    /// tools). Errors name a wrong input length.
    pub fn logits(&mut self, context: &[f32], candidates: &[f32], mask: &[f32]) -> Result<&[f32]> {
        let want = [CONTEXT_LEN, MAX_CANDIDATES * CANDIDATE_LEN, MAX_CANDIDATES];
        for ((name, have), want) in INPUT_NAMES
            .iter()
            .zip([context.len(), candidates.len(), mask.len()])
            .zip(want)
        {
            if have != want {
                return Err(model_err(
                    &self.path,
                    format!("input {name:?} of {have} values, expected {want}"),
                ));
            }
        }
        self.feats.context.copy_from_slice(context);
        self.feats.candidates.copy_from_slice(candidates);
        self.feats.mask.copy_from_slice(mask);
        self.infer()?;
        Ok(&self.logits)
    }

    /// Runs the network on the current features into `logits` (unchecked values).
    fn infer(&mut self) -> Result<()> {
        let srcs: [&[f32]; 3] = [
            &self.feats.context,
            &self.feats.candidates,
            &self.feats.mask,
        ];
        for (t, src) in self.inputs.iter_mut().zip(srcs) {
            Arc::make_mut(t)
                .try_as_plain_ram_mut()
                .and_then(|mut v| {
                    v.as_slice_mut::<f32>()?.copy_from_slice(src);
                    Ok(())
                })
                .map_err(|e| model_err(&self.path, format!("input: {e:#}")))?;
        }
        let logits = &mut self.logits;
        self.state
            .run(
                self.inputs
                    .iter()
                    .map(|t| t.clone().into_tvalue())
                    .collect(),
            )
            .and_then(|out| {
                let first = out.first().ok_or_else(|| {
                    tract_onnx::tract_core::internal::anyhow!("the model returned no output")
                })?;
                let view = first.try_as_plain_ram()?;
                logits.clear();
                logits.extend_from_slice(view.as_slice::<f32>()?);
                Ok(())
            })
            .map_err(|e| model_err(&self.path, format!("inference failed: {e:#}")))?;
        if self.logits.len() != MAX_CANDIDATES {
            return Err(model_err(
                &self.path,
                format!("{} logits, expected {MAX_CANDIDATES}", self.logits.len()),
            ));
        }
        Ok(())
    }
}

/// Reads, checks and optimises a candidate model.
fn plan(bytes: &[u8]) -> std::result::Result<(TypedSimpleState, i64), String> {
    let raw = tract_onnx::onnx()
        .model_for_read(&mut &bytes[..])
        .map_err(|e| format!("not a readable ONNX model: {e:#}"))?;
    check_contract(&raw)?;
    crate::onnx::runnable(raw)
}

/// The input names of an ONNX model (to tell the two policy contracts apart).
pub fn input_names(bytes: &[u8]) -> std::result::Result<Vec<String>, ModelReadError> {
    let raw = std::panic::catch_unwind(|| tract_onnx::onnx().model_for_read(&mut &bytes[..]))
        .map_err(|_| ModelReadError::ParserFailed)?
        .map_err(ModelReadError::Unreadable)?;
    let ins = raw.input_outlets().map_err(ModelReadError::Inputs)?;
    Ok(ins.iter().map(|o| raw.node(o.node).name.clone()).collect())
}

/// Checks a model against the candidate contract.
fn check_contract(raw: &InferenceModel) -> std::result::Result<(), String> {
    let ins = raw.input_outlets().map_err(|e| e.to_string())?;
    let names: Vec<&str> = ins.iter().map(|o| raw.node(o.node).name.as_str()).collect();
    if names != INPUT_NAMES {
        return Err(format!("inputs {names:?}, expected {INPUT_NAMES:?}"));
    }
    for (i, want) in input_shapes().iter().enumerate() {
        let f = raw.input_fact(i).map_err(|e| e.to_string())?;
        if f.datum_type() != Some(DatumType::F32) {
            return Err(format!(
                "input {:?} of type {:?}, expected f32",
                INPUT_NAMES[i],
                f.datum_type()
            ));
        }
        let shape = f.shape.as_concrete_finite().map_err(|e| e.to_string())?;
        if shape.as_deref() != Some(&want[..]) {
            return Err(format!(
                "input {:?} of shape {shape:?}, expected {want:?}",
                INPUT_NAMES[i]
            ));
        }
    }
    let outs = raw.output_outlets().map_err(|e| e.to_string())?;
    if outs.len() != 1 || raw.outlet_label(outs[0]) != Some(CandidateLayout::OUTPUT_NAME) {
        return Err(format!(
            "outputs {:?}, expected one named {:?}",
            outs.iter()
                .map(|o| raw.outlet_label(*o))
                .collect::<Vec<_>>(),
            CandidateLayout::OUTPUT_NAME
        ));
    }
    let typed = raw
        .clone()
        .into_typed()
        .map_err(|e| format!("cannot type the model: {e:#}"))?;
    let of = typed.output_fact(0).map_err(|e| e.to_string())?;
    if of.datum_type != DatumType::F32 || of.shape.as_concrete() != Some(&[1, MAX_CANDIDATES][..]) {
        return Err(format!(
            "output {:?} {:?}, expected f32 [1, {MAX_CANDIDATES}]",
            of.datum_type, of.shape
        ));
    }
    Ok(())
}

impl Policy for CandidatePolicy {
    fn name(&self) -> &str {
        "candidates"
    }
    fn fork(&self) -> Option<Box<dyn Policy + Send>> {
        Some(Box::new(Self {
            path: self.path.clone(),
            // A clone of tract's state is a new session of the same optimised plan.
            state: self.state.clone(),
            inputs: self.inputs.each_ref().map(|t| Arc::new((**t).clone())),
            lattice: self.lattice.clone(),
            feats: self.feats.clone(),
            logits: Vec::with_capacity(MAX_CANDIDATES),
            fma: self.fma,
            bytes: self.bytes,
        }))
    }
    fn begin_episode(&mut self, _seed: u64) {}
    fn needs_observation(&self) -> bool {
        false
    }
    fn decide(&mut self, input: &DecisionInput) -> Result<PlanarPose> {
        let p = self.choose(input.catalog, input.heightmap, input.object, input.after())?;
        Ok(p.into())
    }
}
