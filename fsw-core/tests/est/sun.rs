//! Onboard Sun ephemeris against DE421 (Skyfield) apparent directions, `data/sun_reference.csv`.

use crate::est_support::Csv;
use fsw_core::sun_ephemeris::{aberrate, sun_state};
use fsw_core::units::{ARCSEC_PER_RAD, S_PER_DAY};
use nalgebra::Vector3;

fn angle_arcsec(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b)) * ARCSEC_PER_RAD
}

#[test]
fn apparent_sun_within_36_arcsec_of_de421() {
    let csv = Csv::read("sun_reference.csv");
    let jd = csv.col("jd_tt");
    let app = csv.cols3("app_");
    let geo = csv.cols3("geo_");
    let vel = ["earth_vx_kms", "earth_vy_kms", "earth_vz_kms"].map(|c| csv.col(c));
    let dist = csv.col("sun_dist_au");
    let (mut max_app, mut max_geo, mut max_beta, mut max_dist, mut sum_app) =
        (0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64, 0.0_f64);
    let mut max_aberrate_only = 0.0_f64;
    for row in &csv.rows {
        let t = (csv.f64(row, jd) - 2_451_545.0) * S_PER_DAY;
        let v = |c: [usize; 3]| csv.vec3(row, c);
        let s = sun_state(t).unwrap();
        let e_app = angle_arcsec(&s.dir_eci, &v(app));
        max_app = max_app.max(e_app);
        sum_app += e_app;
        max_geo = max_geo.max(angle_arcsec(&s.geometric_dir_eci, &v(geo)));
        let beta_ref = v(vel) / 299_792.458;
        max_beta = max_beta.max((s.earth_velocity_over_c - beta_ref).norm() * ARCSEC_PER_RAD);
        max_dist = max_dist.max((s.distance_au - csv.f64(row, dist)).abs());
        // The aberration step alone: reference geometric + reference velocity → apparent.
        let ab = aberrate(&v(geo), &beta_ref);
        max_aberrate_only = max_aberrate_only.max(angle_arcsec(&ab, &v(app)));
    }
    let n = csv.rows.len() as f64;
    println!(
        "Sun ephemeris vs DE421 over {} epochs (1991-04..12): apparent max {:.2}\" mean {:.2}\", \
         geometric max {:.2}\", |beta - v/c| max {:.4}\", distance max {:.2e} au, \
         aberration formula alone max {:.4}\"",
        csv.rows.len(),
        max_app,
        sum_app / n,
        max_geo,
        max_beta,
        max_dist,
        max_aberrate_only
    );
    assert_eq!(csv.rows.len(), 200);
    assert!(max_app < 36.0, "max apparent error {max_app}\"");
    assert!(max_beta < 0.1, "Earth velocity error {max_beta}\"");
    assert!(max_aberrate_only < 0.01);
    assert!(max_dist < 1e-4);
}

#[test]
fn star_aberration_with_the_onboard_earth_velocity() {
    // 50 bright stars × 20 epochs of 1991: astrometric → apparent with our β.
    let csv = Csv::read("aberration_reference.csv");
    let jd = csv.col("jd_tt");
    let astr = csv.cols3("astr_");
    let app = csv.cols3("app_");
    let shift = csv.col("aberration_arcsec");
    let (mut max_err, mut max_shift) = (0.0_f64, 0.0_f64);
    for row in &csv.rows {
        let t = (csv.f64(row, jd) - 2_451_545.0) * S_PER_DAY;
        let v = |c: [usize; 3]| csv.vec3(row, c);
        let beta = fsw_core::sun_ephemeris::earth_velocity_over_c(t).unwrap();
        max_err = max_err.max(angle_arcsec(&aberrate(&v(astr), &beta), &v(app)));
        max_shift = max_shift.max(csv.f64(row, shift));
    }
    println!(
        "star aberration with onboard beta: max error {max_err:.4}\" (shifts up to {max_shift:.2}\") over {} cases",
        csv.rows.len()
    );
    assert!(max_err < 0.05);
}
