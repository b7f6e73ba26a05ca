//! MEKF robustness: arbitrary (including non-finite and absurd) inputs never panic, never
//! corrupt the state, and the covariance stays symmetric positive definite.

use fsw_core::attitude::Quat;
use fsw_core::mekf::Mekf;
use fsw_core::tables::FilterTable;
use nalgebra::{Matrix3, Vector3};
use proptest::prelude::*;

fn any_f64() -> impl Strategy<Value = f64> {
    prop_oneof![
        4 => -1.0f64..1.0,
        1 => prop::num::f64::ANY,
        1 => Just(f64::NAN),
        1 => Just(f64::INFINITY),
        1 => Just(0.0),
        1 => -1e-7f64..1e-7,
    ]
}

fn vec3() -> impl Strategy<Value = Vector3<f64>> {
    (any_f64(), any_f64(), any_f64()).prop_map(|(x, y, z)| Vector3::new(x, y, z))
}

#[derive(Debug, Clone)]
enum Op {
    Propagate(Vector3<f64>, f64),
    Vector(Vector3<f64>, Vector3<f64>, f64, f64),
    Focal(f64, f64, Vector3<f64>, f64, f64),
    Triad(Vector3<f64>, Vector3<f64>, Vector3<f64>, Vector3<f64>),
}

fn op() -> impl Strategy<Value = Op> {
    prop_oneof![
        (vec3(), any_f64()).prop_map(|(d, t)| Op::Propagate(d * 1e-3, t.abs() * 2.0)),
        (vec3(), vec3(), any_f64(), any_f64()).prop_map(|(z, r, s, g)| Op::Vector(
            z,
            r,
            s.abs() * 1e-3,
            g.abs() * 20.0
        )),
        (any_f64(), any_f64(), vec3(), any_f64(), any_f64()).prop_map(|(h, v, r, s, g)| Op::Focal(
            h * 0.07,
            v * 0.07,
            r,
            s.abs() * 1e-4,
            g.abs() * 20.0
        )),
        (vec3(), vec3(), vec3(), vec3()).prop_map(|(a, b, c, d)| Op::Triad(a, b, c, d)),
    ]
}

fn check(f: &Mekf) -> Result<(), TestCaseError> {
    let p = f.covariance;
    prop_assert!(p.iter().all(|x| x.is_finite()));
    prop_assert!((p - p.transpose()).abs().max() <= 1e-12 * p.abs().max());
    prop_assert!(p.cholesky().is_some(), "P not positive definite: {p}");
    prop_assert!(f.q_acs_from_eci.is_finite());
    prop_assert!((f.q_acs_from_eci.norm() - 1.0).abs() < 1e-12);
    prop_assert!(f.bias_rad_per_s.iter().all(|x| x.is_finite()));
    Ok(())
}

proptest! {
    #![proptest_config(ProptestConfig::with_cases(300))]

    #[test]
    fn arbitrary_operation_sequences_keep_the_state_sane(ops in prop::collection::vec(op(), 1..60)) {
        let t = FilterTable::default_boot();
        let mut f = Mekf::new();
        f.initialize(&Quat::from_rotation_vector(&Vector3::new(0.1, 0.2, 0.3)), &t).unwrap();
        let m = Matrix3::new(0.0, 0.0, 1.0, 0.0, 1.0, 0.0, -1.0, 0.0, 0.0);
        for o in ops {
            let before = f;
            match o {
                Op::Propagate(d, dt) => {
                    if f.propagate(&d, dt, &t).is_err() {
                        prop_assert_eq!(f, before);
                    }
                }
                Op::Vector(z, r, s, g) => {
                    let out = f.update_vector(&z, &r, s, g);
                    if !out.accepted {
                        prop_assert_eq!(f.q_acs_from_eci, before.q_acs_from_eci);
                        prop_assert_eq!(f.covariance, before.covariance);
                    }
                }
                Op::Focal(h, v, r, s, g) => {
                    let out = f.update_focal_plane(h, v, &r, &m, s, g);
                    if !out.accepted {
                        prop_assert_eq!(f.covariance, before.covariance);
                    }
                }
                Op::Triad(a, b, c, d) => {
                    if f.initialize_from_two_vectors(&a, &b, &c, &d, &t).is_err() {
                        prop_assert_eq!(f, before);
                    }
                }
            }
            check(&f)?;
        }
    }
}
