//! # Table services: load → validate → activate, like cFE Table Services
//!
//! Each table has an *active* copy (what the flight code uses) and an *inactive* buffer.
//! `load` parses, CRC-checks, decodes and validates an image into the inactive buffer (a
//! failure leaves the inactive buffer empty and the active table untouched); `activate`
//! swaps it in — the executive calls it only at a cycle boundary, on command; `abort`
//! clears the inactive buffer. Validation at load and again at activation checks the change
//! from the active table against the FilterTable bound, so loading several tables in any
//! order before activating gives the same result.
//!
//! Requirements verified by tests: TBL-001 a rejected image never changes the active table;
//! TBL-002 a dump of the active table round-trips bit for bit; TBL-003 activation only of a
//! validated inactive buffer.

use super::image::{
    decode_catalog_into, decode_payload, encode_image, parse_image, TableError, TableId,
};
use super::magnetics::MagneticsTable;
use super::types::{
    check_alignment_change, check_iru_change, AlignmentTable, FilterTable, IruTable, OrbitTable,
    StarCatalogTable,
};
use crate::raw::TimeTag;

/// State of a table's inactive buffer.
/// docs/tables.md ("Lifecycle", cFE Table Services style).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum BufferState {
    /// Nothing loaded.
    /// docs/tables.md ("Lifecycle").
    Empty,
    /// A validated table waits for activation.
    /// docs/tables.md ("Lifecycle").
    Validated,
}

/// Status of one table for telemetry.
/// docs/icd.md §3.2 (table CRCs, pending mask).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Default, serde::Serialize, serde::Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub struct TableStatus {
    /// CRC-32 of the active table's image (0 for a boot table never loaded).
    /// docs/icd.md §3.2 (offset 213); CRC per docs/tables.md.
    pub active_crc: u32,
    /// Creation time of the active table's image (zero for the boot table).
    /// docs/tables.md (offsets 12–17).
    pub active_created: TimeTag,
    /// Whether a validated table waits in the inactive buffer.
    /// docs/icd.md §3.2 (offset 229).
    pub pending: bool,
    /// Number of successful activations since boot.
    /// Project choice (not in the paper): operator evidence (cFE Table Services keeps the same).
    pub activations: u16,
    /// Number of rejected loads since boot.
    /// Project choice (not in the paper): operator evidence (cFE Table Services keeps the same).
    pub rejections: u16,
}

/// An active table with the header data needed to dump it bit for bit.
#[derive(Clone, Debug, PartialEq)]
struct Slot<T> {
    active: T,
    active_created: TimeTag,
    active_crc: u32,
    inactive: Option<(T, TimeTag, u32)>,
    activations: u16,
    rejections: u16,
}

impl<T: Clone> Slot<T> {
    fn new(active: T) -> Self {
        Self {
            active,
            active_created: TimeTag::default(),
            active_crc: 0,
            inactive: None,
            activations: 0,
            rejections: 0,
        }
    }

    fn status(&self) -> TableStatus {
        TableStatus {
            active_crc: self.active_crc,
            active_created: self.active_created,
            pending: self.inactive.is_some(),
            activations: self.activations,
            rejections: self.rejections,
        }
    }

    fn activate(&mut self) -> bool {
        // Swap in place rather than move the table out of the option: the star catalog is
        // ~82 KB and a move would copy it through the stack.
        let Some((table, created, crc)) = self.inactive.as_mut() else {
            return false;
        };
        core::mem::swap(&mut self.active, table);
        self.active_created = *created;
        self.active_crc = *crc;
        self.activations = self.activations.saturating_add(1);
        self.inactive = None;
        true
    }
}

/// The five tables with their double buffers.
/// docs/tables.md (tables 1–5, "Lifecycle").
#[derive(Clone, Debug, PartialEq)]
pub struct TableSet {
    alignment: Slot<AlignmentTable>,
    iru: Slot<IruTable>,
    filter: Slot<FilterTable>,
    catalog: Slot<StarCatalogTable>,
    orbit: Slot<OrbitTable>,
    magnetics: Slot<MagneticsTable>,
}

impl Default for TableSet {
    fn default() -> Self {
        Self::boot()
    }
}

fn crc_of(bytes: &[u8]) -> u32 {
    let n = bytes.len();
    let start = n.saturating_sub(4);
    match bytes
        .get(start..n)
        .and_then(|s| <[u8; 4]>::try_from(s).ok())
    {
        Some(b) => u32::from_be_bytes(b),
        None => 0,
    }
}

impl TableSet {
    /// Boot tables: the paper's prelaunch alignments (Table 1) and IRU G, default filter
    /// settings, an empty star catalog (a catalog must be uplinked before fine mode) and no
    /// orbit (an orbit table must be uplinked before the orbital aberration correction).
    #[must_use]
    pub fn boot() -> Self {
        Self {
            alignment: Slot::new(AlignmentTable::prelaunch()),
            iru: Slot::new(IruTable::prelaunch()),
            filter: Slot::new(FilterTable::default_boot()),
            catalog: Slot::new(StarCatalogTable::default()),
            orbit: Slot::new(OrbitTable::none()),
            magnetics: Slot::new(MagneticsTable::boot()),
        }
    }

    /// Active alignment table.
    /// docs/tables.md (Table 1: alignment); paper Table 1 at boot.
    #[must_use]
    pub fn alignment(&self) -> &AlignmentTable {
        &self.alignment.active
    }
    /// Active IRU table.
    /// docs/tables.md (Table 2: IRU); paper prelaunch `G` at boot.
    #[must_use]
    pub fn iru(&self) -> &IruTable {
        &self.iru.active
    }
    /// Active filter table.
    /// docs/tables.md (Table 3: filter).
    #[must_use]
    pub fn filter(&self) -> &FilterTable {
        &self.filter.active
    }
    /// Active star catalog.
    /// docs/tables.md (Table 4: star catalog).
    #[must_use]
    pub fn catalog(&self) -> &StarCatalogTable {
        &self.catalog.active
    }
    /// Active orbit table ([`OrbitTable::none`] until one is activated).
    /// docs/tables.md (Table 5: orbit).
    #[must_use]
    pub fn orbit(&self) -> &OrbitTable {
        &self.orbit.active
    }
    /// Whether an orbit table has been activated since boot (the boot table holds no orbit).
    /// docs/tables.md (Table 5: "boot: none").
    #[must_use]
    pub fn has_orbit(&self) -> bool {
        self.orbit.activations > 0
    }
    /// Active magnetics table ([`MagneticsTable::boot`]: no field model, until one is
    /// activated).
    /// docs/tables.md (Table 6: magnetics).
    #[must_use]
    pub fn magnetics(&self) -> &MagneticsTable {
        &self.magnetics.active
    }

    /// Status of every table, in [`TableId::ALL`] order.
    /// docs/icd.md §3.2 (table CRCs, pending mask).
    #[must_use]
    pub fn status(&self) -> [TableStatus; 6] {
        [
            self.alignment.status(),
            self.iru.status(),
            self.filter.status(),
            self.catalog.status(),
            self.orbit.status(),
            self.magnetics.status(),
        ]
    }

    /// Load an image into its table's inactive buffer after full validation.
    /// docs/tables.md ("Lifecycle"; event 0x0102 reason codes).
    ///
    /// On any error the inactive buffer of the addressed table (when the id is readable) is
    /// cleared and the active table is unchanged.
    ///
    /// # Errors
    /// Why the image was refused; the id is returned when it could be read.
    // Kept out of line: the star-catalog path moves ~82 KB values, which must not
    // enlarge the stack frame of every cycle (`FlightCore::step`).
    #[inline(never)]
    pub fn load(&mut self, image: &[u8]) -> Result<TableId, (Option<TableId>, TableError)> {
        let (header, payload) = parse_image(image).map_err(|e| {
            let id = image.get(4).copied().and_then(TableId::from_u8);
            if let Some(id) = id {
                self.reject(id);
            }
            (id, e)
        })?;
        let id = header.table_id;
        let crc = crc_of(image);
        let result = self.decode_and_validate(id, payload, header.created, crc);
        match result {
            Ok(()) => Ok(id),
            Err(e) => {
                self.reject(id);
                Err((Some(id), e))
            }
        }
    }

    fn reject(&mut self, id: TableId) {
        match id {
            TableId::Alignment => {
                self.alignment.inactive = None;
                self.alignment.rejections = self.alignment.rejections.saturating_add(1);
            }
            TableId::Iru => {
                self.iru.inactive = None;
                self.iru.rejections = self.iru.rejections.saturating_add(1);
            }
            TableId::Filter => {
                self.filter.inactive = None;
                self.filter.rejections = self.filter.rejections.saturating_add(1);
            }
            TableId::StarCatalog => {
                self.catalog.inactive = None;
                self.catalog.rejections = self.catalog.rejections.saturating_add(1);
            }
            TableId::Orbit => {
                self.orbit.inactive = None;
                self.orbit.rejections = self.orbit.rejections.saturating_add(1);
            }
            TableId::Magnetics => {
                self.magnetics.inactive = None;
                self.magnetics.rejections = self.magnetics.rejections.saturating_add(1);
            }
        }
    }

    // Kept out of line: the star-catalog path moves ~82 KB values, which must not
    // enlarge the stack frame of every cycle (`FlightCore::step`).
    #[inline(never)]
    fn decode_and_validate(
        &mut self,
        id: TableId,
        payload: &[u8],
        created: TimeTag,
        crc: u32,
    ) -> Result<(), TableError> {
        match id {
            TableId::Alignment => {
                let t: AlignmentTable = decode_payload(payload)?;
                t.validate()?;
                check_alignment_change(&t, &self.alignment.active, &self.filter.active)?;
                self.alignment.inactive = Some((t, created, crc));
            }
            TableId::Iru => {
                let t: IruTable = decode_payload(payload)?;
                t.validate()?;
                check_iru_change(&t, &self.iru.active, &self.filter.active)?;
                self.iru.inactive = Some((t, created, crc));
            }
            TableId::Filter => {
                let t: FilterTable = decode_payload(payload)?;
                t.validate()?;
                self.filter.inactive = Some((t, created, crc));
            }
            TableId::StarCatalog => {
                // In place: the ~82 KB table never passes through the stack
                // (`decode_catalog_into`); `load` clears the buffer on any error.
                let slot = self
                    .catalog
                    .inactive
                    .get_or_insert_with(|| (StarCatalogTable::default(), created, crc));
                decode_catalog_into(payload, &mut slot.0)?;
                slot.0.validate()?;
                slot.1 = created;
                slot.2 = crc;
            }
            TableId::Orbit => {
                let t: OrbitTable = decode_payload(payload)?;
                t.validate()?;
                self.orbit.inactive = Some((t, created, crc));
            }
            TableId::Magnetics => {
                // Layout 3 (fields 0–25), else layout 2 (fields 0–23, before the wheel
                // geometry), else layout 1 (fields 0–18, before momentum unloading).
                let (t, _layout) = MagneticsTable::decode_any_layout(payload)?;
                t.validate()?;
                self.magnetics.inactive = Some((t, created, crc));
            }
        }
        Ok(())
    }

    /// Activate the validated inactive buffer of `id`. The change bound is checked again
    /// against the table active *now*.
    /// docs/tables.md ("Lifecycle"; event 0x0104 reason codes).
    ///
    /// # Errors
    /// `None` in the inner option means nothing was pending; `Some(e)` a re-check failed (the
    /// inactive buffer is then cleared).
    // Kept out of line: the star-catalog path moves ~82 KB values, which must not
    // enlarge the stack frame of every cycle (`FlightCore::step`).
    #[inline(never)]
    pub fn activate(&mut self, id: TableId) -> Result<(), Option<TableError>> {
        let recheck = match id {
            TableId::Alignment => match &self.alignment.inactive {
                Some((t, _, _)) => {
                    check_alignment_change(t, &self.alignment.active, &self.filter.active)
                }
                None => return Err(None),
            },
            TableId::Iru => match &self.iru.inactive {
                Some((t, _, _)) => check_iru_change(t, &self.iru.active, &self.filter.active),
                None => return Err(None),
            },
            TableId::Filter | TableId::StarCatalog | TableId::Orbit | TableId::Magnetics => Ok(()),
        };
        if let Err(e) = recheck {
            self.reject(id);
            return Err(Some(e));
        }
        let done = match id {
            TableId::Alignment => self.alignment.activate(),
            TableId::Iru => self.iru.activate(),
            TableId::Filter => self.filter.activate(),
            TableId::StarCatalog => self.catalog.activate(),
            TableId::Orbit => self.orbit.activate(),
            TableId::Magnetics => self.magnetics.activate(),
        };
        if done {
            Ok(())
        } else {
            Err(None)
        }
    }

    /// Clear the inactive buffer of `id`; returns whether something was pending.
    /// docs/tables.md ("Lifecycle"); docs/icd.md §3.3 (event 0x0105).
    pub fn abort(&mut self, id: TableId) -> bool {
        match id {
            TableId::Alignment => self.alignment.inactive.take().is_some(),
            TableId::Iru => self.iru.inactive.take().is_some(),
            TableId::Filter => self.filter.inactive.take().is_some(),
            TableId::StarCatalog => self.catalog.inactive.take().is_some(),
            TableId::Orbit => self.orbit.inactive.take().is_some(),
            TableId::Magnetics => self.magnetics.inactive.take().is_some(),
        }
    }

    /// Encode the active table `id` as an image into `out` (same bytes as the image that
    /// was activated; boot tables carry a zero creation time).
    /// docs/tables.md ("Image = header + payload + CRC"); TBL-002.
    ///
    /// # Errors
    /// [`TableError::BufferTooSmall`].
    // Kept out of line: the star-catalog path moves ~82 KB values, which must not
    // enlarge the stack frame of every cycle (`FlightCore::step`).
    #[inline(never)]
    pub fn dump(&self, id: TableId, out: &mut [u8]) -> Result<usize, TableError> {
        match id {
            TableId::Alignment => encode_image(
                id,
                self.alignment.active_created,
                &self.alignment.active,
                out,
            ),
            TableId::Iru => encode_image(id, self.iru.active_created, &self.iru.active, out),
            TableId::Filter => {
                encode_image(id, self.filter.active_created, &self.filter.active, out)
            }
            TableId::StarCatalog => {
                encode_image(id, self.catalog.active_created, &self.catalog.active, out)
            }
            TableId::Orbit => encode_image(id, self.orbit.active_created, &self.orbit.active, out),
            TableId::Magnetics => encode_image(
                id,
                self.magnetics.active_created,
                &self.magnetics.active,
                out,
            ),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::attitude::rot;
    use crate::tables::image::{CRC_LEN, HEADER_LEN};
    use crate::tables::magnetics::MagneticsTableLayout1;
    use crate::tables::types::{matrix_from_rows, rows_from_matrix};
    use crate::units::RAD_PER_ARCSEC;
    use nalgebra::Vector3;

    fn image_of<T: serde::Serialize>(id: TableId, t: &T) -> ([u8; 1024], usize) {
        let mut buf = [0u8; 1024];
        let n = encode_image(
            id,
            TimeTag {
                coarse_s: 1_000,
                fine: 7,
            },
            t,
            &mut buf,
        )
        .unwrap();
        (buf, n)
    }

    fn rotated_alignment(arcsec: f64) -> AlignmentTable {
        let mut t = AlignmentTable::prelaunch();
        let m = rot(&Vector3::new(arcsec * RAD_PER_ARCSEC, 0.0, 0.0))
            * matrix_from_rows(&t.m_acs_from_fss1);
        t.m_acs_from_fss1 = rows_from_matrix(&m);
        t
    }

    #[test]
    fn load_activate_dump_round_trip() {
        let mut set = TableSet::boot();
        let t = rotated_alignment(700.0);
        let (buf, n) = image_of(TableId::Alignment, &t);
        assert_eq!(set.load(&buf[..n]), Ok(TableId::Alignment));
        assert_eq!(set.alignment(), &AlignmentTable::prelaunch());
        assert_eq!(set.activate(TableId::Alignment), Ok(()));
        assert_eq!(set.alignment(), &t);
        let mut out = [0u8; 1024];
        let m = set.dump(TableId::Alignment, &mut out).unwrap();
        assert_eq!(&out[..m], &buf[..n]);
    }

    #[test]
    fn corrupt_and_out_of_bound_images_leave_active_unchanged() {
        let mut set = TableSet::boot();
        let before = set.clone();
        let (mut buf, n) = image_of(TableId::Alignment, &rotated_alignment(700.0));
        buf[30] ^= 0x40;
        assert!(matches!(
            set.load(&buf[..n]),
            Err((Some(TableId::Alignment), TableError::CrcMismatch { .. }))
        ));
        let (buf, n) = image_of(TableId::Alignment, &rotated_alignment(36_000.0));
        assert!(matches!(
            set.load(&buf[..n]),
            Err((Some(TableId::Alignment), TableError::ChangeTooLarge { .. }))
        ));
        assert_eq!(set.alignment(), before.alignment());
        assert_eq!(set.activate(TableId::Alignment), Err(None));
    }

    /// Table 6 of layout 3 round-trips; layout-2 and layout-1 payloads (written before the
    /// wheel fields, and before the unloading fields) still load, with the boot values of the
    /// fields they lack; one octet more or less than any layout is refused.
    #[test]
    #[allow(clippy::float_cmp)] // copied values: exact equality is the point
    fn magnetics_layouts_round_trip_and_old_payloads_load() {
        let mut t = MagneticsTable::boot();
        t.unloading_gain_per_s = 2.0e-3;
        t.torquer_dipole_limit_am2 = 300.0;
        t.tam_bias_milligauss[0] = [0.0, 0.0, -4.0];
        let mut buf = [0u8; 8192];
        let created = TimeTag::default();
        let n = encode_image(TableId::Magnetics, created, &t, &mut buf).unwrap();
        assert_eq!(n, 4_570, "the layout-3 image of docs/tables.md");
        let payload = |image: &[u8]| image[HEADER_LEN..image.len() - CRC_LEN].to_vec();
        assert_eq!(
            MagneticsTable::decode_any_layout(&payload(&buf[..n])),
            Ok((t, 3))
        );
        let mut set = TableSet::boot();
        assert_eq!(set.load(&buf[..n]), Ok(TableId::Magnetics));
        set.activate(TableId::Magnetics).unwrap();
        assert_eq!(set.magnetics(), &t);
        let mut out = [0u8; 8192];
        let m = set.dump(TableId::Magnetics, &mut out).unwrap();
        assert_eq!(&out[..m], &buf[..n]);

        let mut b = MagneticsTable::boot();
        b.tam_bias_milligauss = [[0.0, 0.0, -4.0], [0.5, 0.0, 0.0]];
        b.field_sigma_milligauss = [0.3, 2.5];
        b.coarse_fix_every_n_cycles = 10;
        b.unloading_gain_per_s = 1.0e-3;
        b.wheel_spin_inertia_kg_m2 = 0.3;
        let old2 = (
            MagneticsTableLayout1::from_table(&b),
            super::super::magnetics::MagneticsUnloadingFields::from_table(&b),
        );
        let n2 = encode_image(TableId::Magnetics, created, &old2, &mut buf).unwrap();
        assert_eq!(n2, 4_466, "the layout-2 image of docs/tables.md");
        assert_eq!(
            MagneticsTable::decode_any_layout(&payload(&buf[..n2])).map(|(_, layout)| layout),
            Ok(2)
        );
        let mut set = TableSet::boot();
        assert_eq!(set.load(&buf[..n2]), Ok(TableId::Magnetics));
        set.activate(TableId::Magnetics).unwrap();
        let loaded = set.magnetics();
        assert_eq!(loaded.unloading_gain_per_s, 1.0e-3);
        assert_eq!(
            loaded.wheel_spin_inertia_kg_m2,
            MagneticsTable::boot().wheel_spin_inertia_kg_m2
        );
        let mut b = MagneticsTable::boot();
        b.tam_bias_milligauss = [[0.0, 0.0, -4.0], [0.5, 0.0, 0.0]];
        b.field_sigma_milligauss = [0.3, 2.5];
        b.coarse_fix_every_n_cycles = 10;
        let old = MagneticsTableLayout1::from_table(&b);
        let n1 = encode_image(TableId::Magnetics, created, &old, &mut buf).unwrap();
        assert_eq!(n1, 4_426, "the layout-1 image of docs/tables.md");
        assert_eq!(
            MagneticsTable::decode_any_layout(&payload(&buf[..n1])).map(|(_, layout)| layout),
            Ok(1)
        );
        assert!(n1 < n);
        let mut set = TableSet::boot();
        assert_eq!(set.load(&buf[..n1]), Ok(TableId::Magnetics));
        set.activate(TableId::Magnetics).unwrap();
        let loaded = set.magnetics();
        assert_eq!(loaded.tam_bias_milligauss, old.tam_bias_milligauss);
        assert_eq!(loaded.field_sigma_milligauss, [0.3, 2.5]);
        assert_eq!(loaded.unloading_gain_per_s, b.unloading_gain_per_s);
        assert_eq!(loaded.torquer_dipole_limit_am2, b.torquer_dipole_limit_am2);
        // An invalid new field is named; a payload of neither length is refused.
        let mut bad = t;
        bad.unloading_stop_nms = 1e6;
        let n2 = encode_image(TableId::Magnetics, created, &bad, &mut buf).unwrap();
        assert!(matches!(
            TableSet::boot().load(&buf[..n2]),
            Err((_, TableError::OutOfRange { field: 22 }))
        ));
        let payload = &t;
        let mut raw = [0u8; 8192];
        let len = postcard::to_slice(payload, &mut raw).unwrap().len();
        assert!(decode_payload::<MagneticsTable>(&raw[..len - 1]).is_err());
        assert!(decode_payload::<MagneticsTableLayout1>(&raw[..len]).is_err());
    }

    #[test]
    fn nan_and_truncated_rejected() {
        let mut set = TableSet::boot();
        let mut t = AlignmentTable::prelaunch();
        t.m_acs_from_fhst2[1][1] = f64::NAN;
        let (buf, n) = image_of(TableId::Alignment, &t);
        assert!(matches!(
            set.load(&buf[..n]),
            Err((_, TableError::NotFinite { field: 1 }))
        ));
        let (buf, n) = image_of(TableId::Alignment, &AlignmentTable::prelaunch());
        assert!(matches!(
            set.load(&buf[..n - 10]),
            Err((_, TableError::LengthMismatch { .. }))
        ));
        assert_eq!(set.alignment(), &AlignmentTable::prelaunch());
    }
}
