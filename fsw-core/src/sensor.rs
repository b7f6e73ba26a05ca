//! # The attitude sensors by name: one identifier and one per-sensor container
//!
//! Why: the four aligned sensors (FHST1, FHST2, FSS1, FSS2) are the slots of the alignment
//! table, the rows of the paper's Tables 1–3, the pairs of the ground's relative alignments
//! and the subjects of `diagnose`. Carried as bare indices and strings (`tracker: usize`,
//! `"FSS2"`, `[bool; 4]`), a swapped slot or a misspelt name compiles and is wrong in silence.
//! [`SensorId`] names a slot; [`PerSensor`] holds one value per sensor and is indexed by a
//! `SensorId` only, so that the index cannot be out of range (no panic path in flight code)
//! and cannot be a sensor of the wrong kind. The wire names (`"FHST1"` …) are defined here
//! once; in self-describing formats (JSON reports) serde writes and reads a `SensorId` as its
//! name (postcard, not self-describing, writes the variant index).

use serde::{Deserialize, Serialize};

/// Number of aligned attitude sensors.
/// Paper: two FHSTs and two FSSs (Tables 1–3).
pub const SENSORS: usize = 4;

/// One of the four aligned attitude sensors, in alignment-table order.
/// Paper Tables 1–3 (rows FHST1, FHST2, FSS1, FSS2); docs/tables.md (Table 1).
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord, Serialize, Deserialize)]
#[cfg_attr(feature = "defmt", derive(defmt::Format))]
pub enum SensorId {
    /// Fixed-head star tracker 1.
    /// Paper Table 1.
    #[serde(rename = "FHST1")]
    Fhst1,
    /// Fixed-head star tracker 2.
    /// Paper Table 1.
    #[serde(rename = "FHST2")]
    Fhst2,
    /// Fine Sun sensor 1.
    /// Paper Table 1.
    #[serde(rename = "FSS1")]
    Fss1,
    /// Fine Sun sensor 2.
    /// Paper Table 1.
    #[serde(rename = "FSS2")]
    Fss2,
}

impl SensorId {
    /// Every sensor, in table order.
    /// Paper Tables 1–3.
    pub const ALL: [Self; SENSORS] = [Self::Fhst1, Self::Fhst2, Self::Fss1, Self::Fss2];

    /// The sensors' names in table order (the wire and report names).
    /// Paper Tables 1–3.
    pub const NAMES: [&'static str; SENSORS] = ["FHST1", "FHST2", "FSS1", "FSS2"];

    /// Slot in table order (0–3).
    /// Paper Tables 1–3.
    #[must_use]
    pub const fn index(self) -> usize {
        match self {
            Self::Fhst1 => 0,
            Self::Fhst2 => 1,
            Self::Fss1 => 2,
            Self::Fss2 => 3,
        }
    }

    /// The sensor of slot `i`, `None` beyond 3.
    /// Paper Tables 1–3.
    #[must_use]
    pub const fn from_index(i: usize) -> Option<Self> {
        match i {
            0 => Some(Self::Fhst1),
            1 => Some(Self::Fhst2),
            2 => Some(Self::Fss1),
            3 => Some(Self::Fss2),
            _ => None,
        }
    }

    /// Its name (`"FHST1"` …).
    /// Paper Tables 1–3.
    #[must_use]
    pub const fn name(self) -> &'static str {
        match self {
            Self::Fhst1 => "FHST1",
            Self::Fhst2 => "FHST2",
            Self::Fss1 => "FSS1",
            Self::Fss2 => "FSS2",
        }
    }

    /// The sensor of a name, any case (`"fss2"` and `"FSS2"` alike).
    /// Paper Tables 1–3.
    #[must_use]
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL
            .into_iter()
            .find(|s| s.name().eq_ignore_ascii_case(name))
    }

    /// A star tracker (FHST1, FHST2), not a Sun sensor.
    /// Paper Table 1.
    #[must_use]
    pub const fn is_fhst(self) -> bool {
        matches!(self, Self::Fhst1 | Self::Fhst2)
    }

    /// The unit number within its kind: 0 for FHST1 and FSS1, 1 for FHST2 and FSS2.
    /// Paper Table 1.
    #[must_use]
    pub const fn unit(self) -> usize {
        match self {
            Self::Fhst1 | Self::Fss1 => 0,
            Self::Fhst2 | Self::Fss2 => 1,
        }
    }
}

impl core::fmt::Display for SensorId {
    fn fmt(&self, f: &mut core::fmt::Formatter<'_>) -> core::fmt::Result {
        f.write_str(self.name())
    }
}

/// One value per sensor, indexed by [`SensorId`] (infallible: no index can be out of range).
/// Project choice (not in the paper): see the module doc.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub struct PerSensor<T>([T; SENSORS]);

impl<T> PerSensor<T> {
    /// The container of the values in table order (FHST1, FHST2, FSS1, FSS2).
    /// Project choice (not in the paper): module doc.
    pub const fn new(values_in_table_order: [T; SENSORS]) -> Self {
        Self(values_in_table_order)
    }

    /// The values in table order.
    /// Project choice (not in the paper): module doc.
    pub const fn as_array(&self) -> &[T; SENSORS] {
        &self.0
    }

    /// The value of `id`.
    /// Project choice (not in the paper): module doc.
    #[must_use]
    pub const fn get(&self, id: SensorId) -> &T {
        let [a, b, c, d] = &self.0;
        match id {
            SensorId::Fhst1 => a,
            SensorId::Fhst2 => b,
            SensorId::Fss1 => c,
            SensorId::Fss2 => d,
        }
    }

    /// The value of `id`, mutable.
    /// Project choice (not in the paper): module doc.
    pub fn get_mut(&mut self, id: SensorId) -> &mut T {
        let [a, b, c, d] = &mut self.0;
        match id {
            SensorId::Fhst1 => a,
            SensorId::Fhst2 => b,
            SensorId::Fss1 => c,
            SensorId::Fss2 => d,
        }
    }

    /// Each sensor with its value, in table order.
    /// Project choice (not in the paper): module doc.
    pub fn iter(&self) -> impl Iterator<Item = (SensorId, &T)> {
        SensorId::ALL.into_iter().zip(self.0.iter())
    }

    /// A container of `f(id)` for every sensor.
    /// Project choice (not in the paper): module doc.
    pub fn from_fn(mut f: impl FnMut(SensorId) -> T) -> Self {
        Self(SensorId::ALL.map(&mut f))
    }
}

impl<T> core::ops::Index<SensorId> for PerSensor<T> {
    type Output = T;
    fn index(&self, id: SensorId) -> &T {
        self.get(id)
    }
}

impl<T> core::ops::IndexMut<SensorId> for PerSensor<T> {
    fn index_mut(&mut self, id: SensorId) -> &mut T {
        self.get_mut(id)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn names_indices_and_containers_agree() {
        for (i, s) in SensorId::ALL.into_iter().enumerate() {
            assert_eq!(s.index(), i);
            assert_eq!(SensorId::from_index(i), Some(s));
            assert_eq!(s.name(), SensorId::NAMES[i]);
            assert_eq!(SensorId::from_name(&s.name().to_ascii_lowercase()), Some(s));
        }
        assert_eq!(SensorId::from_index(4), None);
        assert_eq!(SensorId::from_name("FSS3"), None);
        assert!(SensorId::Fhst2.is_fhst() && !SensorId::Fss1.is_fhst());
        assert_eq!((SensorId::Fss2.unit(), SensorId::Fhst1.unit()), (1, 0));
        let mut p = PerSensor::from_fn(SensorId::index);
        p[SensorId::Fss1] += 10;
        assert_eq!(p.as_array(), &[0, 1, 12, 3]);
        assert_eq!(PerSensor::new([0, 1, 12, 3]), p);
        let names: heapless::Vec<&str, 4> = p.iter().map(|(s, _)| s.name()).collect();
        assert_eq!(names.as_slice(), &SensorId::NAMES);
    }

    #[test]
    fn serde_uses_the_names() {
        extern crate std;
        let json = serde_json::to_string(&[SensorId::Fhst1, SensorId::Fss2]).unwrap();
        assert_eq!(json, r#"["FHST1","FSS2"]"#);
        let back: [SensorId; 2] = serde_json::from_str(&json).unwrap();
        assert_eq!(back, [SensorId::Fhst1, SensorId::Fss2]);
        assert!(serde_json::from_str::<SensorId>(r#""FSS3""#).is_err());
        let mut buf = [0u8; 16];
        let bytes = postcard::to_slice(&SensorId::Fss2, &mut buf).unwrap();
        assert_eq!(
            postcard::from_bytes::<SensorId>(bytes).unwrap(),
            SensorId::Fss2
        );
    }
}
