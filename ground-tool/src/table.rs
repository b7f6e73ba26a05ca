//! # Uplink table images on the ground: inspect, diff, write (`ground-tool table …`)
//!
//! Why: the calibration ends in tables the OBC loads (paper §4: the adjusted alignments were
//! uplinked on 1991-05-14). The image format and the table types are `fsw_core::tables` (one
//! definition for the OBC and the ground, `docs/tables.md`); this module only reads and
//! writes them. Every image written here passes the same `validate()` the OBC runs on load,
//! and is re-parsed after encoding.

use std::path::Path;

use nalgebra::Matrix3;
use serde::Serialize;
use thiserror::Error;

use fsw_core::attitude::rotvec_from_rot;
use fsw_core::raw::TimeTag;
use fsw_core::tables::image::{decode_payload, encode_image, parse_image, ImageHeader};
use fsw_core::tables::types::{matrix_from_rows, rows_from_matrix, SensorCorrections};
use fsw_core::tables::{
    AlignmentTable, FilterTable, IruTable, MagneticsTable, OrbitTable, StarCatalogTable,
    TableError, TableId,
};

use crate::ARCSEC_PER_RAD;

/// Names of the alignment table's sensors, in table order.
pub const ALIGNMENT_SENSORS: [&str; 4] = ["FHST1", "FHST2", "FSS1", "FSS2"];

/// Largest image this tool writes or reads into memory for encoding (bytes).
const MAX_IMAGE_BYTES: usize = 1 << 20;

/// Errors of the table tools.
#[derive(Debug, Error)]
pub enum TableToolError {
    /// File could not be read or written.
    #[error("cannot read {path}")]
    Io {
        /// File.
        path: String,
        /// OS error.
        source: std::io::Error,
    },
    /// The image is malformed (header, CRC, payload) — the OBC would reject it too.
    #[error("{what}: not a valid table image: {detail}")]
    Image {
        /// Which image.
        what: String,
        /// `fsw_core::tables::TableError`, formatted.
        detail: String,
    },
    /// The two images hold different tables.
    #[error("cannot diff a {a} table against a {b} table: give two images of the same table")]
    DifferentTables {
        /// First table name.
        a: &'static str,
        /// Second table name.
        b: &'static str,
    },
    /// A table to be written fails the OBC's validation.
    #[error("table fails the OBC's validation ({detail}): it would be rejected on load; fix the content")]
    Invalid {
        /// `TableError`, formatted.
        detail: String,
    },
}

/// A decoded table of any kind.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub enum AnyTable {
    /// Sensor alignments.
    Alignment(AlignmentTable),
    /// IRU calibration.
    Iru(IruTable),
    /// Filter / star-ID / control settings.
    Filter(FilterTable),
    /// Star catalog.
    StarCatalog(Box<StarCatalogTable>),
    /// Onboard orbit (state vector at an epoch).
    Orbit(OrbitTable),
    /// Field model, TAM calibration, coarse-attitude settings.
    Magnetics(Box<MagneticsTable>),
}

impl AnyTable {
    /// The OBC's content validation of this table.
    ///
    /// # Errors
    /// The first failed check.
    pub fn validate(&self) -> Result<(), TableError> {
        match self {
            Self::Alignment(t) => t.validate(),
            Self::Iru(t) => t.validate(),
            Self::Filter(t) => t.validate(),
            Self::StarCatalog(t) => t.validate(),
            Self::Orbit(t) => t.validate(),
            Self::Magnetics(t) => t.validate(),
        }
    }

    /// Content as JSON.
    #[must_use]
    pub fn to_json(&self) -> serde_json::Value {
        let v = match self {
            Self::Alignment(t) => serde_json::to_value(t),
            Self::Iru(t) => serde_json::to_value(t),
            Self::Filter(t) => serde_json::to_value(t),
            Self::StarCatalog(t) => serde_json::to_value(t),
            Self::Orbit(t) => serde_json::to_value(t),
            Self::Magnetics(t) => serde_json::to_value(t),
        };
        v.unwrap_or(serde_json::Value::Null)
    }
}

/// Parse, CRC-check and decode an image (content validation is reported, not required).
///
/// # Errors
/// [`TableToolError::Image`] when the header, CRC or payload is bad.
pub fn decode_image(bytes: &[u8], what: &str) -> Result<(ImageHeader, AnyTable), TableToolError> {
    let image_err = |e: TableError| TableToolError::Image {
        what: what.to_owned(),
        detail: e.to_string(),
    };
    let (header, payload) = parse_image(bytes).map_err(image_err)?;
    let table = match header.table_id {
        TableId::Alignment => AnyTable::Alignment(decode_payload(payload).map_err(image_err)?),
        TableId::Iru => AnyTable::Iru(decode_payload(payload).map_err(image_err)?),
        TableId::Filter => AnyTable::Filter(decode_payload(payload).map_err(image_err)?),
        TableId::StarCatalog => {
            AnyTable::StarCatalog(Box::new(decode_payload(payload).map_err(image_err)?))
        }
        TableId::Orbit => AnyTable::Orbit(decode_payload(payload).map_err(image_err)?),
        // Either layout, as the OBC reads it (layout-1 images: the unloading fields at boot).
        TableId::Magnetics => AnyTable::Magnetics(Box::new(
            MagneticsTable::decode_any_layout(payload)
                .map_err(image_err)?
                .0,
        )),
    };
    Ok((header, table))
}

/// What `table inspect` reports.
#[derive(Clone, Debug, Serialize)]
pub struct Inspection {
    /// Table name.
    pub table: &'static str,
    /// Format version.
    pub format_version: u8,
    /// Image length (bytes).
    pub image_len: usize,
    /// Payload length (bytes).
    pub payload_len: u32,
    /// Creation time, seconds since 1958-01-01 TAI.
    pub created_tai_s: f64,
    /// `None` when the OBC would accept the content, else the failed check.
    pub validation_error: Option<String>,
    /// Alignment tables: per sensor, the rotation from the prelaunch (boot) table (ACS, arcsec).
    pub rotation_from_prelaunch_arcsec: Option<Vec<(String, [f64; 3], f64)>>,
    /// Content.
    pub content: serde_json::Value,
}

fn rotations_between(a: &AlignmentTable, b: &AlignmentTable) -> Vec<(String, [f64; 3], f64)> {
    ALIGNMENT_SENSORS
        .iter()
        .zip(a.matrices().iter().zip(b.matrices()))
        .map(|(id, (ma, mb))| {
            let theta = rotvec_from_rot(&(matrix_from_rows(mb) * matrix_from_rows(ma).transpose()))
                * ARCSEC_PER_RAD;
            ((*id).to_owned(), theta.into(), theta.norm())
        })
        .collect()
}

/// Inspect an image.
///
/// # Errors
/// [`TableToolError::Image`] for a malformed image.
pub fn inspect(bytes: &[u8], what: &str) -> Result<Inspection, TableToolError> {
    let (header, table) = decode_image(bytes, what)?;
    let rotation_from_prelaunch_arcsec = match &table {
        AnyTable::Alignment(t) => Some(rotations_between(&AlignmentTable::prelaunch(), t)),
        _ => None,
    };
    Ok(Inspection {
        table: header.table_id.name(),
        format_version: header.format_version,
        image_len: bytes.len(),
        payload_len: header.payload_len,
        created_tai_s: f64::from(header.created.coarse_s)
            + f64::from(header.created.fine) / 65536.0,
        validation_error: table.validate().err().map(|e| e.to_string()),
        rotation_from_prelaunch_arcsec,
        content: table.to_json(),
    })
}

/// One numeric field that differs.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct FieldDiff {
    /// JSON path of the field.
    pub path: String,
    /// Value in A (`None` if absent).
    pub a: Option<f64>,
    /// Value in B (`None` if absent).
    pub b: Option<f64>,
}

/// What `table diff` reports.
#[derive(Clone, Debug, Serialize)]
pub struct TableDiff {
    /// Table name.
    pub table: &'static str,
    /// Fields that differ (numbers, and booleans/strings as NaN-free notes in `path`).
    pub fields: Vec<FieldDiff>,
    /// Alignment tables: rotation per sensor from A to B (ACS, arcsec), vector and angle.
    pub alignment_rotation_arcsec: Option<Vec<(String, [f64; 3], f64)>>,
    /// IRU tables: largest G element change (ppm).
    pub iru_max_g_change_ppm: Option<f64>,
}

fn walk(
    path: &str,
    a: Option<&serde_json::Value>,
    b: Option<&serde_json::Value>,
    out: &mut Vec<FieldDiff>,
) {
    use serde_json::Value;
    match (a, b) {
        (Some(Value::Object(ma)), Some(Value::Object(mb))) => {
            let mut keys: Vec<&String> = ma.keys().chain(mb.keys()).collect();
            keys.sort();
            keys.dedup();
            for k in keys {
                walk(&format!("{path}.{k}"), ma.get(k), mb.get(k), out);
            }
        }
        (Some(Value::Array(va)), Some(Value::Array(vb))) => {
            for i in 0..va.len().max(vb.len()) {
                walk(&format!("{path}[{i}]"), va.get(i), vb.get(i), out);
            }
        }
        (x, y) => {
            if x != y {
                out.push(FieldDiff {
                    path: path.to_owned(),
                    a: x.and_then(Value::as_f64),
                    b: y.and_then(Value::as_f64),
                });
            }
        }
    }
}

/// Diff two images of the same table.
///
/// # Errors
/// [`TableToolError::Image`] for a malformed image, [`TableToolError::DifferentTables`].
pub fn diff(a_bytes: &[u8], b_bytes: &[u8]) -> Result<TableDiff, TableToolError> {
    let (ha, ta) = decode_image(a_bytes, "A")?;
    let (hb, tb) = decode_image(b_bytes, "B")?;
    if ha.table_id != hb.table_id {
        return Err(TableToolError::DifferentTables {
            a: ha.table_id.name(),
            b: hb.table_id.name(),
        });
    }
    let mut fields = Vec::new();
    walk("", Some(&ta.to_json()), Some(&tb.to_json()), &mut fields);
    let (alignment_rotation_arcsec, iru_max_g_change_ppm) = match (&ta, &tb) {
        (AnyTable::Alignment(a), AnyTable::Alignment(b)) => (Some(rotations_between(a, b)), None),
        (AnyTable::Iru(a), AnyTable::Iru(b)) => (None, Some(a.max_g_change_ppm(b))),
        _ => (None, None),
    };
    Ok(TableDiff {
        table: ha.table_id.name(),
        fields,
        alignment_rotation_arcsec,
        iru_max_g_change_ppm,
    })
}

/// Encode any table after validating it, and check the image parses back to the same table.
///
/// # Errors
/// [`TableToolError::Invalid`] if the OBC would reject the content; [`TableToolError::Image`]
/// if encoding fails.
pub fn write_image(table: &AnyTable, created: TimeTag) -> Result<Vec<u8>, TableToolError> {
    table.validate().map_err(|e| TableToolError::Invalid {
        detail: e.to_string(),
    })?;
    let mut buf = vec![0u8; MAX_IMAGE_BYTES];
    let encoded = match table {
        AnyTable::Alignment(t) => encode_image(TableId::Alignment, created, t, &mut buf),
        AnyTable::Iru(t) => encode_image(TableId::Iru, created, t, &mut buf),
        AnyTable::Filter(t) => encode_image(TableId::Filter, created, t, &mut buf),
        AnyTable::StarCatalog(t) => {
            encode_image(TableId::StarCatalog, created, t.as_ref(), &mut buf)
        }
        AnyTable::Orbit(t) => encode_image(TableId::Orbit, created, t, &mut buf),
        AnyTable::Magnetics(t) => encode_image(TableId::Magnetics, created, t.as_ref(), &mut buf),
    };
    let len = encoded.map_err(|e| TableToolError::Image {
        what: "new image".into(),
        detail: e.to_string(),
    })?;
    buf.truncate(len);
    let (_, back) = decode_image(&buf, "new image")?;
    if &back != table {
        return Err(TableToolError::Image {
            what: "new image".into(),
            detail: "does not decode to the table written".into(),
        });
    }
    Ok(buf)
}

/// Alignment table from four `M_AS` (FHST1, FHST2, FSS1, FSS2), no corrections.
#[must_use]
pub fn alignment_table(
    m_acs_from_sensor: &[Matrix3<f64>; 4],
    corrections: SensorCorrections,
) -> AlignmentTable {
    AlignmentTable {
        m_acs_from_fhst1: rows_from_matrix(&m_acs_from_sensor[0]),
        m_acs_from_fhst2: rows_from_matrix(&m_acs_from_sensor[1]),
        m_acs_from_fss1: rows_from_matrix(&m_acs_from_sensor[2]),
        m_acs_from_fss2: rows_from_matrix(&m_acs_from_sensor[3]),
        corrections,
    }
}

/// Creation time of the paper's alignment uplink, 1991-05-14 00:00 UTC, as seconds since
/// 1958-01-01 TAI (12 186 days + TAI − UTC = 26 s in 1991).
pub const PAPER_UPLINK_TAI_S: u32 = 1_052_870_426;

/// The alignment table the paper uplinked on 1991-05-14: `M_AS'' = M_AS M_SS''` (Table 1 ×
/// Table 2), orthonormalised (the printed 8 digits leave 3e-7 of non-orthogonality).
///
/// # Errors
/// Only if the embedded paper data are incomplete.
pub fn paper_alignment_table() -> Result<AlignmentTable, crate::paper::PaperError> {
    let p = crate::paper::PaperData::embedded()?;
    let mut m = [Matrix3::identity(); 4];
    for (slot, id) in m.iter_mut().zip(ALIGNMENT_SENSORS) {
        let missing = || crate::paper::PaperError::Missing(format!("tables 1/2 for {id}"));
        let pre = p.prelaunch(id).ok_or_else(missing)?;
        let mis = p.misalignment(id).ok_or_else(missing)?;
        *slot = crate::paper::nearest_rotation(&(pre * mis));
    }
    Ok(alignment_table(&m, SensorCorrections::default()))
}

/// Read a file.
///
/// # Errors
/// [`TableToolError::Io`].
pub fn read_file(path: &Path) -> Result<Vec<u8>, TableToolError> {
    std::fs::read(path).map_err(|source| TableToolError::Io {
        path: path.display().to_string(),
        source,
    })
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    fn tag() -> TimeTag {
        TimeTag {
            coarse_s: PAPER_UPLINK_TAI_S,
            fine: 0,
        }
    }

    /// A layout-1 magnetics image (fields 0–18, before the unloading fields), which the OBC
    /// accepts, is read by the ground's tools too, with the unloading fields at boot.
    #[test]
    fn layout1_magnetics_images_are_read_as_the_obc_reads_them() {
        let mut t = fsw_core::tables::MagneticsTable::boot();
        t.tam_bias_milligauss[0] = [0.0, 0.0, -4.0];
        let old = fsw_core::tables::magnetics::MagneticsTableLayout1::from_table(&t);
        let mut buf = vec![0u8; 8192];
        let n = encode_image(TableId::Magnetics, tag(), &old, &mut buf).unwrap();
        let (_, read) = decode_image(&buf[..n], "layout-1 test image").unwrap();
        let AnyTable::Magnetics(read) = read else {
            panic!("not a magnetics table")
        };
        assert_eq!(*read, t);
    }

    /// The paper's uplinked alignment table round-trips through the fsw-core image format,
    /// and its rotations from the boot table are the paper's (|θ| FSS1 ≈ 733″).
    #[test]
    fn val_table_paper_alignment_image_round_trip() {
        let t = AnyTable::Alignment(paper_alignment_table().unwrap());
        let img = write_image(&t, tag()).unwrap();
        let ins = inspect(&img, "paper").unwrap();
        assert_eq!(ins.table, "alignment");
        assert!(ins.validation_error.is_none());
        let rot = ins.rotation_from_prelaunch_arcsec.unwrap();
        assert!((rot[2].2 - 733.0).abs() < 1.0, "{:?}", rot[2]);
        assert_eq!(ins.created_tai_s, f64::from(PAPER_UPLINK_TAI_S));
    }

    #[test]
    fn table_diff_and_rejections() {
        let boot = write_image(&AnyTable::Alignment(AlignmentTable::prelaunch()), tag()).unwrap();
        let paper = write_image(
            &AnyTable::Alignment(paper_alignment_table().unwrap()),
            tag(),
        )
        .unwrap();
        let d = diff(&boot, &paper).unwrap();
        assert!(!d.fields.is_empty());
        assert!(d.fields.iter().all(|f| f.path.starts_with(".m_acs_from")));
        let rot = d.alignment_rotation_arcsec.unwrap();
        assert!((rot[3].2 - 189.0).abs() < 1.0);
        assert!(diff(&boot, &boot).unwrap().fields.is_empty());
        // different tables
        let iru = write_image(&AnyTable::Iru(IruTable::prelaunch()), tag()).unwrap();
        assert!(matches!(
            diff(&boot, &iru),
            Err(TableToolError::DifferentTables { .. })
        ));
        // damaged image (CRC)
        let mut bad = boot.clone();
        bad[25] ^= 0x40;
        assert!(matches!(
            inspect(&bad, "bad"),
            Err(TableToolError::Image { .. })
        ));
        // non-rotation is refused before encoding
        let mut t = AlignmentTable::prelaunch();
        t.m_acs_from_fss1[0][0] += 1e-3;
        assert!(matches!(
            write_image(&AnyTable::Alignment(t), tag()),
            Err(TableToolError::Invalid { .. })
        ));
    }
}
