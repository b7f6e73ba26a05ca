//! # `calibration-mc` as a campaign: per-seed results, shards, merging, the summary
//!
//! Why: the calibration Monte Carlo (fly + calibrate + score per seed) is the campaign users
//! run most, and at 20+ seeds of six months it belongs on a cluster. A shard (`--shard K/M`)
//! flies the campaign's seeds `first_seed + i` with `i mod M = K` and writes its per-seed
//! results to `results.shard-K-of-M.json`; `--merge FILES` checks that the shards belong to one
//! campaign (the same scenario, seeds and options, every `K` of one `M` present once, every seed
//! once) and summarises them.
//!
//! The summary is a function of the per-seed results *as recorded* (their JSON, sorted by
//! seed): the unsharded run summarises the same JSON round trip, so a merged campaign and an
//! unsharded one give identical numbers, bit for bit (serde_json's default float parsing is
//! not guaranteed to round-trip the last bit; recording both paths the same way makes that
//! moot). A non-finite number (a Cramér–Rao bound that could not be formed) is recorded as
//! `null` and read back as NaN.

use nalgebra::Vector3;
use serde::{Deserialize, Deserializer, Serialize, Serializer};
use std::path::{Path, PathBuf};

/// A number that may be NaN: `null` in JSON.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct Num(pub f64);

impl Serialize for Num {
    fn serialize<S: Serializer>(&self, s: S) -> Result<S::Ok, S::Error> {
        if self.0.is_finite() {
            s.serialize_f64(self.0)
        } else {
            s.serialize_none()
        }
    }
}

impl<'de> Deserialize<'de> for Num {
    fn deserialize<D: Deserializer<'de>>(d: D) -> Result<Self, D::Error> {
        Ok(Self(Option::<f64>::deserialize(d)?.unwrap_or(f64::NAN)))
    }
}

/// Three numbers that may be NaN.
#[must_use]
pub fn nums3(a: [f64; 3]) -> [Num; 3] {
    a.map(Num)
}

fn f3(a: &[Num; 3]) -> [f64; 3] {
    a.map(|x| x.0)
}

/// One seed's scores.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct SeedResult {
    /// The seed.
    pub seed: u64,
    /// Relative error w.r.t. FHST1 per sensor (FHST2, FSS1, FSS2), ACS, arcsec.
    pub relative_error_arcsec: Vec<(String, [Num; 3])>,
    /// NEES per sensor.
    pub nees: Vec<(String, Num)>,
    /// Stated 1σ of FHST2 rel FHST1, arcsec.
    pub sigma_fhst2_rel_fhst1_arcsec: [Num; 3],
    /// Cramér–Rao 1σ of FHST2 rel FHST1 from the simultaneous star pairs, arcsec.
    pub crb_fhst2_rel_fhst1_arcsec: [Num; 3],
    /// Cramér–Rao 1σ of the same from every star in gyro batches (scaled by the fit's
    /// χ²/dof, i.e. with the noise the data show), arcsec.
    pub crb_batches_fhst2_rel_fhst1_arcsec: [Num; 3],
    /// δM error / σ, row-major (absent when IRUCAL did not run).
    pub delta_m_normalised: Option<[Num; 9]>,
}

impl SeedResult {
    /// FHST2's error relative to FHST1 (NaN when absent).
    #[must_use]
    pub fn fhst2(&self) -> [f64; 3] {
        self.relative_error_arcsec
            .iter()
            .find(|(id, _)| id == "FHST2")
            .map_or([f64::NAN; 3], |(_, e)| f3(e))
    }
}

/// What a campaign is: every shard of one campaign says the same.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Campaign {
    /// Scenario name or path, as given.
    pub scenario: String,
    /// Number of seeds.
    pub runs: u64,
    /// First seed.
    pub first_seed: u64,
    /// The options that change the results (`--shuster1982`, `--single-stage`,
    /// `--star-pairs`, `--fixed-fss-tf`), as flags.
    pub options: Vec<String>,
}

impl Campaign {
    /// The seeds of shard `(k, m)`: `first_seed + i` for `i mod m = k`.
    #[must_use]
    pub fn seeds(&self, (k, m): (u32, u32)) -> Vec<u64> {
        (0..self.runs)
            .filter(|i| i % u64::from(m) == u64::from(k))
            .map(|i| self.first_seed + i)
            .collect()
    }
}

/// A shard's file: the campaign, which shard, and its seeds' results.
#[derive(Clone, Debug, Serialize, Deserialize)]
pub struct ShardFile {
    /// The campaign this shard belongs to.
    pub campaign: Campaign,
    /// `(K, M)`.
    pub shard: (u32, u32),
    /// Results, sorted by seed.
    pub seeds: Vec<SeedResult>,
}

/// File name of shard `(k, m)`.
#[must_use]
pub fn shard_file_name((k, m): (u32, u32)) -> String {
    format!("results.shard-{k}-of-{m}.json")
}

/// The per-seed results as recorded: through their JSON, as a shard file holds them.
///
/// # Errors
/// Serialisation (not expected).
pub fn recorded(seeds: &[SeedResult]) -> anyhow::Result<Vec<SeedResult>> {
    Ok(serde_json::from_str(&serde_json::to_string(seeds)?)?)
}

/// Read shard files and check they make one whole campaign; returns it and every seed's
/// result, sorted by seed.
///
/// # Errors
/// An unreadable file, or shards that do not make one campaign (the message says which
/// file and what disagrees): wrapped as input errors by the caller.
pub fn merge_shards(files: &[PathBuf]) -> anyhow::Result<(Campaign, Vec<SeedResult>)> {
    let mut shards: Vec<(PathBuf, ShardFile)> = Vec::new();
    for f in files {
        let text = std::fs::read_to_string(f)
            .map_err(|e| anyhow::anyhow!("{}: cannot read: {e}", f.display()))?;
        let s: ShardFile = serde_json::from_str(&text).map_err(|e| {
            anyhow::anyhow!("{}: not a calibration-mc shard file: {e}", f.display())
        })?;
        shards.push((f.clone(), s));
    }
    check_shards(&shards)?;
    let (_, first) = &shards[0];
    let campaign = first.campaign.clone();
    let mut seeds: Vec<SeedResult> = shards.into_iter().flat_map(|(_, s)| s.seeds).collect();
    seeds.sort_by_key(|s| s.seed);
    Ok((campaign, seeds))
}

fn check_shards(shards: &[(PathBuf, ShardFile)]) -> anyhow::Result<()> {
    let Some((f0, first)) = shards.first() else {
        anyhow::bail!("--merge needs at least one shard file");
    };
    let m = first.shard.1;
    let mut have = vec![None::<&Path>; m as usize];
    for (f, s) in shards {
        if s.campaign != first.campaign {
            anyhow::bail!(
                "{} belongs to another campaign than {}: {:?} against {:?}",
                f.display(),
                f0.display(),
                s.campaign,
                first.campaign
            );
        }
        let (k, mm) = s.shard;
        if mm != m || k >= m {
            anyhow::bail!(
                "{} is shard {k}/{mm}, {} is one of {m} shards",
                f.display(),
                f0.display()
            );
        }
        if let Some(other) = have[k as usize] {
            anyhow::bail!(
                "shard {k}/{m} twice: {} and {}",
                other.display(),
                f.display()
            );
        }
        have[k as usize] = Some(f);
        let got: Vec<u64> = s.seeds.iter().map(|r| r.seed).collect();
        let want = s.campaign.seeds(s.shard);
        if got != want {
            anyhow::bail!(
                "{}: shard {k}/{m} holds seeds {got:?}, the campaign's shard has {want:?} (an incomplete or edited shard)",
                f.display()
            );
        }
    }
    let missing: Vec<u32> = (0..m).filter(|&k| have[k as usize].is_none()).collect();
    if !missing.is_empty() {
        anyhow::bail!("shards {missing:?} of {m} are missing: the campaign is incomplete");
    }
    Ok(())
}

/// The campaign's statistics.
#[derive(Clone, Debug, PartialEq, Serialize)]
pub struct McSummary {
    /// Scenario.
    pub scenario: String,
    /// Seeds summarised.
    pub runs: usize,
    /// Mean NEES per sensor (3 dof: 3 when the covariance is right).
    pub mean_nees: Vec<(String, Num)>,
    /// Fraction of seeds with the FHST1–FHST2 error within 5″.
    pub fhst1_fhst2_within_5_arcsec_fraction: f64,
    /// RMS FHST1–FHST2 error per axis, arcsec.
    pub fhst1_fhst2_error_rms_per_axis_arcsec: [Num; 3],
    /// Mean stated σ per axis, arcsec.
    pub fhst1_fhst2_mean_stated_sigma_arcsec: [Num; 3],
    /// Mean Cramér–Rao σ (star pairs), arcsec.
    pub fhst1_fhst2_mean_crb_sigma_arcsec: [Num; 3],
    /// Mean Cramér–Rao σ (gyro batches), arcsec.
    pub fhst1_fhst2_mean_crb_batches_sigma_arcsec: [Num; 3],
    /// Mean of (δM error/σ)² over every element of every seed.
    pub delta_m_mean_square_normalised: Option<f64>,
    /// Fraction of δM elements within 3σ.
    pub delta_m_within_3sigma_fraction: Option<f64>,
    /// Every seed's result, sorted by seed.
    pub seeds: Vec<SeedResult>,
}

/// Summarise per-seed results (as recorded, sorted by seed).
#[must_use]
pub fn summarise(scenario: &str, seeds: Vec<SeedResult>) -> McSummary {
    let n = seeds.len().max(1) as f64;
    let mut mean_nees: Vec<(String, Num)> = Vec::new();
    for s in &seeds {
        for (id, v) in &s.nees {
            match mean_nees.iter_mut().find(|(i, _)| i == id) {
                Some((_, m)) => m.0 += v.0 / n,
                None => mean_nees.push((id.clone(), Num(v.0 / n))),
            }
        }
    }
    let within = seeds
        .iter()
        .filter(|s| Vector3::from(s.fhst2()).norm() <= 5.0)
        .count() as f64
        / n;
    let per_axis = |f: &dyn Fn(&SeedResult) -> [f64; 3], square: bool| -> [Num; 3] {
        let mut a = [0.0; 3];
        for s in &seeds {
            let v = f(s);
            for i in 0..3 {
                a[i] += if square { v[i] * v[i] } else { v[i] } / n;
            }
        }
        nums3(if square { a.map(f64::sqrt) } else { a })
    };
    let dm: Vec<[Num; 9]> = seeds.iter().filter_map(|s| s.delta_m_normalised).collect();
    let (dm_ms, dm_within) = if dm.is_empty() {
        (None, None)
    } else {
        let all: Vec<f64> = dm.iter().flatten().map(|x| x.0).collect();
        let k = all.len() as f64;
        (
            Some(all.iter().map(|x| x * x).sum::<f64>() / k),
            Some(all.iter().filter(|x| x.abs() <= 3.0).count() as f64 / k),
        )
    };
    McSummary {
        scenario: scenario.to_owned(),
        runs: seeds.len(),
        mean_nees,
        fhst1_fhst2_within_5_arcsec_fraction: within,
        fhst1_fhst2_error_rms_per_axis_arcsec: per_axis(&SeedResult::fhst2, true),
        fhst1_fhst2_mean_stated_sigma_arcsec: per_axis(
            &|s| f3(&s.sigma_fhst2_rel_fhst1_arcsec),
            false,
        ),
        fhst1_fhst2_mean_crb_sigma_arcsec: per_axis(&|s| f3(&s.crb_fhst2_rel_fhst1_arcsec), false),
        fhst1_fhst2_mean_crb_batches_sigma_arcsec: per_axis(
            &|s| f3(&s.crb_batches_fhst2_rel_fhst1_arcsec),
            false,
        ),
        delta_m_mean_square_normalised: dm_ms,
        delta_m_within_3sigma_fraction: dm_within,
        seeds,
    }
}

#[cfg(test)]
mod tests {
    #![allow(clippy::unwrap_used, clippy::expect_used)]
    use super::*;

    fn result(seed: u64) -> SeedResult {
        let x = seed as f64;
        SeedResult {
            seed,
            relative_error_arcsec: vec![
                ("FHST2".into(), nums3([0.1 * x, -0.3 / x, 1.0 / 3.0 + x])),
                ("FSS1".into(), nums3([x, 2.0, 3.0])),
            ],
            nees: vec![
                ("FHST2".into(), Num(2.0 + 0.1 * x)),
                ("FSS1".into(), Num(f64::NAN)),
            ],
            sigma_fhst2_rel_fhst1_arcsec: nums3([1.1, 2.2, 0.3]),
            crb_fhst2_rel_fhst1_arcsec: nums3([f64::NAN; 3]),
            crb_batches_fhst2_rel_fhst1_arcsec: nums3([0.7 / x, 0.9, 0.1]),
            delta_m_normalised: Some([0.1, -2.0, 3.5, 0.2, 0.3, 1.0 / x, 0.0, 0.5, -0.7].map(Num)),
        }
    }

    fn campaign() -> Campaign {
        Campaign {
            scenario: "gro-early-mission".into(),
            runs: 5,
            first_seed: 11,
            options: vec![],
        }
    }

    fn write_shard(dir: &Path, shard: (u32, u32), c: &Campaign) -> PathBuf {
        let seeds = c.seeds(shard).into_iter().map(result).collect();
        let f = dir.join(shard_file_name(shard));
        let s = ShardFile {
            campaign: c.clone(),
            shard,
            seeds,
        };
        std::fs::write(&f, serde_json::to_string_pretty(&s).unwrap()).unwrap();
        f
    }

    fn tmp(tag: &str) -> PathBuf {
        let d = std::env::temp_dir().join(format!("mc-campaign-{}-{tag}", std::process::id()));
        std::fs::create_dir_all(&d).unwrap();
        d
    }

    #[test]
    fn merged_shards_summarise_exactly_as_the_unsharded_campaign() {
        let d = tmp("merge");
        let c = campaign();
        let files = [(2, 3), (0, 3), (1, 3)].map(|s| write_shard(&d, s, &c));
        let (got_c, merged) = merge_shards(&files).unwrap();
        std::fs::remove_dir_all(&d).unwrap();
        assert_eq!(got_c, c);
        let all: Vec<SeedResult> = (11..16).map(result).collect();
        let unsharded = summarise(&c.scenario, recorded(&all).unwrap());
        let sharded = summarise(&c.scenario, merged);
        // Bit for bit, NaNs included (compared as JSON text).
        assert_eq!(
            serde_json::to_string(&unsharded).unwrap(),
            serde_json::to_string(&sharded).unwrap()
        );
        assert_eq!(sharded.runs, 5);
        assert_eq!(
            sharded.seeds.iter().map(|s| s.seed).collect::<Vec<_>>(),
            vec![11, 12, 13, 14, 15]
        );
    }

    #[test]
    fn shards_that_do_not_make_one_campaign_are_refused_with_the_reason() {
        let d = tmp("refuse");
        let c = campaign();
        let a = write_shard(&d, (0, 2), &c);
        let err = |files: &[PathBuf]| merge_shards(files).unwrap_err().to_string();
        assert!(
            err(std::slice::from_ref(&a)).contains("missing"),
            "{}",
            err(std::slice::from_ref(&a))
        );
        assert!(err(&[a.clone(), a.clone()]).contains("twice"));
        let mut other = c.clone();
        other.first_seed = 100;
        let d2 = tmp("refuse-other");
        let b = write_shard(&d2, (1, 2), &other);
        assert!(err(&[a.clone(), b]).contains("another campaign"));
        let c3 = write_shard(&d2, (1, 3), &c);
        assert!(err(&[a.clone(), c3]).contains("one of 2 shards"));
        // A shard that lost a seed.
        let b = write_shard(&d2, (1, 2), &c);
        let mut s: ShardFile = serde_json::from_str(&std::fs::read_to_string(&b).unwrap()).unwrap();
        s.seeds.pop();
        std::fs::write(&b, serde_json::to_string(&s).unwrap()).unwrap();
        assert!(err(&[a, b]).contains("incomplete or edited"));
        std::fs::remove_dir_all(&d).unwrap();
        std::fs::remove_dir_all(&d2).unwrap();
    }
}
