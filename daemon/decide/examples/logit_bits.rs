//! Prints a candidate policy's logits on its parity samples as raw bits, one line per sample,
//! to compare tract's kernels (e.g. `TRACT_CPU_ISA=-avx512f`) or machines bit for bit:
//! `cargo run --release -p herb-decide --example logit_bits -- models/policy-cs06.onnx`.

use herb_core::features::{CANDIDATE_LEN, CONTEXT_LEN};
use herb_core::lattice::MAX_CANDIDATES;
use herb_decide::CandidatePolicy;
use std::path::PathBuf;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let onnx = PathBuf::from(
        std::env::args()
            .nth(1)
            .ok_or("usage: logit_bits <policy.onnx>")?,
    );
    let bytes = std::fs::read(onnx.with_extension("parity.bin"))?;
    let data: Vec<f32> = bytes
        .chunks_exact(4)
        .map(|b| f32::from_le_bytes([b[0], b[1], b[2], b[3]]))
        .collect();
    let catalog = herb_core::Catalog::builtin(&herb_core::paths::MeshSource::None("bits".into()))?;
    let mut p = CandidatePolicy::load(&onnx, &catalog)?;
    let per = CONTEXT_LEN + MAX_CANDIDATES * CANDIDATE_LEN + MAX_CANDIDATES;
    for x in data.chunks_exact(per) {
        let (ctx, rest) = x.split_at(CONTEXT_LEN);
        let (cand, mask) = rest.split_at(MAX_CANDIDATES * CANDIDATE_LEN);
        let line: Vec<String> = p
            .logits(ctx, cand, mask)?
            .iter()
            .zip(mask)
            .filter(|(_, m)| **m > 0.0)
            .map(|(l, _)| format!("{:08x}", l.to_bits()))
            .collect();
        println!("{}", line.join(" "));
    }
    Ok(())
}
