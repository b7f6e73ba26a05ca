//! # The downlink's field layout as data (docs/icd.md §3)
//!
//! Why: outside ground systems (Yamcs, OpenC3 COSMOS, cFS tools) read telemetry from a
//! machine-readable packet description (an XTCE mission database, a `ccsdspy` layout), not
//! from a Markdown table. This module states every field of every APID once, as data: name,
//! octet offset in the user data (after the 6-octet CUC time code), type, unit and meaning.
//! The host tool generates XTCE and `ccsdspy` files from it (`ground-tool icd`).
//!
//! The bytes themselves are written and read by the encoders and decoders of
//! [`crate::telemetry`]; the `visit_*` functions here give a decoded record's values in the
//! layout's field order. A test encodes records whose every field differs and reads each field
//! back at its layout offset, so the layout, the encoders and the visitors cannot drift apart.
//! Flag octets are single `u8` fields (their bits are described in the field's meaning).

use crate::events::Event;
use crate::raw::RawSensorFrame;
use crate::telemetry::{
    EphemerisRecord, MagneticsFrame, ObcHousekeeping, WheelFrame, APID_EPHEMERIS, APID_EVENT,
    APID_HOUSEKEEPING, APID_MAGNETICS, APID_RAW_SENSORS, APID_WHEELS, EPHEMERIS_LEN, EVENT_LEN,
    HOUSEKEEPING_LEN, MAGNETICS_LEN, RAW_FRAME_LEN, WHEEL_FRAME_LEN,
};

/// A field's wire type (big-endian; floats IEEE-754).
/// docs/icd.md §2 (all multi-octet fields big-endian).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FieldType {
    /// Unsigned 8-bit integer.
    /// docs/icd.md §2.
    U8,
    /// Unsigned 16-bit integer.
    /// docs/icd.md §2.
    U16,
    /// Two's-complement 16-bit integer.
    /// docs/icd.md §2.
    I16,
    /// Unsigned 32-bit integer.
    /// docs/icd.md §2.
    U32,
    /// IEEE-754 binary32.
    /// docs/icd.md §2.
    F32,
    /// IEEE-754 binary64.
    /// docs/icd.md §2.
    F64,
}

impl FieldType {
    /// Size in octets.
    /// docs/icd.md §2.
    #[must_use]
    pub const fn octets(self) -> usize {
        match self {
            Self::U8 => 1,
            Self::U16 | Self::I16 => 2,
            Self::U32 | Self::F32 => 4,
            Self::F64 => 8,
        }
    }
}

/// One field of a record.
/// docs/icd.md §3.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Field {
    /// Name (lower snake case, unique in its packet; unit suffix where it has one).
    /// docs/icd.md §3 (the field column).
    pub name: &'static str,
    /// Octet offset in the user data (after the 6-octet time code).
    /// docs/icd.md §3 (the offset column).
    pub offset: usize,
    /// Wire type.
    /// docs/icd.md §3 (the type column).
    pub ty: FieldType,
    /// Unit ("" when dimensionless or a code).
    /// docs/icd.md §3 (the unit column).
    pub unit: &'static str,
    /// Meaning, as in the ICD.
    /// docs/icd.md §3.
    pub meaning: &'static str,
}

/// One packet type: its APID, name, user-data length and fields.
/// docs/icd.md §3.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PacketLayout {
    /// APID.
    /// docs/icd.md §2 (primary header).
    pub apid: u16,
    /// Name of the record.
    /// docs/icd.md §3 (section titles).
    pub name: &'static str,
    /// User-data length, octets (after the time code).
    /// docs/icd.md §2 (fixed per APID).
    pub user_data_len: usize,
    /// Fields in wire order.
    /// docs/icd.md §3.
    pub fields: &'static [Field],
}

/// A decoded field value.
/// docs/icd.md §3 (types of §2).
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum FieldValue {
    /// Unsigned integer.
    /// docs/icd.md §2.
    Unsigned(u64),
    /// Signed integer.
    /// docs/icd.md §2.
    Signed(i64),
    /// Float (a binary32 field widened exactly).
    /// docs/icd.md §2.
    Float(f64),
}

const fn f(
    name: &'static str,
    offset: usize,
    ty: FieldType,
    unit: &'static str,
    meaning: &'static str,
) -> Field {
    Field {
        name,
        offset,
        ty,
        unit,
        meaning,
    }
}

use FieldType::{F32, F64, I16, U16, U32, U8};

const FHST_FLAGS: &str =
    "bit0 data valid, bit1 tracking, bit2 new star; used only with bit0 and bit1 set";
const FSS_FLAGS: &str =
    "bit0 Sun on the alpha head, bit1 Sun on the beta head; used only with both set";

/// APID 0x010, raw sensor frame: the fields of docs/icd.md §3.1.
/// docs/icd.md §3.1.
pub const RAW_FRAME_FIELDS: [Field; 27] = [
    f("iru_count_x1", 0, U16, "pulse", "IRU accumulated pulse counter X1, wrapping"),
    f("iru_count_x2", 2, U16, "pulse", "IRU accumulated pulse counter X2, wrapping"),
    f("iru_count_y1", 4, U16, "pulse", "IRU accumulated pulse counter Y1, wrapping"),
    f("iru_count_y2", 6, U16, "pulse", "IRU accumulated pulse counter Y2, wrapping"),
    f("iru_count_z1", 8, U16, "pulse", "IRU accumulated pulse counter Z1, wrapping"),
    f("iru_count_z2", 10, U16, "pulse", "IRU accumulated pulse counter Z2, wrapping"),
    f("iru_bit_failed", 12, U8, "", "IRU channel BIT failure bits, bit i = channel i (X1=0 .. Z2=5)"),
    f("iru_rate_mode", 13, U8, "", "rate mode of the interval that ended at this sample: 0 low (0.05 arcsec/pulse), 1 high (0.8)"),
    f("fhst1_h_counts", 14, I16, "7.78 arcsec", "FHST1 H, 0 on the boresight"),
    f("fhst1_v_counts", 16, I16, "7.78 arcsec", "FHST1 V"),
    f("fhst1_magnitude_centimag", 18, I16, "0.01 mag", "FHST1 instrument magnitude"),
    f("fhst1_flags", 20, U8, "", FHST_FLAGS),
    f("fhst2_h_counts", 21, I16, "7.78 arcsec", "FHST2 H, 0 on the boresight"),
    f("fhst2_v_counts", 23, I16, "7.78 arcsec", "FHST2 V"),
    f("fhst2_magnitude_centimag", 25, I16, "0.01 mag", "FHST2 instrument magnitude"),
    f("fhst2_flags", 27, U8, "", FHST_FLAGS),
    f("fss1_alpha_counts", 28, I16, "0.004 deg", "FSS1 alpha, 0 on the boresight"),
    f("fss1_beta_counts", 30, I16, "0.004 deg", "FSS1 beta"),
    f("fss1_flags", 32, U8, "", FSS_FLAGS),
    f("fss2_alpha_counts", 33, I16, "0.004 deg", "FSS2 alpha, 0 on the boresight"),
    f("fss2_beta_counts", 35, I16, "0.004 deg", "FSS2 beta"),
    f("fss2_flags", 37, U8, "", FSS_FLAGS),
    f("temperature_fhst1_centi_c", 38, I16, "0.01 degC", "FHST1 temperature"),
    f("temperature_fhst2_centi_c", 40, I16, "0.01 degC", "FHST2 temperature"),
    f("temperature_fss1_centi_c", 42, I16, "0.01 degC", "FSS1 temperature"),
    f("temperature_fss2_centi_c", 44, I16, "0.01 degC", "FSS2 temperature"),
    f("temperature_iru_centi_c", 46, I16, "0.01 degC", "IRU baseplate temperature"),
];

const RES_STATUS: &str = "0 none, 1 accepted, 2 gated out, 3 rejected by input validation, 4 star not identified, 5 valid but not used";

/// APID 0x011, OBC housekeeping: the fields of docs/icd.md §3.2.
/// docs/icd.md §3.2.
pub const HOUSEKEEPING_FIELDS: [Field; 52] = [
    f(
        "q_acs_from_eci_x",
        0,
        F64,
        "",
        "attitude quaternion q_acs_from_eci, x",
    ),
    f("q_acs_from_eci_y", 8, F64, "", "attitude quaternion, y"),
    f("q_acs_from_eci_z", 16, F64, "", "attitude quaternion, z"),
    f(
        "q_acs_from_eci_w",
        24,
        F64,
        "",
        "attitude quaternion, w (scalar)",
    ),
    f(
        "bias_acs_x_rad_per_s",
        32,
        F64,
        "rad/s",
        "gyro bias estimate in ACS, x",
    ),
    f(
        "bias_acs_y_rad_per_s",
        40,
        F64,
        "rad/s",
        "gyro bias estimate in ACS, y",
    ),
    f(
        "bias_acs_z_rad_per_s",
        48,
        F64,
        "rad/s",
        "gyro bias estimate in ACS, z",
    ),
    f(
        "cov_dtheta_x_rad2",
        56,
        F64,
        "rad^2",
        "covariance diagonal, attitude error x",
    ),
    f(
        "cov_dtheta_y_rad2",
        64,
        F64,
        "rad^2",
        "covariance diagonal, attitude error y",
    ),
    f(
        "cov_dtheta_z_rad2",
        72,
        F64,
        "rad^2",
        "covariance diagonal, attitude error z",
    ),
    f(
        "cov_dbias_x_rad2_per_s2",
        80,
        F64,
        "(rad/s)^2",
        "covariance diagonal, bias error x",
    ),
    f(
        "cov_dbias_y_rad2_per_s2",
        88,
        F64,
        "(rad/s)^2",
        "covariance diagonal, bias error y",
    ),
    f(
        "cov_dbias_z_rad2_per_s2",
        96,
        F64,
        "(rad/s)^2",
        "covariance diagonal, bias error z",
    ),
    f(
        "filter_mode",
        104,
        U8,
        "",
        "0 uninitialised, 1 coarse (FSS), 2 fine (FHST)",
    ),
    f(
        "control_mode",
        105,
        U8,
        "",
        "0 idle, 1 inertial hold, 2 slew, 3 Sun acquisition",
    ),
    f("iru_config", 106, U8, "", "0 primary, 1 backup"),
    f(
        "iru_high_rate_cmd",
        107,
        U8,
        "",
        "IRU rate mode commanded at this cycle: 0 low, 1 high",
    ),
    f(
        "wheel_torque_acs_x_nm",
        108,
        F32,
        "N m",
        "wheel torque command in ACS, x",
    ),
    f(
        "wheel_torque_acs_y_nm",
        112,
        F32,
        "N m",
        "wheel torque command in ACS, y",
    ),
    f(
        "wheel_torque_acs_z_nm",
        116,
        F32,
        "N m",
        "wheel torque command in ACS, z",
    ),
    f("fhst1_residual_status", 120, U8, "", RES_STATUS),
    f(
        "fhst1_innovation_h_arcsec",
        121,
        F32,
        "arcsec",
        "FHST1 innovation, measured - predicted, H",
    ),
    f(
        "fhst1_innovation_v_arcsec",
        125,
        F32,
        "arcsec",
        "FHST1 innovation, V",
    ),
    f(
        "fhst1_star_hip",
        129,
        U32,
        "",
        "FHST1 identified star (Hipparcos number), 0 none",
    ),
    f("fhst2_residual_status", 133, U8, "", RES_STATUS),
    f(
        "fhst2_innovation_h_arcsec",
        134,
        F32,
        "arcsec",
        "FHST2 innovation, measured - predicted, H",
    ),
    f(
        "fhst2_innovation_v_arcsec",
        138,
        F32,
        "arcsec",
        "FHST2 innovation, V",
    ),
    f(
        "fhst2_star_hip",
        142,
        U32,
        "",
        "FHST2 identified star (Hipparcos number), 0 none",
    ),
    f("fss1_residual_status", 146, U8, "", RES_STATUS),
    f(
        "fss1_innovation_alpha_arcsec",
        147,
        F32,
        "arcsec",
        "FSS1 innovation, measured - predicted, alpha",
    ),
    f(
        "fss1_innovation_beta_arcsec",
        151,
        F32,
        "arcsec",
        "FSS1 innovation, beta",
    ),
    f("fss1_star_hip", 155, U32, "", "always 0 for an FSS"),
    f("fss2_residual_status", 159, U8, "", RES_STATUS),
    f(
        "fss2_innovation_alpha_arcsec",
        160,
        F32,
        "arcsec",
        "FSS2 innovation, measured - predicted, alpha",
    ),
    f(
        "fss2_innovation_beta_arcsec",
        164,
        F32,
        "arcsec",
        "FSS2 innovation, beta",
    ),
    f("fss2_star_hip", 168, U32, "", "always 0 for an FSS"),
    f(
        "iru_excluded_mask",
        172,
        U8,
        "",
        "IRU channels excluded, bit i = channel i",
    ),
    f("count_cycles", 173, U32, "", "cycles since boot"),
    f(
        "count_rejected_inputs",
        177,
        U32,
        "",
        "inputs rejected by validation since boot",
    ),
    f(
        "count_gated_measurements",
        181,
        U32,
        "",
        "measurements gated out since boot",
    ),
    f(
        "count_accepted_measurements",
        185,
        U32,
        "",
        "measurements accepted since boot",
    ),
    f(
        "count_stars_identified",
        189,
        U32,
        "",
        "stars identified since boot",
    ),
    f(
        "count_star_id_unmatched",
        193,
        U32,
        "",
        "star identifications with no match since boot",
    ),
    f(
        "count_star_id_ambiguous",
        197,
        U32,
        "",
        "ambiguous star identifications since boot",
    ),
    f(
        "count_time_tag_anomalies",
        201,
        U32,
        "",
        "time-tag anomalies since boot",
    ),
    f(
        "count_iru_unusable_cycles",
        205,
        U32,
        "",
        "cycles with unusable IRU data since boot",
    ),
    f(
        "count_events_dropped",
        209,
        U32,
        "",
        "events dropped since boot",
    ),
    f(
        "crc_alignment_table",
        213,
        U32,
        "",
        "CRC-32 of the active alignment table image, 0 boot",
    ),
    f(
        "crc_iru_table",
        217,
        U32,
        "",
        "CRC-32 of the active IRU table image, 0 boot",
    ),
    f(
        "crc_filter_table",
        221,
        U32,
        "",
        "CRC-32 of the active filter table image, 0 boot",
    ),
    f(
        "crc_star_catalog_table",
        225,
        U32,
        "",
        "CRC-32 of the active star-catalog table image, 0 boot",
    ),
    f(
        "table_pending_mask",
        229,
        U8,
        "",
        "tables with a validated image pending, bit i = table id i+1",
    ),
];

/// APID 0x012, event: the fields of docs/icd.md §3.3.
/// docs/icd.md §3.3.
pub const EVENT_FIELDS: [Field; 3] = [
    f(
        "event_code",
        0,
        U16,
        "",
        "event code (docs/icd.md §3.3 table)",
    ),
    f("parameter_1", 2, U32, "", "parameter 1"),
    f("parameter_2", 6, U32, "", "parameter 2"),
];

const TAM_FLAGS: &str = "bit0 valid (the three field words hold a measurement); 0 = no data; bit1 torquer bars on while sampled (ICD version 3)";
const CSS_FLAGS: &str = "bit0 valid (the six eye words hold a measurement); 0 = no data";

/// APID 0x013, magnetics frame: the fields of docs/icd.md §3.5.
/// docs/icd.md §3.5.
pub const MAGNETICS_FIELDS: [Field; 15] = [
    f(
        "tam1_x_counts",
        0,
        I16,
        "TAM count",
        "TAM1 (primary) field along its X axis; mG per count in the TAM table (0.3 as flown)",
    ),
    f(
        "tam1_y_counts",
        2,
        I16,
        "TAM count",
        "TAM1 field along its Y axis",
    ),
    f(
        "tam1_z_counts",
        4,
        I16,
        "TAM count",
        "TAM1 field along its Z axis",
    ),
    f("tam1_flags", 6, U8, "", TAM_FLAGS),
    f(
        "tam2_x_counts",
        7,
        I16,
        "TAM count",
        "TAM2 field along its X axis",
    ),
    f(
        "tam2_y_counts",
        9,
        I16,
        "TAM count",
        "TAM2 field along its Y axis",
    ),
    f(
        "tam2_z_counts",
        11,
        I16,
        "TAM count",
        "TAM2 field along its Z axis",
    ),
    f("tam2_flags", 13, U8, "", TAM_FLAGS),
    f(
        "css_plus_x_counts",
        14,
        U16,
        "CSS count",
        "coarse Sun sensor eye on +X of ACS",
    ),
    f("css_minus_x_counts", 16, U16, "CSS count", "CSS eye on -X"),
    f("css_plus_y_counts", 18, U16, "CSS count", "CSS eye on +Y"),
    f("css_minus_y_counts", 20, U16, "CSS count", "CSS eye on -Y"),
    f("css_plus_z_counts", 22, U16, "CSS count", "CSS eye on +Z"),
    f("css_minus_z_counts", 24, U16, "CSS count", "CSS eye on -Z"),
    f("css_flags", 26, U8, "", CSS_FLAGS),
];

const SPEED_VALID: &str =
    "bit i set: wheel i+1's tachometer word holds a measurement (bits 0-3); 0 = no tachometers";
const DIPOLE_VALID: &str =
    "bit k set: bar k+1's current-monitor word holds a measurement (bits 0-2); 0 = no monitors";

/// APID 0x014, wheel frame: the fields of docs/icd.md §3.6.
/// docs/icd.md §3.6.
pub const WHEEL_FIELDS: [Field; 9] = [
    f(
        "wheel1_speed_counts",
        0,
        I16,
        "0.1 rpm",
        "reaction wheel 1 speed about its spin axis (tachometer); +-32767 and -32768 saturated",
    ),
    f("wheel2_speed_counts", 2, I16, "0.1 rpm", "wheel 2 speed"),
    f("wheel3_speed_counts", 4, I16, "0.1 rpm", "wheel 3 speed"),
    f("wheel4_speed_counts", 6, I16, "0.1 rpm", "wheel 4 speed"),
    f("wheel_speed_valid", 8, U8, "", SPEED_VALID),
    f(
        "bar_x_dipole_counts",
        9,
        I16,
        "A m^2",
        "torquer bar along ACS x: dipole carried over the interval that ended at the sample (current monitor)",
    ),
    f("bar_y_dipole_counts", 11, I16, "A m^2", "bar along ACS y"),
    f("bar_z_dipole_counts", 13, I16, "A m^2", "bar along ACS z"),
    f("bar_dipole_valid", 15, U8, "", DIPOLE_VALID),
];

/// APID 0x020, definitive orbit: the fields of docs/icd.md §3.4.
/// docs/icd.md §3.4.
pub const EPHEMERIS_FIELDS: [Field; 6] = [
    f("pos_eci_x_km", 0, F64, "km", "position, J2000/GCRS, x"),
    f("pos_eci_y_km", 8, F64, "km", "position, y"),
    f("pos_eci_z_km", 16, F64, "km", "position, z"),
    f(
        "vel_eci_x_km_per_s",
        24,
        F64,
        "km/s",
        "velocity, J2000/GCRS, x",
    ),
    f("vel_eci_y_km_per_s", 32, F64, "km/s", "velocity, y"),
    f("vel_eci_z_km_per_s", 40, F64, "km/s", "velocity, z"),
];

/// Every packet type of the downlink, in APID order.
/// docs/icd.md §3.
pub const PACKETS: [PacketLayout; 6] = [
    PacketLayout {
        apid: APID_RAW_SENSORS,
        name: "raw_sensor_frame",
        user_data_len: RAW_FRAME_LEN,
        fields: &RAW_FRAME_FIELDS,
    },
    PacketLayout {
        apid: APID_HOUSEKEEPING,
        name: "obc_housekeeping",
        user_data_len: HOUSEKEEPING_LEN,
        fields: &HOUSEKEEPING_FIELDS,
    },
    PacketLayout {
        apid: APID_EVENT,
        name: "event",
        user_data_len: EVENT_LEN,
        fields: &EVENT_FIELDS,
    },
    PacketLayout {
        apid: APID_MAGNETICS,
        name: "magnetics_frame",
        user_data_len: MAGNETICS_LEN,
        fields: &MAGNETICS_FIELDS,
    },
    PacketLayout {
        apid: APID_WHEELS,
        name: "wheel_frame",
        user_data_len: WHEEL_FRAME_LEN,
        fields: &WHEEL_FIELDS,
    },
    PacketLayout {
        apid: APID_EPHEMERIS,
        name: "definitive_orbit",
        user_data_len: EPHEMERIS_LEN,
        fields: &EPHEMERIS_FIELDS,
    },
];

/// A raw sensor frame's values in [`RAW_FRAME_FIELDS`] order.
/// docs/icd.md §3.1.
pub fn visit_raw_frame<F: FnMut(FieldValue) + ?Sized>(r: &RawSensorFrame, out: &mut F) {
    use FieldValue::{Signed, Unsigned};
    for c in r.iru.counts {
        out(Unsigned(u64::from(c)));
    }
    out(Unsigned(u64::from(r.iru.channel_failed)));
    out(Unsigned(u64::from(r.iru.high_rate)));
    for t in &r.fhst {
        out(Signed(i64::from(t.h_counts)));
        out(Signed(i64::from(t.v_counts)));
        out(Signed(i64::from(t.magnitude_centimag)));
        out(Unsigned(u64::from(t.flags)));
    }
    for s in &r.fss {
        out(Signed(i64::from(s.alpha_counts)));
        out(Signed(i64::from(s.beta_counts)));
        out(Unsigned(u64::from(s.flags)));
    }
    for t in r.temperatures_centi_c {
        out(Signed(i64::from(t)));
    }
}

/// A housekeeping record's values in [`HOUSEKEEPING_FIELDS`] order.
/// docs/icd.md §3.2.
pub fn visit_housekeeping<F: FnMut(FieldValue) + ?Sized>(h: &ObcHousekeeping, out: &mut F) {
    use FieldValue::{Float, Unsigned};
    for q in [
        h.q_acs_from_eci.x,
        h.q_acs_from_eci.y,
        h.q_acs_from_eci.z,
        h.q_acs_from_eci.w,
    ] {
        out(Float(q));
    }
    for x in h.bias_acs_rad_per_s.iter().chain(&h.covariance_diag) {
        out(Float(*x));
    }
    for m in [
        h.filter_mode,
        h.control_mode,
        h.iru_config,
        h.iru_high_rate_cmd,
    ] {
        out(Unsigned(u64::from(m)));
    }
    for t in h.wheel_torque_cmd_nm {
        out(Float(f64::from(t)));
    }
    for r in &h.residuals {
        out(Unsigned(u64::from(r.status as u8)));
        out(Float(f64::from(r.innovation_arcsec[0])));
        out(Float(f64::from(r.innovation_arcsec[1])));
        out(Unsigned(u64::from(r.star_id)));
    }
    out(Unsigned(u64::from(h.iru_excluded_mask)));
    for n in h.counters.wire_order() {
        out(Unsigned(u64::from(n)));
    }
    for crc in h.table_crc {
        out(Unsigned(u64::from(crc)));
    }
    out(Unsigned(u64::from(h.table_pending_mask)));
}

/// An event's values in [`EVENT_FIELDS`] order.
/// docs/icd.md §3.3.
pub fn visit_event<F: FnMut(FieldValue) + ?Sized>(e: &Event, out: &mut F) {
    out(FieldValue::Unsigned(u64::from(e.id.code())));
    out(FieldValue::Unsigned(u64::from(e.p1)));
    out(FieldValue::Unsigned(u64::from(e.p2)));
}

/// A magnetics frame's values in [`MAGNETICS_FIELDS`] order.
/// docs/icd.md §3.5.
pub fn visit_magnetics<F: FnMut(FieldValue) + ?Sized>(m: &MagneticsFrame, out: &mut F) {
    use FieldValue::{Signed, Unsigned};
    for t in &m.tam {
        for c in t.field_counts {
            out(Signed(i64::from(c)));
        }
        out(Unsigned(u64::from(t.flags)));
    }
    for c in m.css.counts {
        out(Unsigned(u64::from(c)));
    }
    out(Unsigned(u64::from(m.css.flags)));
}

/// A wheel frame's values in [`WHEEL_FIELDS`] order.
/// docs/icd.md §3.6.
pub fn visit_wheels<F: FnMut(FieldValue) + ?Sized>(w: &WheelFrame, out: &mut F) {
    use FieldValue::{Signed, Unsigned};
    for c in w.wheels.speed_counts {
        out(Signed(i64::from(c)));
    }
    out(Unsigned(u64::from(w.wheels.speed_valid)));
    for c in w.wheels.dipole_counts {
        out(Signed(i64::from(c)));
    }
    out(Unsigned(u64::from(w.wheels.dipole_valid)));
}

/// An orbit record's values in [`EPHEMERIS_FIELDS`] order.
/// docs/icd.md §3.4.
pub fn visit_ephemeris<F: FnMut(FieldValue) + ?Sized>(e: &EphemerisRecord, out: &mut F) {
    for x in e.pos_eci_km.iter().chain(&e.vel_eci_km_per_s) {
        out(FieldValue::Float(*x));
    }
}

#[cfg(test)]
mod tests {
    #![allow(
        clippy::unwrap_used,
        clippy::indexing_slicing,
        clippy::arithmetic_side_effects
    )]
    use super::*;
    use crate::events::{Counters, EventId};
    use crate::raw::{
        CssSample, FhstSample, FssSample, IruSample, TamSample, TimeTag, WheelSample,
    };
    use crate::telemetry::{
        encode_ephemeris, encode_event, encode_housekeeping, encode_magnetics, encode_raw_frame,
        encode_wheels, MeasurementStatus, SensorResidual,
    };

    /// The value at a field's offset, read from the encoded user data by its type alone.
    fn read(data: &[u8], fl: &Field) -> FieldValue {
        let b = &data[fl.offset..fl.offset + fl.ty.octets()];
        match fl.ty {
            FieldType::U8 => FieldValue::Unsigned(u64::from(b[0])),
            FieldType::U16 => FieldValue::Unsigned(u64::from(u16::from_be_bytes([b[0], b[1]]))),
            FieldType::I16 => FieldValue::Signed(i64::from(i16::from_be_bytes([b[0], b[1]]))),
            FieldType::U32 => {
                FieldValue::Unsigned(u64::from(u32::from_be_bytes([b[0], b[1], b[2], b[3]])))
            }
            FieldType::F32 => {
                FieldValue::Float(f64::from(f32::from_be_bytes([b[0], b[1], b[2], b[3]])))
            }
            FieldType::F64 => FieldValue::Float(f64::from_be_bytes(b.try_into().unwrap())),
        }
    }

    /// Layout, encoder and visitor agree on every field, and the fields tile the record.
    fn check(layout: &PacketLayout, encoded: &[u8], values: &[FieldValue]) {
        assert_eq!(encoded.len(), layout.user_data_len, "{}", layout.name);
        let mut end = 0;
        for fl in layout.fields {
            assert_eq!(
                fl.offset, end,
                "{}: {} does not follow its predecessor",
                layout.name, fl.name
            );
            end = fl.offset + fl.ty.octets();
        }
        assert_eq!(
            end, layout.user_data_len,
            "{}: fields do not fill the record",
            layout.name
        );
        assert_eq!(values.len(), layout.fields.len(), "{}", layout.name);
        let mut seen = std::collections::BTreeSet::new();
        for (fl, v) in layout.fields.iter().zip(values) {
            assert!(seen.insert(fl.name), "{}: {} twice", layout.name, fl.name);
            assert_eq!(read(encoded, fl), *v, "{}: {}", layout.name, fl.name);
        }
    }

    extern crate std;
    use std::vec::Vec;

    fn values(visit: impl FnOnce(&mut dyn FnMut(FieldValue))) -> Vec<FieldValue> {
        let mut v = Vec::new();
        visit(&mut |x| v.push(x));
        v
    }

    /// The time code of every test record.
    const TIME: TimeTag = TimeTag {
        coarse_s: 1,
        fine: 2,
    };

    /// Encode `rec`, then [`check`] it against layout `k` of [`PACKETS`] and its visitor.
    fn check_record<R>(
        k: usize,
        rec: &R,
        encode: impl Fn(&R, &mut [u8]) -> Result<usize, crate::telemetry::RecordError>,
        visit: impl Fn(&R, &mut dyn FnMut(FieldValue)),
    ) {
        let mut buf = [0u8; 256];
        let n = encode(rec, &mut buf).unwrap();
        check(&PACKETS[k], &buf[..n], &values(|out| visit(rec, out)));
    }

    #[test]
    fn every_field_sits_where_the_layout_says() {
        // Every field a different value, so a swapped or shifted field cannot pass.
        let mut k = 0u16;
        let mut next = || {
            k += 1;
            k
        };
        let raw = RawSensorFrame {
            time: TIME,
            iru: IruSample {
                counts: [next(), next(), next(), next(), next(), 65535],
                channel_failed: 0b10_1010,
                high_rate: true,
            },
            fhst: [0, 1].map(|i| FhstSample {
                h_counts: -100 - i,
                v_counts: 200 + i,
                magnitude_centimag: 350 + i,
                flags: 3 + 4 * i as u8,
            }),
            fss: [0, 1].map(|i| FssSample {
                alpha_counts: -7000 + i,
                beta_counts: 6000 + i,
                flags: 1 + 2 * i as u8,
            }),
            temperatures_centi_c: [2001, -2002, 2003, 2004, -2005],
            tam: Default::default(),
            css: Default::default(),
            wheels: WheelSample::default(),
        };
        check_record(0, &raw, encode_raw_frame, |r, out| visit_raw_frame(r, out));

        let statuses = [
            MeasurementStatus::Accepted,
            MeasurementStatus::Gated,
            MeasurementStatus::Rejected,
            MeasurementStatus::NotUsed,
        ];
        let hk = ObcHousekeeping {
            time: TIME,
            q_acs_from_eci: crate::attitude::Quat {
                x: 0.1,
                y: -0.2,
                z: 0.3,
                w: 0.9,
            },
            bias_acs_rad_per_s: [1e-6, -2e-6, 3e-6],
            covariance_diag: [1e-9, 2e-9, 3e-9, 4e-15, 5e-15, 6e-15],
            filter_mode: 2,
            control_mode: 5,
            iru_config: 1,
            iru_high_rate_cmd: 7,
            wheel_torque_cmd_nm: [0.25, -0.5, 0.125],
            residuals: [0, 1, 2, 3].map(|i| SensorResidual {
                status: statuses[i],
                innovation_arcsec: [1.5 + i as f32, -2.25 - i as f32],
                star_id: 1000 + i as u32,
            }),
            iru_excluded_mask: 0b100,
            counters: Counters {
                cycles: 11,
                rejected_inputs: 12,
                gated_measurements: 13,
                accepted_measurements: 14,
                stars_identified: 15,
                star_id_unmatched: 16,
                star_id_ambiguous: 17,
                time_tag_anomalies: 18,
                iru_unusable_cycles: 19,
                events_dropped: 20,
            },
            table_crc: [0xDEAD_BEEF, 2, 3, 0xFFFF_FFFF],
            table_pending_mask: 0b1010,
        };
        check_record(1, &hk, encode_housekeeping, |r, out| {
            visit_housekeeping(r, out)
        });

        let ev = Event {
            id: EventId::TableActivated,
            p1: 3,
            p2: 0xCAFE_F00D,
        };
        check_record(2, &ev, encode_event, |r, out| visit_event(r, out));

        let mag = MagneticsFrame {
            time: TIME,
            tam: [0i16, 1].map(|i| TamSample {
                field_counts: [-1000 - i, 1100 + i, -1200 - 3 * i],
                flags: 1 + 2 * i as u8,
            }),
            css: CssSample {
                counts: [10, 20, 30, 40, 50, 65535],
                flags: 5,
            },
        };
        check_record(3, &mag, encode_magnetics, |r, out| visit_magnetics(r, out));

        let wheels = WheelFrame {
            time: TIME,
            wheels: WheelSample {
                speed_counts: [-29_000, 1, 2, 32_767],
                speed_valid: 0x0E,
                dipole_counts: [-4_000, 3, 4_000],
                dipole_valid: 0x05,
            },
        };
        check_record(4, &wheels, encode_wheels, |r, out| visit_wheels(r, out));

        let eph = EphemerisRecord {
            time: TIME,
            pos_eci_km: [6800.5, -10.25, 3.0],
            vel_eci_km_per_s: [0.1, 7.5, -0.3],
        };
        check_record(5, &eph, encode_ephemeris, |r, out| visit_ephemeris(r, out));
    }
}
