//! Fuzz `TableSet::load` with arbitrary bytes (docs/reliability.md).
//!
//! Input: one flags octet, then the image. Flags bit 0: rewrite the payload length and the
//! CRC before loading ("resealed"), so the fuzzer reaches payload decoding and validation
//! instead of stopping at the CRC; bit 1: activate a permissive filter table first (widest
//! change bounds) so alignment and IRU tables far from the boot ones are reachable.
//!
//! Invariants: a rejected image leaves every active table and its status unchanged and has a
//! reason; an accepted image changes no active table until activated, activates, validates,
//! its dump is the image bit for bit, and the dump re-loads and re-activates to the same
//! tables.
#![no_main]

use fsw_core::raw::TimeTag;
use fsw_core::tables::image::{encode_image, CRC_LEN, HEADER_LEN, IMAGE_CRC};
use fsw_core::tables::{FilterTable, TableError, TableId, TableSet};
use libfuzzer_sys::fuzz_target;
use std::sync::OnceLock;

fn same_active(a: &TableSet, b: &TableSet) -> bool {
    a.alignment() == b.alignment()
        && a.iru() == b.iru()
        && a.filter() == b.filter()
        && a.catalog() == b.catalog()
        && a.orbit() == b.orbit()
        && a.magnetics() == b.magnetics()
}

fn reseal(img: &mut [u8]) {
    let min = HEADER_LEN + CRC_LEN;
    if img.len() < min {
        return;
    }
    let n = u32::try_from(img.len() - min).unwrap_or(u32::MAX);
    img[8..12].copy_from_slice(&n.to_be_bytes());
    let crc_at = img.len() - CRC_LEN;
    let crc = IMAGE_CRC.checksum(&img[..crc_at]);
    img[crc_at..].copy_from_slice(&crc.to_be_bytes());
}

fn validate_active(set: &TableSet, id: TableId) -> Result<(), TableError> {
    match id {
        TableId::Alignment => set.alignment().validate(),
        TableId::Iru => set.iru().validate(),
        TableId::Filter => set.filter().validate(),
        TableId::StarCatalog => set.catalog().validate(),
        TableId::Orbit => set.orbit().validate(),
        TableId::Magnetics => set.magnetics().validate(),
    }
}

/// The boot set, and the boot set with the permissive filter active (built once).
fn templates() -> &'static [Box<TableSet>; 2] {
    static T: OnceLock<[Box<TableSet>; 2]> = OnceLock::new();
    T.get_or_init(|| {
        let boot = Box::new(TableSet::boot());
        let mut permissive = boot.clone();
        let filter = FilterTable {
            max_alignment_change_arcsec: 36_000.0,
            max_iru_change_ppm: 100_000.0,
            ..FilterTable::default_boot()
        };
        let mut buf = vec![0u8; 512];
        let n = encode_image(TableId::Filter, TimeTag::default(), &filter, &mut buf)
            .expect("filter image fits");
        assert_eq!(permissive.load(&buf[..n]), Ok(TableId::Filter));
        assert_eq!(permissive.activate(TableId::Filter), Ok(()));
        [boot, permissive]
    })
}

fuzz_target!(|data: &[u8]| {
    let Some((&flags, image)) = data.split_first() else {
        return;
    };
    let mut image = image.to_vec();
    if flags & 1 != 0 {
        reseal(&mut image);
    }
    let before: &TableSet = &templates()[usize::from(flags & 2 != 0)];
    let mut set = Box::new(before.clone());
    let status_before = before.status();
    match set.load(&image) {
        Err((id, e)) => {
            assert!((1..=15).contains(&e.code()) && e.code() != 11, "{e:?}");
            assert_eq!(id, image.get(4).copied().and_then(TableId::from_u8));
            assert!(
                same_active(&set, before),
                "rejected load changed an active table"
            );
            let after = set.status();
            for i in 0..4 {
                assert_eq!(after[i].active_crc, status_before[i].active_crc);
                assert_eq!(after[i].activations, status_before[i].activations);
            }
            if let Some(id) = id {
                assert!(!after[id.index()].pending);
                assert_eq!(set.activate(id), Err(None));
            }
        }
        Ok(id) => {
            assert_eq!(Some(id), image.get(4).copied().and_then(TableId::from_u8));
            assert!(same_active(&set, before), "load changed an active table");
            assert!(set.status()[id.index()].pending);
            assert_eq!(set.activate(id), Ok(()));
            assert_eq!(validate_active(&set, id), Ok(()));
            for other in TableId::ALL.into_iter().filter(|o| *o != id) {
                assert_eq!(set.status()[other.index()], status_before[other.index()]);
            }
            // The canonical encoding is never longer than the accepted image.
            let mut buf = vec![0u8; image.len()];
            let n = set.dump(id, &mut buf).expect("dump fits");
            let dump = &buf[..n];
            // TBL-002: the dump is the accepted image bit for bit.
            assert_eq!(dump, &image[..], "dump differs from the accepted image");
            let snapshot = set.clone();
            assert_eq!(
                set.load(dump),
                Ok(id),
                "dump of an activated table does not re-load"
            );
            assert_eq!(set.activate(id), Ok(()));
            assert!(same_active(&set, &snapshot), "re-loaded dump differs");
        }
    }
});
