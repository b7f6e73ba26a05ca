//! Cross-check of the Allan deviation against `allantools` (PyPI) on the same samples.
//!
//! Reference data: `tests/data/allan_crosscheck.json`, written by
//! `scripts/allan_crosscheck.py` (its `provenance` block names the allantools, numpy and
//! scipy versions and the command): a seeded white + random-walk rate series, once as the
//! true rate and once counted in whole 0.05″ pulses (the DRIRU II quantization), and what
//! `allantools.oadev`, `allantools.edf_simple` and `allantools.confidence_interval` (scipy's χ²
//! quantiles) give on them. Re-run the script to verify or regenerate.
//!
//! Tolerances: σ to 1e-9 relative (the same sums in another order: rounding only); the number
//! of second differences exactly; the edf to 1e-12 (closed forms); the χ² intervals to 1e-7
//! (statrs' inverse χ² CDF against scipy's).

#![allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]

use ground_tool::calibration::allan::{chi2_interval, edf_simple, overlapping_allan_variance};
use serde_json::Value;

fn fixture() -> Value {
    let path =
        std::path::Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/data/allan_crosscheck.json");
    serde_json::from_str(&std::fs::read_to_string(&path).unwrap()).unwrap()
}

fn rel(a: f64, b: f64) -> f64 {
    (a - b).abs() / b.abs().max(f64::MIN_POSITIVE)
}

/// The series' samples: the true rate as stored, the counted rate from whole pulses.
fn samples(fx: &Value, name: &str) -> Vec<f64> {
    let s = &fx["series"][name];
    if let Some(v) = s["samples"].as_array() {
        return v.iter().map(|x| x.as_f64().unwrap()).collect();
    }
    let pulse_rad = fx["parameters"]["pulse_rad"].as_f64().unwrap();
    let tau0_s = fx["parameters"]["tau0_s"].as_f64().unwrap();
    s["delta_pulses"]
        .as_array()
        .unwrap()
        .iter()
        .map(|p| p.as_i64().unwrap() as f64 * pulse_rad / tau0_s)
        .collect()
}

#[test]
fn val_oadev_matches_allantools() {
    let fx = fixture();
    let tau0_s = fx["parameters"]["tau0_s"].as_f64().unwrap();
    let mut checked = 0;
    for name in ["rate_true_rad_per_s", "rate_counted_rad_per_s"] {
        let y = samples(&fx, name);
        assert_eq!(
            y.len() as u64,
            fx["parameters"]["n_samples"].as_u64().unwrap()
        );
        for p in fx["series"][name]["oadev"].as_array().unwrap() {
            let m = p["m"].as_u64().unwrap() as usize;
            let (var, n) = overlapping_allan_variance(std::slice::from_ref(&y), tau0_s, m).unwrap();
            let sigma = var.sqrt();
            let want = p["sigma"].as_f64().unwrap();
            assert!(
                rel(sigma, want) < 1e-9,
                "{name} τ = {m}: ours {sigma:e}, allantools {want:e} ({:.1e})",
                rel(sigma, want)
            );
            assert_eq!(n as u64, p["n"].as_u64().unwrap(), "{name} τ = {m}: terms");
            checked += 1;
        }
    }
    assert!(checked >= 20, "only {checked} points checked");
}

#[test]
fn val_edf_and_intervals_match_allantools() {
    let fx = fixture();
    let n_phase = fx["parameters"]["n_samples"].as_u64().unwrap() as usize + 1;
    for name in ["rate_true_rad_per_s", "rate_counted_rad_per_s"] {
        for p in fx["series"][name]["oadev"].as_array().unwrap() {
            let m = p["m"].as_u64().unwrap() as usize;
            for alpha in [2, 1, 0, -1, -2] {
                let want = p["edf_simple"][alpha.to_string()].as_f64().unwrap();
                let got = edf_simple(n_phase, m, alpha);
                assert!(
                    rel(got, want) < 1e-12,
                    "edf α {alpha} m {m}: {got} vs {want}"
                );
            }
            for level in ["one_sigma", "p95"] {
                let ci = &p["interval"][level];
                let edf = ci["edf_alpha0"].as_f64().unwrap();
                if !(edf > 0.0) {
                    continue;
                }
                let (lo, hi) = chi2_interval(
                    p["sigma"].as_f64().unwrap(),
                    edf,
                    ci["confidence"].as_f64().unwrap(),
                )
                .unwrap();
                let (want_lo, want_hi) =
                    (ci["low"].as_f64().unwrap(), ci["high"].as_f64().unwrap());
                assert!(
                    rel(lo, want_lo) < 1e-7 && rel(hi, want_hi) < 1e-7,
                    "{name} m {m} {level} edf {edf}: [{lo:e}, {hi:e}] vs [{want_lo:e}, {want_hi:e}]"
                );
            }
        }
    }
}
