//! The names of methods, orders and policies: one spelling each, parsed back to the same value,
//! and unknown names refused with the list of known ones.

use herb_decide::{Order, PolicySpec, Shipped};
use herb_methods::Method;
use std::path::Path;

#[test]
fn every_method_and_order_parses_back_from_its_name() {
    for m in Method::ALL {
        assert_eq!(m.name().parse::<Method>(), Ok(m));
        assert_eq!(m.to_string(), m.name());
    }
    for o in Order::ALL {
        assert_eq!(o.name().parse::<Order>(), Ok(o));
    }
    let e = "blfb".parse::<Method>().unwrap_err().to_string();
    assert!(e.contains("blfb") && e.contains("lattice-reserve"), "{e}");
    let e = "biggest".parse::<Order>().unwrap_err().to_string();
    assert!(e.contains("largest"), "{e}");
    // The text users read, kept as it was when the error was a String.
    assert_eq!(
        e,
        r#"order "biggest": expected one of beam3, beam3-last, human, largest, random"#
    );
}

#[test]
fn replays_keep_the_human_order_and_the_others_default_as_documented() {
    for m in Method::ALL {
        let expected = match m {
            Method::Human | Method::HumanPose | Method::Random | Method::HumanRecorded => None,
            Method::Blbf | Method::LatticeBlbf | Method::PackitSo3 => Some(Order::Largest),
            Method::BcMse | Method::BcMdn => Some(Order::Human),
            _ => Some(Order::Beam3),
        };
        assert_eq!(m.order(None), expected, "{m}");
        assert_eq!(m.replay().is_some(), expected.is_none(), "{m}");
        if expected.is_some() {
            assert_eq!(m.order(Some(Order::Random)), Some(Order::Random));
        }
    }
}

#[test]
fn policies_are_blbf_or_a_model_path() {
    assert_eq!("blbf".parse(), Ok(PolicySpec::Blbf));
    assert_eq!(
        "models/policy-cs06.onnx".parse(),
        Ok(PolicySpec::Onnx("models/policy-cs06.onnx".into()))
    );
    assert!(
        "".parse::<PolicySpec>()
            .unwrap_err()
            .to_string()
            .contains("empty")
    );
    for s in ["blbf", "cs06", "cs09", "a/b.onnx"] {
        assert_eq!(s.parse::<PolicySpec>().unwrap().to_string(), s);
    }
}

#[test]
fn shipped_policies_are_named_and_found_in_the_models_folder() {
    assert_eq!("cs06".parse(), Ok(PolicySpec::Shipped(Shipped::Cs06)));
    assert_eq!("cs09".parse(), Ok(PolicySpec::Shipped(Shipped::Cs09)));
    let dir = Path::new("/opt/herb/models");
    assert_eq!(
        PolicySpec::Shipped(Shipped::Cs06).resolved(dir),
        PolicySpec::Onnx(dir.join("policy-cs06.onnx"))
    );
    assert_eq!(PolicySpec::Blbf.resolved(dir), PolicySpec::Blbf);
    // Every shipped name is a file of the repository's models folder.
    let models = Path::new(env!("CARGO_MANIFEST_DIR")).join("../../models");
    for s in Shipped::ALL {
        assert!(models.join(s.file_name()).is_file(), "{}", s.file_name());
    }
}

#[test]
fn the_old_name_of_herbs_order_is_an_alias() {
    assert_eq!("beam3-start".parse::<Order>(), Ok(Order::Beam3));
    assert_eq!("beam3".parse::<Order>(), Ok(Order::HERB));
    assert_eq!("beam3-last".parse::<Order>(), Ok(Order::Beam3Last));
}

#[test]
fn herb_orders_with_beam3_as_algorithm_1_writes_it() {
    // HERB's Beam-3 is Algorithm 1 read literally: every search starts from <start>.
    assert_eq!(Order::HERB, Order::Beam3);
    assert_eq!(Method::Herb.order(None), Some(Order::HERB));
}
