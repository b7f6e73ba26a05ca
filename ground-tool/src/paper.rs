//! # Reproduction of the CGRO in-flight calibration paper (`ground-tool paper`)
//!
//! Davis, Eudell, Kulp, Lindrose & Harman, "The Results of the In-Flight Attitude Sensor
//! Calibration for the Arthur Holly Compton Gamma Ray Observatory" (CSC/GSFC, ~1992). The
//! published numbers are transcribed in `data/gro_paper.toml` (embedded at build time); this
//! module recomputes what can be recomputed from them and says where the paper is not
//! self-consistent.

use nalgebra::{Matrix3, Vector3};
use serde::Serialize;

/// The transcription's one typed definition, shared with the simulator's truth models
/// (`gro_reference::paper`).
pub use gro_reference::paper::{
    mat, PaperAlignmentResults, PaperData, PaperIruCalibration, PaperManeuver, Rows3,
    GRO_PAPER_TOML,
};

use fsw_core::attitude::rotvec_from_rot;

use crate::calibration::adjust::{m_an_rotation_arcsec, BoresightFrame};
use crate::calibration::iru::{study_plan, GyroNoise, IruError, PlanStudy, PlannedManeuver};
use crate::{ARCSEC_PER_RAD, DEG_PER_RAD, RAD_PER_ARCSEC, RAD_PER_DEG};

/// The four sensors, in the paper's order.
pub const SENSORS: [&str; 4] = ["FHST1", "FHST2", "FSS1", "FSS2"];

/// End-attitude σ for FHST-only ends (arcsec per axis): the FHST's maximum systematic error
/// (`sensors.fhst.systematic_error_1sigma_arcsec_max` = 10″). Each end attitude is a 10-min
/// batch of FHST data, which averages the 8–24″ random errors down to a few arcsec, so the
/// systematic part dominates.
pub const FHST_ONLY_END_SIGMA_ARCSEC: f64 = 10.0;

/// Gyro rate random walk used in the plan study (rad/s^1.5): the paper's bias stability of
/// 0.0012″/s over 6 h read as a random walk (`docs/algorithms.md` §2). Angle random walk is
/// not given in the paper and is set to zero; over 15–20 min intervals neither matters
/// against 10–80″ end attitudes.
pub const PLAN_SIGMA_U_RAD_PER_S_1P5: f64 = 0.0012 * RAD_PER_ARCSEC / 146.969_384_566_990_7; // √21600

/// Errors of the reproduction.
#[derive(Debug, thiserror::Error)]
pub enum PaperError {
    /// The embedded TOML does not parse.
    #[error("embedded gro_paper.toml does not match the expected schema: {0}")]
    Toml(#[from] toml::de::Error),
    /// A table entry is missing.
    #[error("gro_paper.toml lacks {0}: restore it from the paper")]
    Missing(String),
    /// The IRU plan study failed.
    #[error("IRU plan study: {0}")]
    Iru(#[from] IruError),
}

/// Nearest rotation (polar decomposition): the tables are printed to 8–9 digits and are not
/// exactly orthonormal.
#[must_use]
pub fn nearest_rotation(m: &Matrix3<f64>) -> Matrix3<f64> {
    let svd = m.svd(true, true);
    match (svd.u, svd.v_t) {
        (Some(u), Some(v_t)) => {
            let d = (u * v_t).determinant().signum();
            u * Matrix3::from_diagonal(&Vector3::new(1.0, 1.0, d)) * v_t
        }
        _ => *m,
    }
}

/// Largest |MᵀM − I| element.
#[must_use]
pub fn orthonormality_error(m: &Matrix3<f64>) -> f64 {
    (m.transpose() * m - Matrix3::identity()).amax()
}

/// Rotation vector (ACS, arcsec) taking `m_pre` to `m_adj`: `rotvec(M'' Mᵀ)` on the nearest
/// rotations.
#[must_use]
pub fn rotation_vector_arcsec(m_pre: &Matrix3<f64>, m_adj: &Matrix3<f64>) -> Vector3<f64> {
    rotvec_from_rot(&(nearest_rotation(m_adj) * nearest_rotation(m_pre).transpose()))
        * ARCSEC_PER_RAD
}

fn angle_between_rad(a: &Vector3<f64>, b: &Vector3<f64>) -> f64 {
    a.cross(b).norm().atan2(a.dot(b))
}

/// Per-sensor comparison.
#[derive(Clone, Debug, Serialize)]
pub struct SensorReproduction {
    /// Sensor id.
    pub id: String,
    /// `M_AS'' = M_AS M_SS''` (Table 1 × Table 2), row-major.
    pub table3_product: Rows3,
    /// Max |product − published Table 3| (FHSTs only).
    pub table3_max_abs_diff: Option<f64>,
    /// Row, column (0-based) of that largest difference.
    pub table3_max_abs_diff_at: Option<(usize, usize)>,
    /// Non-orthonormality of Table 2 (max |MᵀM − I|).
    pub table2_orthonormality_error: f64,
    /// θ from Table 1 to Table 1 × Table 2 (ACS, arcsec).
    pub rotation_vector_arcsec: [f64; 3],
    /// |θ| (arcsec).
    pub rotation_magnitude_arcsec: f64,
    /// θ from Table 1 to the published Table 3 (FHSTs only).
    pub rotation_vector_from_published_table3_arcsec: Option<[f64; 3]>,
    /// Published θ (arcsec).
    pub rotation_vector_published_arcsec: [f64; 3],
    /// Published |θ|.
    pub rotation_magnitude_published_arcsec: f64,
    /// |published vector| (the published magnitude should equal it).
    pub published_vector_norm_arcsec: f64,
    /// The same rotation in sensor axes, `M_ASᵀ θ` (arcsec).
    pub rotation_vector_sensor_arcsec: [f64; 3],
    /// Angle the boresight moved (arcsec).
    pub boresight_shift_arcsec: f64,
    /// θ component along the boresight (roll, arcsec).
    pub roll_about_boresight_arcsec: f64,
}

/// The IRU plan study against the published σ.
#[derive(Clone, Debug, Serialize)]
pub struct IruPlanReproduction {
    /// End σ used for FSS-based ends (deg).
    pub fss_end_sigma_deg: f64,
    /// End σ used for FHST-only ends (arcsec).
    pub fhst_end_sigma_arcsec: f64,
    /// Predicted σ(ΔM), all ends at the FSS-based 0.022°.
    pub sigma_delta_m_fss_ends: Rows3,
    /// Predicted σ(ΔM), ends as flown: FHST pair → 10″ per axis; FSS + FHST → 10″ across the
    /// FHST boresight and 0.022° about it (the Sun fixes only the roll about the tracker).
    pub sigma_delta_m_as_flown: Rows3,
    /// Predicted σ(ΔM), ends as flown but FSS-based ends isotropic at 0.022°.
    pub sigma_delta_m_as_flown_isotropic: Rows3,
    /// Ratio of that to published.
    pub ratio_as_flown_isotropic_to_published: Rows3,
    /// Predicted bias σ (deg/s), ends as flown (anisotropic FSS+FHST ends).
    pub sigma_bias_as_flown_deg_per_s: [f64; 3],
    /// Predicted bias σ (deg/s), ends as flown with isotropic 0.022° FSS-based ends.
    pub sigma_bias_as_flown_isotropic_deg_per_s: [f64; 3],
    /// Predicted σ(ΔM), all ends FHST-only.
    pub sigma_delta_m_fhst_only: Rows3,
    /// Published σ(ΔM).
    pub sigma_delta_m_published: Rows3,
    /// Ratio predicted (FSS ends) / published.
    pub ratio_fss_ends_to_published: Rows3,
    /// Ratio predicted (as flown) / published.
    pub ratio_as_flown_to_published: Rows3,
    /// Median over the 9 elements of published σ / FHST-only σ.
    pub fhst_only_improvement_median: f64,
    /// Predicted bias σ (deg/s) per axis, FSS ends.
    pub sigma_bias_fss_ends_deg_per_s: [f64; 3],
    /// Predicted bias σ (deg/s) per axis, FHST-only ends.
    pub sigma_bias_fhst_only_deg_per_s: [f64; 3],
    /// Published primary high-rate bias σ (deg/s), X2, Y1, Z1.
    pub sigma_bias_published_deg_per_s: [f64; 3],
}

/// Everything `ground-tool paper` reports.
#[derive(Clone, Debug, Serialize)]
pub struct PaperReproduction {
    /// Per-sensor comparisons.
    pub sensors: Vec<SensorReproduction>,
    /// Max |Table 1 × Table 2 − Table 3| over both FHSTs.
    pub table3_max_abs_diff_fhst: f64,
    /// Angle between the FHST boresights, prelaunch (deg).
    pub fhst_boresight_separation_prelaunch_deg: f64,
    /// Change of that angle, published Table 3 vs Table 1 (arcsec, negative = reduced).
    pub fhst_boresight_separation_change_arcsec: f64,
    /// Same from Table 1 × Table 2.
    pub fhst_boresight_separation_change_product_arcsec: f64,
    /// Published reduction (arcsec).
    pub fhst_boresight_separation_reduction_published_arcsec: f64,
    /// Rotation of `M_AN` (bisector construction) from Table 1 to published Table 3 (arcsec).
    pub m_an_rotation_bisector_arcsec: f64,
    /// Rotation of `M_AN` (FHST1-boresight construction) (arcsec).
    pub m_an_rotation_fhst1_arcsec: f64,
    /// FSS misalignments: rotation magnitude (deg).
    pub fss_rotation_deg: [f64; 2],
    /// FSS misalignments: boresight shift (deg).
    pub fss_boresight_shift_deg: [f64; 2],
    /// Published FSS misalignment (deg).
    pub fss_misalignment_published_deg: [f64; 2],
    /// IRU plan study.
    pub iru: IruPlanReproduction,
}

fn rows(m: &Matrix3<f64>) -> Rows3 {
    std::array::from_fn(|r| std::array::from_fn(|c| m[(r, c)]))
}

fn axis_vector(axis: &str) -> Option<Vector3<f64>> {
    match axis {
        "X" | "x" => Some(Vector3::x()),
        "Y" | "y" => Some(Vector3::y()),
        "Z" | "z" => Some(Vector3::z()),
        _ => None,
    }
}

fn uses_fss(sensors: &[String]) -> bool {
    sensors.iter().any(|s| s.starts_with("FSS"))
}

fn iru_study(
    p: &PaperData,
    end_cov_rad2: impl Fn(&[String]) -> Matrix3<f64>,
) -> Result<PlanStudy, PaperError> {
    let plan = p
        .iru_calibration_intervals
        .iter()
        .map(|m| {
            let axis = axis_vector(&m.axis).ok_or_else(|| {
                PaperError::Missing(format!("a valid maneuver axis (got {})", m.axis))
            })?;
            Ok(PlannedManeuver {
                axis_acs: axis,
                angle_rad: m.angle_deg * RAD_PER_DEG,
                duration_s: m.duration_min * 60.0,
                cov_start_acs_rad2: end_cov_rad2(&m.initial_attitude_sensors),
                cov_end_acs_rad2: end_cov_rad2(&m.final_attitude_sensors),
            })
        })
        .collect::<Result<Vec<_>, PaperError>>()?;
    let noise = GyroNoise {
        sigma_v_rad_per_sqrt_s: 0.0,
        sigma_u_rad_per_s_1p5: PLAN_SIGMA_U_RAD_PER_S_1P5,
    };
    Ok(study_plan(&plan, &noise, 1.0)?)
}

fn median(mut v: Vec<f64>) -> f64 {
    v.sort_by(f64::total_cmp);
    let n = v.len();
    if n == 0 {
        return f64::NAN;
    }
    if n % 2 == 1 {
        v[n / 2]
    } else {
        0.5 * (v[n / 2 - 1] + v[n / 2])
    }
}

/// Recompute everything (see the module doc).
///
/// # Errors
/// [`PaperError`] if the embedded data are incomplete.
pub fn reproduce() -> Result<PaperReproduction, PaperError> {
    let p = PaperData::embedded()?;
    let missing = |what: &str| PaperError::Missing(what.to_owned());
    let sensors = SENSORS
        .iter()
        .map(|id| sensor_reproduction(&p, id))
        .collect::<Result<Vec<_>, _>>()?;
    let t1 = |id: &str| p.prelaunch(id).ok_or_else(|| missing(id));
    let t3 = |id: &str| p.adjusted_published(id).ok_or_else(|| missing(id));
    let (pre1, pre2, adj1, adj2) = (t1("FHST1")?, t1("FHST2")?, t3("FHST1")?, t3("FHST2")?);
    let bore = |m: &Matrix3<f64>| m.column(2).into_owned().normalize();
    let sep_pre = angle_between_rad(&bore(&pre1), &bore(&pre2));
    let sep_adj = angle_between_rad(&bore(&adj1), &bore(&adj2));
    let prod = |i: usize| mat(&sensors[i].table3_product);
    let sep_prod = angle_between_rad(&bore(&prod(0)), &bore(&prod(1)));
    let m_an = |c| {
        m_an_rotation_arcsec((&pre1, &pre2), (&adj1, &adj2), c)
            .map_err(|e| PaperError::Missing(e.to_string()))
    };
    let iru = iru_plan_reproduction(&p)?;
    Ok(PaperReproduction {
        table3_max_abs_diff_fhst: sensors
            .iter()
            .filter_map(|s| s.table3_max_abs_diff)
            .fold(0.0_f64, f64::max),
        fhst_boresight_separation_prelaunch_deg: sep_pre * DEG_PER_RAD,
        fhst_boresight_separation_change_arcsec: (sep_adj - sep_pre) * ARCSEC_PER_RAD,
        fhst_boresight_separation_change_product_arcsec: (sep_prod - sep_pre) * ARCSEC_PER_RAD,
        fhst_boresight_separation_reduction_published_arcsec: p
            .alignment_results_published
            .fhst_boresight_separation_reduction_arcsec,
        m_an_rotation_bisector_arcsec: m_an(BoresightFrame::Bisector)?,
        m_an_rotation_fhst1_arcsec: m_an(BoresightFrame::Fhst1Boresight)?,
        fss_rotation_deg: [
            sensors[2].rotation_magnitude_arcsec / 3600.0,
            sensors[3].rotation_magnitude_arcsec / 3600.0,
        ],
        fss_boresight_shift_deg: [
            sensors[2].boresight_shift_arcsec / 3600.0,
            sensors[3].boresight_shift_arcsec / 3600.0,
        ],
        fss_misalignment_published_deg: [
            p.alignment_results_published.fss1_misalignment_deg,
            p.alignment_results_published.fss2_misalignment_deg,
        ],
        iru,
        sensors,
    })
}

/// One sensor's rows of Tables 1–3 and its rotation vector against the published one.
fn sensor_reproduction(p: &PaperData, id: &str) -> Result<SensorReproduction, PaperError> {
    let missing = |what: &str| PaperError::Missing(what.to_owned());
    let m_pre = p
        .prelaunch(id)
        .ok_or_else(|| missing(&format!("table1_prelaunch.{id}")))?;
    let m_ss = p
        .misalignment(id)
        .ok_or_else(|| missing(&format!("table2_misalignment.{id}")))?;
    let product = m_pre * m_ss;
    let published = p.adjusted_published(id);
    let (diff, at) = match &published {
        Some(m3) => {
            let d = product - m3;
            let (mut best, mut at) = (0.0, (0, 0));
            for r in 0..3 {
                for c in 0..3 {
                    if d[(r, c)].abs() > best {
                        best = d[(r, c)].abs();
                        at = (r, c);
                    }
                }
            }
            (Some(best), Some(at))
        }
        None => (None, None),
    };
    let theta = rotation_vector_arcsec(&m_pre, &product);
    let boresight_pre = m_pre.column(2).into_owned().normalize();
    let boresight_adj = product.column(2).into_owned().normalize();
    let published_vec = p
        .rotation_vector_published_arcsec(id)
        .ok_or_else(|| missing(&format!("rotation_vectors_published_arcsec.{id}")))?;
    Ok(SensorReproduction {
        id: id.to_owned(),
        table3_product: rows(&product),
        table3_max_abs_diff: diff,
        table3_max_abs_diff_at: at,
        table2_orthonormality_error: orthonormality_error(&m_ss),
        rotation_vector_arcsec: theta.into(),
        rotation_magnitude_arcsec: theta.norm(),
        rotation_vector_sensor_arcsec: (nearest_rotation(&m_pre).transpose() * theta).into(),
        rotation_vector_from_published_table3_arcsec: published
            .map(|m3| rotation_vector_arcsec(&m_pre, &m3).into()),
        rotation_vector_published_arcsec: published_vec.into(),
        rotation_magnitude_published_arcsec: p
            .rotation_magnitude_published_arcsec(id)
            .ok_or_else(|| missing(&format!("rotation_vectors_published_arcsec.magnitude.{id}")))?,
        published_vector_norm_arcsec: published_vec.norm(),
        boresight_shift_arcsec: angle_between_rad(&boresight_pre, &boresight_adj) * ARCSEC_PER_RAD,
        roll_about_boresight_arcsec: theta.dot(&boresight_pre),
    })
}

/// The IRU calibration plan's σ(δM) and bias σ with FSS-based, as-flown and FHST-only ends,
/// against the published ones.
fn iru_plan_reproduction(p: &PaperData) -> Result<IruPlanReproduction, PaperError> {
    let missing = |what: &str| PaperError::Missing(what.to_owned());
    let fss_sigma_rad = p.fss_inherent_error_deg() * RAD_PER_DEG;
    let fhst_sigma_rad = FHST_ONLY_END_SIGMA_ARCSEC * RAD_PER_ARCSEC;
    let iso = |s: f64| Matrix3::identity() * s * s;
    let fss_ends = iru_study(p, |_| iso(fss_sigma_rad))?;
    let as_flown_isotropic = iru_study(p, |s| {
        iso(if uses_fss(s) {
            fss_sigma_rad
        } else {
            fhst_sigma_rad
        })
    })?;
    // FSS + FHST: the tracker fixes the two axes across its boresight (10″), the Sun only the
    // roll about that boresight (0.022°).
    let as_flown = iru_study(p, |s| {
        if !uses_fss(s) {
            return iso(fhst_sigma_rad);
        }
        let tracker = s
            .iter()
            .find(|x| x.starts_with("FHST"))
            .and_then(|id| p.prelaunch(id));
        match tracker {
            Some(m) => {
                let e = m.column(2).into_owned().normalize();
                let along = e * e.transpose();
                (Matrix3::identity() - along) * fhst_sigma_rad * fhst_sigma_rad
                    + along * fss_sigma_rad * fss_sigma_rad
            }
            None => iso(fss_sigma_rad),
        }
    })?;
    let fhst_only = iru_study(p, |_| iso(fhst_sigma_rad))?;
    let published = mat(&p.iru_calibration_published.delta_m_1sigma);
    let ratio = |s: &PlanStudy| rows(&s.sigma_delta_m.component_div(&published));
    let improvement = median(
        published
            .component_div(&fhst_only.sigma_delta_m)
            .iter()
            .copied()
            .collect(),
    );
    let bias_pub = |ch: &str| p.high_rate_bias_deg_per_s("primary", ch).map(|v| v[1]);
    let sigma_bias_published_deg_per_s = [
        bias_pub("X2").ok_or_else(|| missing("iru_high_rate_bias_deg_per_s.primary.X2"))?,
        bias_pub("Y1").ok_or_else(|| missing("iru_high_rate_bias_deg_per_s.primary.Y1"))?,
        bias_pub("Z1").ok_or_else(|| missing("iru_high_rate_bias_deg_per_s.primary.Z1"))?,
    ];
    let deg = |v: &Vector3<f64>| -> [f64; 3] { (v * DEG_PER_RAD).into() };
    Ok(IruPlanReproduction {
        fss_end_sigma_deg: p.fss_inherent_error_deg(),
        fhst_end_sigma_arcsec: FHST_ONLY_END_SIGMA_ARCSEC,
        sigma_delta_m_fss_ends: rows(&fss_ends.sigma_delta_m),
        sigma_delta_m_as_flown: rows(&as_flown.sigma_delta_m),
        sigma_delta_m_fhst_only: rows(&fhst_only.sigma_delta_m),
        sigma_delta_m_published: rows(&published),
        ratio_fss_ends_to_published: ratio(&fss_ends),
        ratio_as_flown_to_published: ratio(&as_flown),
        sigma_delta_m_as_flown_isotropic: rows(&as_flown_isotropic.sigma_delta_m),
        ratio_as_flown_isotropic_to_published: ratio(&as_flown_isotropic),
        sigma_bias_as_flown_deg_per_s: deg(&as_flown.sigma_bias_acs_rad_per_s),
        sigma_bias_as_flown_isotropic_deg_per_s: deg(&as_flown_isotropic.sigma_bias_acs_rad_per_s),
        fhst_only_improvement_median: improvement,
        sigma_bias_fss_ends_deg_per_s: deg(&fss_ends.sigma_bias_acs_rad_per_s),
        sigma_bias_fhst_only_deg_per_s: deg(&fhst_only.sigma_bias_acs_rad_per_s),
        sigma_bias_published_deg_per_s,
    })
}

/// The JSON document of `ground-tool paper --json`: the required keys at the top level, the
/// full reproduction under `details`.
#[must_use]
pub fn to_json(r: &PaperReproduction) -> serde_json::Value {
    let mag: serde_json::Map<String, serde_json::Value> = r
        .sensors
        .iter()
        .map(|s| (s.id.clone(), serde_json::json!(s.rotation_magnitude_arcsec)))
        .collect();
    serde_json::json!({
        "table3": {
            "max_abs_diff_fhst": r.table3_max_abs_diff_fhst,
            "fss_product": r.sensors.iter().filter(|s| s.id.starts_with("FSS"))
                .map(|s| (s.id.clone(), serde_json::json!(s.table3_product))).collect::<serde_json::Map<_, _>>(),
        },
        "fhst_boresight_separation_change_arcsec": r.fhst_boresight_separation_change_arcsec,
        "m_an_preserved_arcsec": r.m_an_rotation_bisector_arcsec,
        "rotation_magnitude_arcsec": mag,
        "iru_plan_sigma_ratio_to_published": r.iru.ratio_as_flown_isotropic_to_published,
        "iru_fhst_only_improvement": r.iru.fhst_only_improvement_median,
        "details": r,
    })
}

fn fmt3(v: &[f64; 3], prec: usize) -> String {
    format!("[{:.p$}, {:.p$}, {:.p$}]", v[0], v[1], v[2], p = prec)
}

fn fmt_rows(m: &Rows3, scale: f64, prec: usize) -> String {
    m.iter()
        .map(|r| fmt3(&[r[0] * scale, r[1] * scale, r[2] * scale], prec))
        .collect::<Vec<_>>()
        .join(" ")
}

/// Human-readable side-by-side table: quantity, published, ours, explanation.
#[must_use]
pub fn render_table(r: &PaperReproduction) -> String {
    let mut rows: Vec<[String; 4]> = Vec::new();
    let mut push =
        |q: &str, p: String, o: String, n: &str| rows.push([q.to_owned(), p, o, n.to_owned()]);
    for s in r.sensors.iter().filter(|s| s.table3_max_abs_diff.is_some()) {
        let (row, col) = s.table3_max_abs_diff_at.unwrap_or((0, 0));
        push(
            &format!("Table 3 {} = Table 1 × Table 2", s.id),
            "as printed".into(),
            format!(
                "max |Δ| {:.1e} at ({},{})",
                s.table3_max_abs_diff.unwrap_or(f64::NAN),
                row + 1,
                col + 1
            ),
            if s.id == "FHST1" {
                "agrees to the printed 8 digits once the lost minus sign of element (1,1) is restored (the product fixes it)"
            } else {
                "2e-7 (0.04″) is above the 8-digit rounding, all in the middle column: Table 2 FHST2 element (3,2) is printed 0.0000003 (7 decimals where every other entry has 8); read as 0.00000003 the product matches Table 3 to 5.6e-8 (fsw-core/tests/prop_conventions.rs)"
            },
        );
    }
    for s in &r.sensors {
        let note = if s.id.starts_with("FHST") {
            "the published vector is 1–3 % smaller than Table 2 implies, in the roll about the boresight only (the boresight-tilt component agrees to 0.05″); Tables 2 and 3 agree with each other, so the printed vectors come from a slightly different solution"
        } else {
            "magnitude reproduced (the paper is right about the size), but the printed direction is not the ACS rotation vector of Table 2, nor its sensor-frame form (see details.rotation_vector_sensor_arcsec): only the printed z matches ± the sensor-frame y component (FSS1 −562 vs −561″, FSS2 110 vs −110″); the text's FSS vectors are in an undocumented frame"
        };
        push(
            &format!("θ {} (ACS, ″) prelaunch→adjusted", s.id),
            fmt3(&s.rotation_vector_published_arcsec, 1),
            fmt3(&s.rotation_vector_arcsec, 1),
            note,
        );
        push(
            &format!("|θ| {} (″)", s.id),
            format!("{:.1}", s.rotation_magnitude_published_arcsec),
            format!("{:.1}", s.rotation_magnitude_arcsec),
            &format!(
                "boresight moved {:.1}″, roll about boresight {:.1}″; |printed vector| = {:.1}″",
                s.boresight_shift_arcsec,
                s.roll_about_boresight_arcsec,
                s.published_vector_norm_arcsec
            ),
        );
    }
    push(
        "FHST boresight separation change (″)",
        format!("−{:.1}", r.fhst_boresight_separation_reduction_published_arcsec),
        format!("{:.2}", r.fhst_boresight_separation_change_arcsec),
        &format!(
            "from published Table 3 vs Table 1 (Table 1 × Table 2: {:.2}″); prelaunch separation {:.5}°; both boresights move ≈13.7″ in opposite senses",
            r.fhst_boresight_separation_change_product_arcsec, r.fhst_boresight_separation_prelaunch_deg
        ),
    );
    push(
        "M_AN preserved by the adjustment (″)",
        "0 (appendix)".into(),
        format!("{:.4} (bisector frame)", r.m_an_rotation_bisector_arcsec),
        &format!(
            "the published alignments keep the frame (n1 = bisector of the boresights, n3 = their normal); with n1 = FHST1 boresight they would move it by {:.1}″, so the paper used the symmetric frame",
            r.m_an_rotation_fhst1_arcsec
        ),
    );
    for k in 0..2 {
        push(
            &format!("FSS{} misalignment (°)", k + 1),
            format!("{:.2}", r.fss_misalignment_published_deg[k]),
            format!("{:.3}", r.fss_rotation_deg[k]),
            &format!(
                "= rotation angle |θ|; the boresight itself moved only {:.3}°",
                r.fss_boresight_shift_deg[k]
            ),
        );
    }
    let iru = &r.iru;
    push(
        "IRU σ(ΔM) (ppm), 4-maneuver plan",
        fmt_rows(&iru.sigma_delta_m_published, 1e6, 0),
        fmt_rows(&iru.sigma_delta_m_as_flown_isotropic, 1e6, 0),
        &format!(
            "covariance study, FSS-based ends {}° and FHST-pair ends {}″ per axis; ratio {}: the X and Z columns agree within 10 %, the Y column is 1.6× the published σ (the paper's Y result is better than its two Y slews allow with 0.022° ends)",
            iru.fss_end_sigma_deg,
            iru.fhst_end_sigma_arcsec,
            fmt_rows(&iru.ratio_as_flown_isotropic_to_published, 1.0, 2)
        ),
    );
    push(
        "IRU σ(ΔM) (ppm), every end at 0.022°",
        fmt_rows(&iru.sigma_delta_m_published, 1e6, 0),
        fmt_rows(&iru.sigma_delta_m_fss_ends, 1e6, 0),
        &format!("ratio {}: too pessimistic, so the FHST-pair ends must have been better than the FSS ones", fmt_rows(&iru.ratio_fss_ends_to_published, 1.0, 2)),
    );
    push(
        "IRU σ(ΔM) (ppm), anisotropic FSS+FHST ends",
        fmt_rows(&iru.sigma_delta_m_published, 1e6, 0),
        fmt_rows(&iru.sigma_delta_m_as_flown, 1e6, 0),
        &format!("ratio {}: the physically better end model breaks the published pattern (σ equal down each column), so the paper used isotropic end errors", fmt_rows(&iru.ratio_as_flown_to_published, 1.0, 2)),
    );
    push(
        "IRU σ(ΔM) (ppm), FHST-only ends (10″)",
        fmt_rows(&iru.sigma_delta_m_published, 1e6, 0),
        fmt_rows(&iru.sigma_delta_m_fhst_only, 1e6, 0),
        &format!("median published/FHST-only = {:.2}: the improvement the paper recommends for later calibrations", iru.fhst_only_improvement_median),
    );
    push(
        "IRU bias σ (1e-5 °/s) X, Y, Z",
        fmt3(&iru.sigma_bias_published_deg_per_s.map(|x| x * 1e5), 2),
        fmt3(&iru.sigma_bias_as_flown_isotropic_deg_per_s.map(|x| x * 1e5), 2),
        &format!(
            "as-flown ends as in the σ(ΔM) row; anisotropic ends: {}; every end at 0.022°: {}; FHST-only: {}",
            fmt3(&iru.sigma_bias_as_flown_deg_per_s.map(|x| x * 1e5), 2),
            fmt3(&iru.sigma_bias_fss_ends_deg_per_s.map(|x| x * 1e5), 2),
            fmt3(&iru.sigma_bias_fhst_only_deg_per_s.map(|x| x * 1e5), 2)
        ),
    );
    let widths: [usize; 3] = std::array::from_fn(|k| {
        rows.iter()
            .map(|r| r[k].chars().count())
            .max()
            .unwrap_or(0)
            .min(60)
    });
    let mut out = String::new();
    let header = ["Quantity", "Published", "Ours", "Explanation"];
    out.push_str(&format!(
        "{:w0$}  {:w1$}  {:w2$}  {}\n",
        header[0],
        header[1],
        header[2],
        header[3],
        w0 = widths[0],
        w1 = widths[1],
        w2 = widths[2]
    ));
    for r in &rows {
        out.push_str(&format!(
            "{:w0$}  {:w1$}  {:w2$}  {}\n",
            r[0],
            r[1],
            r[2],
            r[3],
            w0 = widths[0],
            w1 = widths[1],
            w2 = widths[2]
        ));
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    fn repro() -> PaperReproduction {
        reproduce().unwrap()
    }

    /// Table 3 FHST rows = Table 1 × Table 2 to 2.5e-7 (the printed 8 digits give 5e-9; the
    /// FHST2 (1,2) element is off by 1.9e-7, a slip in the paper).
    #[test]
    fn val_paper_table3_is_table1_times_table2() {
        let r = repro();
        assert!(
            r.table3_max_abs_diff_fhst < 2.5e-7,
            "{}",
            r.table3_max_abs_diff_fhst
        );
        assert!(r.sensors[0].table3_max_abs_diff.unwrap() < 1e-7);
        // FHST1 (1,1) is negative in the product: the sign fix of the transcription is right
        assert!(r.sensors[0].table3_product[0][0] < -0.7);
    }

    /// Rotation magnitudes: FSS within 1″ of the printed 733/189″; FHSTs within 3 % (the paper's
    /// FHST vectors are 1–3 % smaller in roll than its own Table 2: see the table's notes).
    #[test]
    fn val_paper_rotation_magnitudes() {
        let r = repro();
        for s in &r.sensors {
            let rel = (s.rotation_magnitude_arcsec - s.rotation_magnitude_published_arcsec)
                / s.rotation_magnitude_published_arcsec;
            let tol = if s.id.starts_with("FSS") {
                1.0 / s.rotation_magnitude_published_arcsec
            } else {
                0.035
            };
            assert!(
                rel.abs() < tol,
                "{}: ours {} published {}",
                s.id,
                s.rotation_magnitude_arcsec,
                s.rotation_magnitude_published_arcsec
            );
            // published magnitude is the norm of the printed vector to the printed precision
            assert!(
                (s.published_vector_norm_arcsec - s.rotation_magnitude_published_arcsec).abs()
                    < 0.6
            );
        }
        // FHST boresight-tilt component (ACS z) agrees to 0.1″
        for k in 0..2 {
            let s = &r.sensors[k];
            assert!(
                (s.rotation_vector_arcsec[2] - s.rotation_vector_published_arcsec[2]).abs() < 0.1
            );
        }
    }

    /// Boresight separation reduced by 27.4″ (published 27.5″; tolerance 0.2″ for the
    /// rounding of the text), M_AN preserved to < 0.01″ with the bisector frame, FSS
    /// misalignment angles 0.20° and 0.05° to the printed precision.
    #[test]
    fn val_paper_alignment_statements() {
        let r = repro();
        assert!(
            (r.fhst_boresight_separation_change_arcsec
                + r.fhst_boresight_separation_reduction_published_arcsec)
                .abs()
                < 0.2
        );
        assert!(r.m_an_rotation_bisector_arcsec < 0.01);
        assert!(r.m_an_rotation_fhst1_arcsec > 10.0);
        for k in 0..2 {
            assert!((r.fss_rotation_deg[k] - r.fss_misalignment_published_deg[k]).abs() < 0.005);
        }
    }

    /// IRU plan covariance study vs published σ(ΔM): X and Z columns within 15 %, Y column
    /// within a factor 2 (documented discrepancy); FHST-only ends improve σ by > 2.5×.
    #[test]
    fn val_paper_iru_plan_study() {
        let r = repro();
        let ratio = r.iru.ratio_as_flown_isotropic_to_published;
        for row in ratio {
            assert!(
                (row[0] - 1.0).abs() < 0.15 && (row[2] - 1.0).abs() < 0.15,
                "{row:?}"
            );
            assert!(row[1] > 1.0 && row[1] < 2.0, "{row:?}");
        }
        assert!(r.iru.fhst_only_improvement_median > 2.5);
        let json = to_json(&r);
        for key in [
            "fhst_boresight_separation_change_arcsec",
            "m_an_preserved_arcsec",
            "iru_fhst_only_improvement",
        ] {
            assert!(json[key].is_number(), "{key}");
        }
        assert!(json["table3"]["max_abs_diff_fhst"].is_number());
        for id in SENSORS {
            assert!(json["rotation_magnitude_arcsec"][id].is_number());
        }
        assert_eq!(
            json["iru_plan_sigma_ratio_to_published"]
                .as_array()
                .map(Vec::len),
            Some(3)
        );
    }
}
