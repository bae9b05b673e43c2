//! How early each object order puts the large objects, over the 263 BoxED episodes (a
//! diagnostic, `docs/research-log.md`): per episode, the rank correlation between an
//! object's position and its volume (1: largest first, -1: smallest first, 0: no relation) and
//! the share of the episode's volume in its first third, averaged over the episodes.
//!
//! `cargo run --release -p herb-decide --example order_sizes` (from the repo root; BoxED at
//! `../shared/boxed` or `HERB_BOXED`).
use herb_core::Catalog;
use herb_decide::order::Order;
use herb_decide::sequence::SequenceModel;
use std::path::Path;

/// Spearman's rank correlation between position and volume rank (equal volumes ranked by
/// position): 1 when the volumes fall along the sequence.
fn spearman(vols: &[f32]) -> f64 {
    let n = vols.len();
    let mut idx: Vec<usize> = (0..n).collect();
    idx.sort_by(|&a, &b| vols[b].total_cmp(&vols[a]).then(a.cmp(&b)));
    let mut rank = vec![0.0; n];
    for (r, &i) in idx.iter().enumerate() {
        rank[i] = r as f64;
    }
    let m = (n as f64 - 1.0) / 2.0;
    let (mut sxy, mut sxx) = (0.0, 0.0);
    for (i, &r) in rank.iter().enumerate() {
        sxy += (i as f64 - m) * (r - m);
        sxx += (i as f64 - m) * (i as f64 - m);
    }
    if sxx == 0.0 { 0.0 } else { sxy / sxx }
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let root = herb_core::paths::boxed_root(None)
        .ok_or("BoxED not found: set HERB_BOXED or put it at ../shared/boxed")?;
    let meshes = herb_core::paths::mesh_source(None, Some(&root));
    let catalog = Catalog::builtin(&meshes)?;
    let model = SequenceModel::load(Path::new("models/sequence.json"), &catalog)?;
    let (sessions, _) = herb_core::boxed::load_all(&root, &catalog)?;
    for o in Order::ALL {
        let (mut rho, mut firstvol, mut n) = (0.0, 0.0, 0.0);
        for s in &sessions {
            let ep = s.episode(&catalog);
            let seq = o.order(&catalog, Some(&model), &ep.objects, 0)?;
            let vols: Vec<f32> = seq.iter().map(|&t| catalog.shape(t).volume).collect();
            rho += spearman(&vols);
            let k = vols.len().div_ceil(3);
            let total: f32 = vols.iter().sum();
            firstvol += (vols[..k].iter().sum::<f32>() / total) as f64;
            n += 1.0;
        }
        println!(
            "{o}: mean rank correlation of size with earliness {:.3}, volume share of the first third {:.3}",
            rho / n,
            firstvol / n
        );
    }
    Ok(())
}
