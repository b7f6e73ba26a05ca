//! # Fault injection (scenario `[[faults]]`, issue 7)
//!
//! Why: a flight core is trusted for what it survives. Each `[[faults]]` entry of a scenario
//! is applied by the harness to the truth sensors, the spacecraft clock or the uplink at a
//! given time; the OBC (`fsw_core`) is never touched, it only sees what the hardware or the
//! ground would give it. The scenarios in `scenarios/faults/` use one fault kind each and
//! write down the expected OBC behaviour; [`assess`] flies a scenario with and without its
//! faults and measures what the docs/reliability.md table reports.
//!
//! ```toml
//! [[faults]]
//! kind = "fhst_dropout"     # both trackers give no data for one orbit
//! sensor = "both"
//! at_s = 600
//! duration_s = 5700
//! ```
//!
//! | kind | fields | what the harness does |
//! |---|---|---|
//! | `fhst_dropout` | `sensor` = "fhst1" / "fhst2" / "both", `at_s`, `duration_s` | the tracker words are all zero (no data, flags 0) in `[at_s, at_s + duration_s)`; the truth tracker keeps running underneath |
//! | `fhst_wrong_star` | `sensor` = "fhst1" / "fhst2", `at_s`, `duration_s`, optional `offset_deg = [H, V]`, optional `new_star_flag` (default false) | every valid sample of the window is displaced in the focal plane by `offset_deg`; without `offset_deg`, by the (H, V) offset, at `at_s`, from the tracked star to the nearest other catalogue star in the field (the tracker silently jumps to another star: the OBC's identification is then wrong). `new_star_flag` sets `FHST_FLAG_NEW_STAR` on the first faulty sample |
//! | `fss_glint` | `sensor` = "fss1" / "fss2", `at_s`, `duration_s`, `offset_deg = [α, β]` | the Sun angles are displaced by `offset_deg` while the Sun is seen (a reflection) |
//! | `iru_channel_failure` | `channel` = "X1" … "Z2", `at_s`, optional `bit` (default true) | the channel's counter stops from `at_s`; with `bit = true` its built-in-test bit is set (what `[iru] failure` does), with `bit = false` it sticks silently |
//! | `time_tag_jump` | `at_s`, `offset_s`, optional `duration_s` | the frame time tag is `t + offset_s` from `at_s` on (for `duration_s` only, if given: a glitch) |
//! | `table_upload` | `at_s`, `corruption` = "none" / "bit_flip" / "truncate" / "rotate" / "nan", optional `activate` (default true), `rotation_deg` + `rotation_sensor` (rotate), `bits` (bit_flip, default 1), `octets` (truncate, default 16) | an alignment image built from the start-up alignment (the true one with `fly_true_alignments`, else the boot table), damaged as said, is loaded at `at_s` and, if `activate`, activated in the same cycle |
//! | `filter_reset` | `at_s` | an unexpected `FilterReset` command (covariance reopened, estimate kept) |
//! | `torquer_stuck_on` | `sensor` = "mtb1" / "mtb2" / "mtb3", `at_s`, `dipole_am2`, optional `duration_s` (absent: for good) | the bar delivers `dipole_am2` whatever the OBC commands, within `[torquers] dipole_limit_am2` like a command (a larger value is refused) ([`crate::truth::torquer`]): its torque on the body and its field at the TAMs (needs `[dynamics] momentum_unloading = "bars"`) |
//! | `tachometer_failed` | `sensor` = "rwa1" … "rwa4", `at_s`, `duration_s` | that wheel's tachometer word reads invalid ([`crate::sensors::tachometer`]): the OBC counts its torque commands instead (event 0x0A03; needs `[wheel_tachometers] enabled`) |
//! | `iru_counter_wrap` | `at_s`, optional `margin_pulses` (default 40) | the six 16-bit counters start (t = 0) where, moved by their true bias at low rate until `at_s`, they stand `margin_pulses` short of the wrap in the direction the bias moves them: every counter wraps at about `at_s` (put a high-rate slew there). The OBC sees only count differences, so this is invisible except where the wraps fall |
//!
//! Damage of `table_upload`: `bit_flip` flips `bits` payload bits *after* the CRC was
//! computed (a transmission error); `truncate` drops the last `octets` octets; `rotate`
//! rotates the `rotation_sensor` alignment by `rotation_deg` about the ACS x axis and
//! reseals the image (valid CRC: a wrong table, not a damaged one); `nan` writes NaN into
//! FHST2's `M_AS[1][1]` and reseals.

pub mod campaign;
pub mod model;

pub use campaign::*;
pub use model::*;

#[cfg(test)]
mod tests {
    use super::*;
    use crate::scenario::Scenario;
    use fsw_core::raw::TimeTag;
    use fsw_core::tables::{AlignmentTable, TableId};

    /// Every `scenarios/faults/*.toml` parses, validates and has at least one fault.
    #[test]
    fn shipped_fault_scenarios_load() {
        let files = shipped_fault_scenarios().unwrap();
        assert!(files.len() >= 9, "{files:?}");
        for f in files {
            let s = Scenario::load(&f).unwrap_or_else(|e| panic!("{}: {e:#}", f.display()));
            assert!(!s.faults.is_empty(), "{}", f.display());
        }
    }

    #[test]
    fn windows_and_validation() {
        let text = "name = \"x\"\nduration_s = 10\n[[faults]]\nkind = \"fhst_dropout\"\nsensor = \"both\"\nat_s = 5\nduration_s = 2\n";
        let s = Scenario::from_toml_str(text, "t").unwrap();
        let f = &s.faults[0];
        assert!(!f.active(4.0) && f.active(5.0) && f.active(6.0) && !f.active(7.0));
        assert_eq!(f.unit_mask(), 3);
        // A dropout without a duration, an unknown key, a glint without offset: refused, named.
        for (bad, what) in [
            (
                "kind = \"fhst_dropout\"\nsensor = \"both\"\nat_s = 5\n",
                "duration_s",
            ),
            (
                "kind = \"fss_glint\"\nsensor = \"fss1\"\nat_s = 5\nduration_s = 1\n",
                "offset_deg",
            ),
            (
                "kind = \"iru_channel_failure\"\nchannel = \"Q1\"\nat_s = 5\n",
                "channel",
            ),
            (
                "kind = \"time_tag_jump\"\nat_s = 5\nofset_s = 1\n",
                "ofset_s",
            ),
        ] {
            let err = Scenario::from_toml_str(
                &format!("name = \"x\"\nduration_s = 10\n[[faults]]\n{bad}"),
                "t",
            )
            .unwrap_err();
            assert!(format!("{err:#}").contains(what), "{err:#}");
        }
    }

    /// The damaged images are refused by the OBC's table services for the intended reason.
    #[test]
    fn damaged_images_are_refused_for_their_reason() {
        use fsw_core::tables::TableSet;
        let base = AlignmentTable::prelaunch();
        let upload = |c: Corruption| Fault {
            kind: FaultKind::TableUpload,
            at_s: 0.0,
            duration_s: None,
            sensor: None,
            offset_deg: None,
            new_star_flag: false,
            channel: None,
            bit: None,
            offset_s: None,
            corruption: Some(c),
            activate: None,
            rotation_deg: Some(10.0),
            rotation_sensor: Some("fhst1".into()),
            bits: Some(3),
            octets: None,
            margin_pulses: None,
            offset_milligauss: None,
            eye: None,
            counts: None,
            dipole_am2: None,
        };
        for (c, code) in [
            (Corruption::BitFlip, 9),
            (Corruption::Truncate, 8),
            (Corruption::Rotate, 15),
            (Corruption::Nan, 12),
        ] {
            let img = upload(c).upload_image(&base, TimeTag::default()).unwrap();
            let mut set = TableSet::boot();
            let e = set.load(&img).unwrap_err();
            assert_eq!(e.0, Some(TableId::Alignment), "{c:?}");
            assert_eq!(e.1.code(), code, "{c:?}: {e:?}");
        }
        let img = upload(Corruption::None)
            .upload_image(&base, TimeTag::default())
            .unwrap();
        assert_eq!(TableSet::boot().load(&img), Ok(TableId::Alignment));
    }
}
