//! The ONNX placement policy, run by tract on the calling thread.
//!
//! Loading reads the file, checks it against the model I/O contract written down with the
//! observation layout (`herb_core::observation`, "Policy model I/O contract": one input `obs`
//! `f32 [1, 2, 224, 224]`, one output `action` `f32 [1, 3]`), optimises it once and makes a
//! runnable state. A file that is missing, truncated, not ONNX or of another shape is a
//! [`DecideError::Model`] naming the file and what differs; tract panics while parsing a
//! corrupt file are caught and reported the same way.
//!
//! Per decision: the observation is copied into the one input tensor allocated at load
//! (no copy of the tensor itself: tract releases it after each run), the plan runs, and the
//! action is checked (finite, within `[-1, 1]`) before it leaves. tract allocates its own
//! intermediate tensors inside a run (its 0.23 API has no arena); the rest of the decision
//! does not allocate.

use crate::error::{DecideError, Result};
use crate::policy::{DecisionInput, PlanarPose, Policy, check_action, check_input};
use herb_core::ObsLayout;
use std::path::{Path, PathBuf};
use std::sync::Arc;
use tract_onnx::prelude::*;

/// A loaded, optimised policy network.
pub struct OnnxPolicy {
    path: PathBuf,
    state: TypedSimpleState,
    input: Arc<Tensor>,
    fma: i64,
    bytes: usize,
}

impl std::fmt::Debug for OnnxPolicy {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        f.debug_struct("OnnxPolicy")
            .field("path", &self.path)
            .field("fma", &self.fma)
            .field("bytes", &self.bytes)
            .finish()
    }
}

fn model_err(path: &Path, message: impl std::fmt::Display) -> DecideError {
    DecideError::Model {
        path: path.to_owned(),
        message: message.to_string(),
    }
}

impl OnnxPolicy {
    /// Loads, checks and optimises the model at `path`.
    pub fn load(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|source| DecideError::Io {
            path: path.to_owned(),
            source,
        })?;
        // tract may panic on some corrupt graphs (e.g. an output naming no tensor): report it.
        let loaded = std::panic::catch_unwind(|| Self::from_bytes(&bytes));
        let (state, fma) = match loaded {
            Ok(r) => r.map_err(|e| model_err(path, e))?,
            Err(_) => return Err(model_err(path, "the ONNX parser failed on this file")),
        };
        let input =
            Arc::new(Tensor::zero::<f32>(&ObsLayout::INPUT_SHAPE).map_err(|e| model_err(path, e))?);
        Ok(Self {
            path: path.to_owned(),
            state,
            input,
            fma,
            bytes: bytes.len(),
        })
    }

    fn from_bytes(bytes: &[u8]) -> std::result::Result<(TypedSimpleState, i64), String> {
        let raw = tract_onnx::onnx()
            .model_for_read(&mut &bytes[..])
            .map_err(|e| format!("not a readable ONNX model: {e:#}"))?;
        check_contract(&raw)?;
        runnable(raw)
    }

    /// Multiply-accumulates per decision, from tract's cost model (-1 if unknown).
    pub fn fma(&self) -> i64 {
        self.fma
    }

    /// Size of the ONNX file (bytes).
    pub fn file_bytes(&self) -> usize {
        self.bytes
    }

    /// Runs the network on an observation (length `ObsLayout::LEN`), unchecked output.
    /// Allocates nothing itself (errors aside); tract allocates its intermediate tensors.
    pub fn infer(&mut self, observation: &[f32]) -> Result<[f32; 3]> {
        if observation.len() != ObsLayout::LEN {
            return Err(model_err(
                &self.path,
                format!("observation of {} values", observation.len()),
            ));
        }
        let filled = Arc::make_mut(&mut self.input)
            .try_as_plain_ram_mut()
            .and_then(|mut v| {
                v.as_slice_mut::<f32>()?.copy_from_slice(observation);
                Ok(())
            });
        let out = filled.and_then(|()| self.state.run(tvec!(self.input.clone().into_tvalue())));
        let action = out.and_then(|out| {
            let first = out.first().ok_or_else(|| {
                tract_onnx::tract_core::internal::anyhow!("the model returned no output")
            })?;
            let view = first.try_as_plain_ram()?;
            let s = view.as_slice::<f32>()?;
            <[f32; 3]>::try_from(s).map_err(|_| {
                tract_onnx::tract_core::internal::anyhow!(
                    "output of {} values, expected 3",
                    s.len()
                )
            })
        });
        action.map_err(|e| model_err(&self.path, format!("inference failed: {e:#}")))
    }
}

/// Checks the model against the I/O contract (see `herb_core::observation`).
fn check_contract(raw: &InferenceModel) -> std::result::Result<(), String> {
    let ins = raw.input_outlets().map_err(|e| e.to_string())?;
    if ins.len() != 1 {
        return Err(format!(
            "{} inputs, expected 1 ({:?})",
            ins.len(),
            ObsLayout::INPUT_NAME
        ));
    }
    let name = &raw.node(ins[0].node).name;
    if name != ObsLayout::INPUT_NAME {
        return Err(format!(
            "input is named {name:?}, expected {:?}",
            ObsLayout::INPUT_NAME
        ));
    }
    let f = raw.input_fact(0).map_err(|e| e.to_string())?;
    if f.datum_type() != Some(DatumType::F32) {
        return Err(format!("input type {:?}, expected f32", f.datum_type()));
    }
    let shape = f.shape.as_concrete_finite().map_err(|e| e.to_string())?;
    if shape.as_deref() != Some(&ObsLayout::INPUT_SHAPE[..]) {
        return Err(format!(
            "input shape {shape:?}, expected {:?}",
            ObsLayout::INPUT_SHAPE
        ));
    }
    let outs = raw.output_outlets().map_err(|e| e.to_string())?;
    if outs.len() != 1 {
        return Err(format!(
            "{} outputs, expected 1 ({:?})",
            outs.len(),
            ObsLayout::OUTPUT_NAME
        ));
    }
    let label = raw.outlet_label(outs[0]);
    if label != Some(ObsLayout::OUTPUT_NAME) {
        return Err(format!(
            "output is named {label:?}, expected {:?}",
            ObsLayout::OUTPUT_NAME
        ));
    }
    // Declared output shapes are not read by tract: type the graph to learn the real one.
    let typed = raw
        .clone()
        .into_typed()
        .map_err(|e| format!("cannot type the model: {e:#}"))?;
    let of = typed.output_fact(0).map_err(|e| e.to_string())?;
    if of.datum_type != DatumType::F32 {
        return Err(format!("output type {:?}, expected f32", of.datum_type));
    }
    if of.shape.as_concrete() != Some(&ObsLayout::OUTPUT_SHAPE[..]) {
        return Err(format!(
            "output shape {:?}, expected {:?}",
            of.shape,
            ObsLayout::OUTPUT_SHAPE
        ));
    }
    Ok(())
}

/// Types, declutters and optimises a checked model into a runnable state; also returns its
/// multiply-accumulates per run (-1 if unknown). Shared by both policy contracts.
pub(crate) fn runnable(
    raw: InferenceModel,
) -> std::result::Result<(TypedSimpleState, i64), String> {
    let typed = raw
        .into_typed()
        .and_then(|m| m.into_decluttered())
        .map_err(|e| format!("cannot type the model: {e:#}"))?;
    let fma = fma_count(&typed).unwrap_or(-1);
    let plan = typed
        .into_optimized()
        .and_then(|m| m.into_runnable())
        .map_err(|e| format!("cannot optimise the model: {e:#}"))?;
    let state = plan
        .spawn()
        .map_err(|e| format!("cannot make a runnable state: {e:#}"))?;
    Ok((state, fma))
}

/// Multiply-accumulates of a (decluttered) model, from the ops' cost reports.
fn fma_count(m: &TypedModel) -> TractResult<i64> {
    use tract_onnx::tract_core::ops::Cost;
    let mut fma = 0i64;
    for node in m.nodes() {
        let inputs = m.node_input_facts(node.id)?;
        for (cost, n) in node.op.cost(&inputs)? {
            if let Cost::FMA(_) = cost {
                fma += n.to_i64()?;
            }
        }
    }
    Ok(fma)
}

impl Policy for OnnxPolicy {
    fn name(&self) -> &str {
        "onnx"
    }
    fn fork(&self) -> Option<Box<dyn Policy + Send>> {
        Some(Box::new(Self {
            path: self.path.clone(),
            // A clone of tract's state is a new session of the same optimised plan.
            state: self.state.clone(),
            input: Arc::new((*self.input).clone()),
            fma: self.fma,
            bytes: self.bytes,
        }))
    }
    fn begin_episode(&mut self, _seed: u64) {}
    /// The network's action, checked and decoded once into the box
    /// (`herb_core::observation::action_to_placement`).
    fn decide(&mut self, input: &DecisionInput) -> Result<PlanarPose> {
        check_input("onnx", input)?;
        let a = check_action("onnx", self.infer(input.observation)?)?;
        let (x, y, theta) = herb_core::observation::action_to_placement(a)?;
        Ok(PlanarPose { x, y, theta })
    }
}
