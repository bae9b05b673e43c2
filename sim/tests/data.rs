//! Tests on the BoxED data and the catalog: dimensions against the data README, loader counts,
//! human placements. They need ../shared/boxed and fail loudly under CI=true without it.

mod common;

use herb_sim::boxed;
use herb_sim::paths;

/// Rows of the catalog table in ../shared/boxed/README.md: id -> (extents cm, height cm).
fn readme_table(root: &std::path::Path) -> Vec<(String, [f32; 3], f32)> {
    let text = std::fs::read_to_string(root.join("README.md")).expect("boxed README");
    let mut rows = Vec::new();
    for line in text.lines() {
        let cells: Vec<&str> = line.split('|').map(str::trim).collect();
        // | id | name | mesh | V / F | extents x, y, z (cm) | up | height (cm) |
        if cells.len() < 8 || cells[1].len() != 3 || !cells[1].chars().all(|c| c.is_ascii_digit()) {
            continue;
        }
        let nums: Vec<f32> = cells[5]
            .split_whitespace()
            .filter_map(|t| t.parse().ok())
            .collect();
        let height: f32 = cells[7]
            .trim_start_matches("est. ")
            .parse()
            .expect("height");
        if nums.len() == 3 {
            rows.push((cells[1].to_owned(), [nums[0], nums[1], nums[2]], height));
        }
    }
    rows
}

#[test]
fn catalog_dimensions_match_the_data_readme() {
    let Some(root) = paths::boxed_root_for_tests() else {
        return;
    };
    let c = common::primitives();
    let rows = readme_table(&root);
    assert_eq!(rows.len(), 24, "the README lists 24 object types");
    for (id, ext, height) in rows {
        let t = c
            .by_id(&id)
            .unwrap_or_else(|_| panic!("catalog lacks {id}"));
        let d = c.spec(t).dims_m.map(|v| v * 100.0);
        // Height along the resting up axis. The toothpaste tube's fitted resting face is 9
        // degrees off the README's nominal axis (it lies on its crimped end), so it stands 6 mm
        // taller; known, see the catalog notes.
        let tol = if id == "103" { 0.7 } else { 0.35 };
        assert!(
            (d[2] - height).abs() <= tol,
            "{id}: height {} cm, README {height} cm",
            d[2]
        );
        // The canonical footprint is the smallest rectangle: no larger than the README's
        // mesh-axis footprint, and with the same larger side when the object is axis-aligned.
        let mut readme_sorted = ext;
        readme_sorted.sort_by(f32::total_cmp);
        assert!(
            d[0] >= d[1] - 0.05,
            "{id}: long side along x (round ones within 0.5 mm)"
        );
        assert!(
            d[0] * d[1] <= readme_sorted[1] * readme_sorted[2] * 1.03 + 1.0,
            "{id}: footprint {d:?} vs README {ext:?}"
        );
        // Volume of the bounding box within 25% of the README's. The 008 box and the curved 011
        // banana lie turned in their files, so their mesh-axis extents are inflated; the
        // footprint rule above covers them.
        if id != "008" && id != "011" {
            let (a, b) = (d[0] * d[1] * d[2], ext[0] * ext[1] * ext[2]);
            assert!((a / b - 1.0).abs() < 0.25, "{id}: box volume {a} vs {b}");
        }
    }
}

#[test]
fn mesh_hulls_agree_with_catalog_dimensions() {
    let Some(mc) = common::meshes() else { return };
    let pc = common::primitives();
    for t in mc.types() {
        let (m, p) = (mc.shape(t).extents(), pc.shape(t).extents());
        let d = mc.spec(t).dims_m;
        let id = &mc.spec(t).id;
        for k in 0..3 {
            // Hull extents lose at most a few mm to the support-point reduction and face nudging.
            assert!(
                (m[k] - d[k]).abs() < 0.004,
                "{id}: mesh hull extent {k} = {} vs catalog {}",
                m[k],
                d[k]
            );
            assert!(
                (p[k] - d[k]).abs() < 0.002,
                "{id}: primitive extent {k} = {} vs catalog {}",
                p[k],
                d[k]
            );
        }
        // Canonical origin at the bounding-box centre.
        let centre = (mc.shape(t).aabb_min + mc.shape(t).aabb_max) * 0.5;
        assert!(centre.length() < 0.004, "{id}: hull centre {centre:?}");
    }
}

#[test]
fn loader_counts_sessions_and_records() {
    let Some(root) = paths::boxed_root_for_tests() else {
        return;
    };
    let c = common::primitives();
    let (sessions, bad) = boxed::load_all(&root, &c).expect("sessions folder");
    assert!(bad.is_empty(), "bad sessions: {bad:?}");
    assert_eq!(sessions.len(), 263);
    let records: usize = sessions.iter().map(|s| s.records.len()).sum();
    assert_eq!(records, 4660, "PickPlace records");
    // The papers' 4644: re-grasps moving an object less than 2 cm are adjustments (16 of 84,
    // with a clear gap between 14.2 and 20.6 mm).
    let moves: Vec<f32> = sessions
        .iter()
        .flat_map(|s| s.regrasp_moves())
        .map(|(_, d)| d)
        .collect();
    assert_eq!(moves.len(), 84, "re-grasps");
    let short = moves
        .iter()
        .filter(|&&d| d < boxed::ADJUSTMENT_MAX_M)
        .count();
    assert_eq!(short, 16);
    let below = moves
        .iter()
        .copied()
        .filter(|&d| d < 0.02)
        .fold(0.0, f32::max);
    let above = moves
        .iter()
        .copied()
        .filter(|&d| d >= 0.02)
        .fold(1.0, f32::min);
    assert!(below < 0.015 && above > 0.020, "gap {below} .. {above}");
    let paper: usize = sessions.iter().map(|s| s.paper_placement_count()).sum();
    assert_eq!(paper, 4644, "placements as the papers count them");
    let episodes: Vec<_> = sessions.iter().map(|s| s.episode(&c)).collect();
    let placed: usize = episodes.iter().map(|e| e.objects.len()).sum();
    assert_eq!(placed, 4576, "distinct placed instances");
    let (mean, std) = herb_sim::eval::mean_std(episodes.iter().map(|e| e.objects.len() as f64));
    assert!(
        (mean - 17.40).abs() < 0.005 && (std - 3.63).abs() < 0.005,
        "{mean} ({std}) vs the paper's 17.40 (3.63)"
    );
}

#[test]
fn human_placements_lie_inside_the_box() {
    let Some(root) = paths::boxed_root_for_tests() else {
        return;
    };
    let c = common::primitives();
    let (sessions, _) = boxed::load_all(&root, &c).unwrap();
    let mut inside = 0;
    let mut n = 0;
    for s in &sessions {
        for h in s.episode(&c).human {
            n += 1;
            if h.x.abs() < herb_sim::frames::BOX_HALF_X
                && h.y.abs() < herb_sim::frames::BOX_HALF_Y
                && h.z > -0.01
                && h.z < 0.3
            {
                inside += 1;
            }
        }
    }
    // Object centres of the human placements fall inside the box (a few were thrown out).
    assert!(inside as f64 > 0.98 * n as f64, "{inside} of {n}");
}

#[test]
fn a_malformed_or_missing_session_is_a_clear_error() {
    let c = common::primitives();
    let dir = std::env::temp_dir().join(format!("herb-bad-sessions-{}", std::process::id()));
    let s = dir.join("sessions");
    std::fs::create_dir_all(s.join("p1_s1")).unwrap();
    std::fs::create_dir_all(s.join("p2_s1")).unwrap();
    std::fs::create_dir_all(s.join("p3_s1")).unwrap();
    std::fs::write(s.join("p1_s1/PickPlace_dataset.json"), "[{\"id\": 3").unwrap();
    std::fs::write(
        s.join("p3_s1/PickPlace_dataset.json"),
        r#"[{"id":"999 unicorn(Clone)-1","pickRotation":[[1,0,0],[0,1,0],[0,0,1]],"pickTranslation":[0,0,0],"placeRotation":[[1,0,0],[0,1,0],[0,0,1]],"placeTranslation":[0,0,0]}]"#,
    )
    .unwrap();
    let (ok, bad) = boxed::load_all(&dir, &c).unwrap();
    assert!(ok.is_empty());
    let msgs: Vec<String> = bad.iter().map(|e| e.to_string()).collect();
    assert_eq!(msgs.len(), 3, "{msgs:?}");
    assert!(
        msgs[0].contains("p1_s1") && msgs[0].contains("malformed"),
        "{}",
        msgs[0]
    );
    assert!(
        msgs[1].contains("p2_s1") && msgs[1].contains("cannot read"),
        "{}",
        msgs[1]
    );
    assert!(
        msgs[2].contains("p3_s1") && msgs[2].contains("unknown object type"),
        "{}",
        msgs[2]
    );
    std::fs::remove_dir_all(&dir).ok();
}
