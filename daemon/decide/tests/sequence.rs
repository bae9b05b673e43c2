//! Beam-3 (HERB paper, Algorithm 1) on hand-built chains, and the fitted model.

use herb_decide::sequence::{self, SequenceModel, State, beam3, beam3_last, greedy};
use herb_sim::paths::MeshSource;
use herb_sim::{Catalog, TypeIdx};

fn catalog() -> Catalog {
    Catalog::builtin(&MeshSource::None("test".into())).expect("catalog")
}

/// A chain over the catalog where only the listed entries are non-zero.
fn chain(
    c: &Catalog,
    start: &[(TypeIdx, f64)],
    trans: &[(TypeIdx, TypeIdx, f64)],
) -> SequenceModel {
    let n = c.len();
    let mut s = vec![0.0; n];
    let mut t = vec![vec![0.0; n]; n];
    for &(a, p) in start {
        s[a.0 as usize] = p;
    }
    for &(a, b, p) in trans {
        t[a.0 as usize][b.0 as usize] = p;
    }
    SequenceModel::from_probabilities(c, &s, &t).expect("hand-built chain")
}

fn abc(c: &Catalog) -> (TypeIdx, TypeIdx, TypeIdx) {
    (
        c.by_id("003").unwrap(),
        c.by_id("004").unwrap(),
        c.by_id("005").unwrap(),
    )
}

/// The worked example, by hand. start: A 0.6, B 0.4. A->B 0.1, A->C 0.5, B->A 0.9, B->C 0.1,
/// C->A 0.3, C->B 0.2. Objects {A, B, C}.
///
/// First search (from start): round 1 [A .6, B .4]; round 2 [BA .36, AC .30, AB .06, BC .04];
/// round 3 [BAC .18, ACB .06, BCA .012, ABC .006] -> first object B (greedy takes A, .6).
/// Second search (from B, {A, C} left): [A .9, C .1] -> [AC .45, CA .03] -> A.
/// Last: C. Beam-3 gives B A C; greedy gives A C B.
#[test]
fn algorithm_1_worked_example_beats_greedy() {
    let c = catalog();
    let (a, b, cc) = abc(&c);
    let m = chain(
        &c,
        &[(a, 0.6), (b, 0.4)],
        &[
            (a, b, 0.1),
            (a, cc, 0.5),
            (b, a, 0.9),
            (b, cc, 0.1),
            (cc, a, 0.3),
            (cc, b, 0.2),
        ],
    );
    assert_eq!(beam3_last(&m, &[a, b, cc]).unwrap(), vec![b, a, cc]);
    assert_eq!(greedy(&m, &[a, b, cc]).unwrap(), vec![a, cc, b]);
    // The input order does not matter.
    assert_eq!(beam3_last(&m, &[cc, a, b]).unwrap(), vec![b, a, cc]);
}

/// The two readings of Algorithm 1, by hand. start: A 0.5, C 0.3, B 0.2. A->B 1, B->C 1,
/// C->A 1. Objects {A, B, C}.
///
/// First search (from start, both readings): [A .5, C .3, B .2] -> [AB .5, CA .3, BC .2] ->
/// [ABC .5, CAB .3, BCA .2] -> A.
/// Rooted at the last object (`beam3_last`), from A with {B, C} left: [B 1] -> [BC 1] -> B, then C.
/// Rooted at start (`beam3`), {B, C} left: [C .3, B .2]; C cannot go on (A is
/// used) and is carried, B goes on to BC .2 -> [C .3, BC .2]; nothing extends -> C, then B.
#[test]
fn algorithm_1_read_literally_restarts_every_search_from_start() {
    let c = catalog();
    let (a, b, cc) = abc(&c);
    let m = chain(
        &c,
        &[(a, 0.5), (cc, 0.3), (b, 0.2)],
        &[(a, b, 1.0), (b, cc, 1.0), (cc, a, 1.0)],
    );
    assert_eq!(beam3_last(&m, &[a, b, cc]).unwrap(), vec![a, b, cc]);
    assert_eq!(beam3(&m, &[a, b, cc]).unwrap(), vec![a, cc, b]);
    assert_eq!(beam3(&m, &[b, cc, a]).unwrap(), vec![a, cc, b]);
}

/// Beam width 5 prunes: a path whose prefix falls out of the top 5 is never completed, even if
/// its full probability would be the highest.
#[test]
fn the_beam_width_prunes_low_prefixes() {
    let c = catalog();
    let ids = ["002", "003", "004", "005", "006", "007", "008"];
    let t: Vec<TypeIdx> = ids.iter().map(|i| c.by_id(i).unwrap()).collect();
    // Six first objects with start 0.15 each, and a seventh (t[6]) with 0.1: outside the top 5
    // after round 1. From t[6] everything continues with probability 1; from the others with 0.1.
    let mut start: Vec<(TypeIdx, f64)> = t[..6].iter().map(|&x| (x, 0.15)).collect();
    start.push((t[6], 0.1));
    let mut trans = Vec::new();
    for &a in &t {
        for &b in &t {
            if a != b {
                trans.push((a, b, if a == t[6] { 1.0 } else { 0.1 }));
            }
        }
    }
    let m = chain(&c, &start, &trans);
    let order = beam3_last(&m, &t).unwrap();
    // Unpruned, t[6] first would win (0.1 * 1 * 0.1 = 0.01 > 0.15 * 0.1 * 0.1 = 0.0015).
    assert_ne!(order[0], t[6], "{order:?}");
    // Ties between the six equal starts go to the smallest index sequence.
    assert_eq!(order[0], t[0]);
}

#[test]
fn repeated_types_unseen_types_one_object_and_empty() {
    let c = catalog();
    let (a, b, _) = abc(&c);
    let unseen = c.by_id("103").unwrap();
    let m = chain(&c, &[(a, 1.0)], &[(a, a, 0.5), (a, b, 0.5), (b, a, 1.0)]);
    // Repeats: two A and one B. From start only A; then A->A .5 or A->B .5: beams of 3 are
    // A A B (.25 * 1... ) vs A B A (.5 * 1): A B A wins.
    assert_eq!(beam3_last(&m, &[a, b, a]).unwrap(), vec![a, b, a]);
    // A type never seen: nothing reaches it, so it comes by the fallback when nothing else is
    // reachable, here last.
    assert_eq!(beam3_last(&m, &[unseen, a]).unwrap(), vec![a, unseen]);
    // Only unseen types: the fallback order (start probability, then volume, then index).
    let big = c.by_id("003").unwrap(); // cracker box, bigger than the toothpaste
    let m0 = chain(&c, &[], &[]);
    assert_eq!(beam3_last(&m0, &[unseen, big]).unwrap(), vec![big, unseen]);
    assert_eq!(beam3_last(&m, &[b]).unwrap(), vec![b]);
    assert!(matches!(
        beam3_last(&m, &[]),
        Err(herb_decide::DecideError::EmptyObjectList)
    ));
    assert!(beam3_last(&m, &[TypeIdx(999)]).is_err());
}

#[test]
fn planning_is_deterministic_under_ties() {
    let c = catalog();
    let types: Vec<TypeIdx> = c.types().take(8).collect();
    // All transitions equal: every search is a tie, broken by index order.
    let start: Vec<_> = types.iter().map(|&t| (t, 0.125)).collect();
    let mut trans = Vec::new();
    for &x in &types {
        for &y in &types {
            trans.push((x, y, 0.125));
        }
    }
    let m = chain(&c, &start, &trans);
    let mut shuffled = types.clone();
    shuffled.reverse();
    let o1 = beam3_last(&m, &shuffled).unwrap();
    let o2 = beam3_last(&m, &types).unwrap();
    assert_eq!(o1, o2);
    assert_eq!(o1, types);
}

#[test]
fn sequence_files_round_trip_and_bad_files_are_clear_errors() {
    let c = catalog();
    let (a, b, _) = abc(&c);
    let m = SequenceModel::fit(&c, [&[a, b, a][..]], "fixture episode");
    assert_eq!(m.p(State::Start, a), 1.0);
    assert_eq!(m.p(State::After(a), b), 1.0);
    assert_eq!(m.p(State::After(b), a), 1.0);
    let text = m.to_json();
    let back = SequenceModel::from_json(&text, "round trip", &c).unwrap();
    assert_eq!(back, m);
    let unknown = text.replacen("\"003\"", "\"999\"", 1);
    let e = SequenceModel::from_json(&unknown, "t", &c)
        .unwrap_err()
        .to_string();
    assert!(e.contains("999") && e.contains("not in the catalog"), "{e}");
    let e = SequenceModel::from_json("{", "t", &c)
        .unwrap_err()
        .to_string();
    assert!(e.contains("not a sequence file"), "{e}");
    let wrong = text.replacen(sequence::FORMAT, "other", 1);
    assert!(SequenceModel::from_json(&wrong, "t", &c).is_err());
    let e = SequenceModel::load(std::path::Path::new("/nonexistent/seq.json"), &c).unwrap_err();
    assert!(e.to_string().contains("/nonexistent/seq.json"));
}

/// The committed `models/sequence.json` is what `herb-sim sequence` computes from the data,
/// and matches the transition counts of the data README.
#[test]
fn committed_sequence_model_matches_the_data() {
    let c = catalog();
    let path = std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models/sequence.json");
    let committed = SequenceModel::load(&path, &c).expect("models/sequence.json");
    assert_eq!(committed.provenance().episodes, 263);
    assert_eq!(committed.provenance().transitions, 4313);
    let Some(root) = herb_sim::paths::boxed_root_for_tests() else {
        return;
    };
    let (sessions, bad) = herb_sim::boxed::load_all(&root, &c).unwrap();
    assert!(bad.is_empty());
    let episodes: Vec<_> = sessions.iter().map(|s| s.episode(&c)).collect();
    let fitted = SequenceModel::fit(
        &c,
        episodes.iter().map(|e| &e.objects[..]),
        &committed.provenance().source,
    );
    assert_eq!(
        fitted.to_json(),
        committed.to_json(),
        "regenerate models/sequence.json"
    );
    // Data README: first placements, tomato soup -> master chef 53 of the 4313 transitions.
    let soup = c.by_id("005").unwrap();
    let chef = c.by_id("002").unwrap();
    let from_soup: f64 = c.types().map(|t| fitted.p(State::After(soup), t)).sum();
    assert!((from_soup - 1.0).abs() < 1e-9);
    assert_eq!(fitted.count(State::After(soup), chef), 53);
    // Most frequent first object: the cracker box, 112 times.
    let cracker = c.by_id("003").unwrap();
    assert_eq!(fitted.count(State::Start, cracker), 112);
}
