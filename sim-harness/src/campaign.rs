//! # Monte Carlo campaigns: many seeds in parallel, shards, and merging
//!
//! `sim-harness monte-carlo SCENARIO -n N --seed S --out DIR [--shard K/N]` flies the scenario
//! with seeds `S, S+1, …, S+N−1` (run `i` has seed `S + i`) in parallel (rayon), each into
//! `DIR/run_<i, 5 digits>/` (a complete run folder), then writes the aggregate of the runs it
//! flew. With `--shard K/M` (0 ≤ K < M) only runs with `i mod M = K` are flown and the
//! aggregate is `DIR/aggregate.shard-K-of-M.json`, so a campaign can be a Slurm or
//! Kubernetes job array (`K = $SLURM_ARRAY_TASK_ID` or `$JOB_COMPLETION_INDEX`) writing into
//! one shared `DIR` or into one folder per task. `sim-harness merge DIR...` then reads every
//! `run_*/summary.json` below the given folders (each seed once) and writes the campaign's
//! `aggregate.json`.
//!
//! The aggregate depends only on the set of run summaries (runs sorted by seed), so a
//! sharded and an unsharded campaign give the same statistics.

use std::path::{Path, PathBuf};

use anyhow::Context;
use rayon::prelude::*;
use serde::{Deserialize, Serialize};

use crate::run::{run, RunOptions, Summary};
use crate::scenario::Scenario;

/// Statistics of one scalar over the runs.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Spread {
    /// Runs with a value.
    pub n: usize,
    /// Mean.
    pub mean: f64,
    /// Sample standard deviation.
    pub std: f64,
    /// Smallest.
    pub min: f64,
    /// Largest.
    pub max: f64,
}

impl Spread {
    fn of(values: &[f64]) -> Self {
        let v: Vec<f64> = values.iter().copied().filter(|x| x.is_finite()).collect();
        if v.is_empty() {
            return Self::default();
        }
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = if v.len() > 1 {
            v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
        } else {
            0.0
        };
        Self {
            n: v.len(),
            mean,
            std: var.sqrt(),
            min: v.iter().copied().fold(f64::INFINITY, f64::min),
            max: v.iter().copied().fold(f64::NEG_INFINITY, f64::max),
        }
    }
}

/// aggregate.json.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct Aggregate {
    /// Scenario name(s).
    pub scenario: String,
    /// Runs aggregated.
    pub runs: usize,
    /// Their seeds, ascending.
    pub seeds: Vec<u64>,
    /// Per-axis rms attitude error of the scored window (arcsec), over runs.
    pub attitude_error_rms_arcsec: [Spread; 3],
    /// Max `|δθ|` of the scored window (arcsec), over runs.
    pub attitude_error_max_arcsec: Spread,
    /// Post-maneuver error (deg) per slew index, over runs.
    pub post_maneuver_error_deg: Vec<Spread>,
    /// Largest post-maneuver error of any slew of any run (deg).
    pub post_maneuver_error_max_deg: f64,
    /// Mean NEES per run, over runs.
    pub filter_nees_mean: Spread,
    /// Fine-mode fraction, over runs.
    pub fine_mode_fraction: Spread,
    /// Rejected measurements, over runs.
    pub rejected_measurements: Spread,
    /// Real-time factor, over runs.
    pub real_time_factor: Spread,
    /// The campaign this (shard's) aggregate belongs to; written by `monte-carlo`, checked by
    /// `merge` (absent in a merged aggregate and in files of older versions).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub campaign: Option<CampaignInfo>,
}

/// What a `monte-carlo` shard was asked to fly: `merge` combines only shards that agree.
#[derive(Clone, Debug, Default, Serialize, Deserialize, PartialEq)]
pub struct CampaignInfo {
    /// Scenario name.
    pub scenario: String,
    /// Runs in the whole campaign.
    pub runs: u32,
    /// Seed of run 0.
    pub first_seed: u64,
    /// Simulated duration of each run (s).
    pub duration_s: f64,
    /// `(K, M)`: this aggregate holds the runs with `i mod M = K`.
    pub shard: (u32, u32),
}

/// Aggregate run summaries (sorted by seed first, so the result does not depend on order).
#[must_use]
pub fn aggregate(summaries: &[Summary]) -> Aggregate {
    let mut s: Vec<&Summary> = summaries.iter().collect();
    s.sort_by_key(|x| x.seed);
    let col = |f: &dyn Fn(&Summary) -> f64| -> Vec<f64> { s.iter().map(|x| f(x)).collect() };
    let mut names: Vec<&str> = s.iter().map(|x| x.scenario.as_str()).collect();
    names.dedup();
    let slews = s
        .iter()
        .map(|x| x.post_maneuver_error_deg.len())
        .max()
        .unwrap_or(0);
    Aggregate {
        scenario: names.join(", "),
        runs: s.len(),
        seeds: s.iter().map(|x| x.seed).collect(),
        attitude_error_rms_arcsec: [0, 1, 2]
            .map(|i| Spread::of(&col(&|x| x.attitude_error_arcsec.rms[i]))),
        attitude_error_max_arcsec: Spread::of(&col(&|x| x.attitude_error_arcsec.max)),
        post_maneuver_error_deg: (0..slews)
            .map(|k| {
                Spread::of(
                    &s.iter()
                        .filter_map(|x| x.post_maneuver_error_deg.get(k).copied())
                        .collect::<Vec<_>>(),
                )
            })
            .collect(),
        post_maneuver_error_max_deg: s
            .iter()
            .flat_map(|x| x.post_maneuver_error_deg.iter().copied())
            .fold(0.0, f64::max),
        filter_nees_mean: Spread::of(&col(&|x| x.filter_nees_mean.unwrap_or(f64::NAN))),
        fine_mode_fraction: Spread::of(&col(&|x| x.fine_mode_fraction)),
        rejected_measurements: Spread::of(&col(&|x| x.rejected_measurements as f64)),
        real_time_factor: Spread::of(&col(&|x| x.timing.real_time_factor)),
        campaign: None,
    }
}

/// Parse `K/M` (0 ≤ K < M).
///
/// # Errors
/// Malformed text.
pub fn parse_shard(text: &str) -> anyhow::Result<(u32, u32)> {
    let (k, m) = text
        .split_once('/')
        .ok_or_else(|| anyhow::anyhow!("--shard must be K/M, got {text:?}"))?;
    let k: u32 = k
        .trim()
        .parse()
        .with_context(|| format!("--shard K in {text:?}"))?;
    let m: u32 = m
        .trim()
        .parse()
        .with_context(|| format!("--shard M in {text:?}"))?;
    if m == 0 || k >= m {
        anyhow::bail!("--shard K/M needs 0 ≤ K < M, got {text:?}");
    }
    Ok((k, m))
}

/// Options of a campaign.
#[derive(Clone, Debug)]
pub struct CampaignOptions {
    /// Runs in the whole campaign.
    pub runs: u32,
    /// Seed of run 0.
    pub seed: u64,
    /// Output folder.
    pub out_dir: PathBuf,
    /// `(K, M)`: fly runs with `i mod M = K`.
    pub shard: (u32, u32),
    /// `--tables DIR`.
    pub tables_dir: Option<PathBuf>,
    /// Duration override (s).
    pub duration_s: Option<f64>,
    /// Replace run folders another tool wrote (`--force`).
    pub force: bool,
}

/// Fly a campaign (or its shard) and write its aggregate; returns the aggregate and where it
/// was written.
///
/// # Errors
/// The first failing run (named by index and seed), or I/O.
pub fn monte_carlo(
    scenario: &Scenario,
    opts: &CampaignOptions,
    on_done: &(dyn Fn() + Sync),
) -> anyhow::Result<(Aggregate, PathBuf)> {
    std::fs::create_dir_all(&opts.out_dir)
        .with_context(|| format!("creating {}", opts.out_dir.display()))?;
    let (k, m) = opts.shard;
    let indices: Vec<u32> = (0..opts.runs).filter(|i| i % m == k).collect();
    let summaries: Vec<anyhow::Result<Summary>> = indices
        .par_iter()
        .map(|&i| {
            let mut s = scenario.clone();
            s.seed = opts.seed.wrapping_add(u64::from(i));
            if let Some(d) = opts.duration_s {
                s.duration_s = d;
            }
            let seed = s.seed;
            let folder = opts.out_dir.join(format!("run_{i:05}"));
            let inputs: Vec<&Path> = opts.tables_dir.as_deref().into_iter().collect();
            let out =
                crate::outdir::OutputDir::begin(&folder, "sim-harness run", opts.force, &inputs)
                    .and_then(|dir| {
                        let summary = run(
                            s,
                            &RunOptions {
                                out_dir: Some(dir.path().to_path_buf()),
                                tables_dir: opts.tables_dir.clone(),
                                progress: false,
                            },
                        )?;
                        dir.commit()?;
                        Ok(summary)
                    })
                    .with_context(|| format!("run {i} (seed {seed})"));
            on_done();
            out
        })
        .collect();
    let summaries: Vec<Summary> = summaries.into_iter().collect::<anyhow::Result<_>>()?;
    let mut agg = aggregate(&summaries);
    agg.campaign = Some(CampaignInfo {
        scenario: scenario.name.clone(),
        runs: opts.runs,
        first_seed: opts.seed,
        duration_s: opts.duration_s.unwrap_or(scenario.duration_s),
        shard: opts.shard,
    });
    let name = if m == 1 {
        "aggregate.json".to_owned()
    } else {
        format!("aggregate.shard-{k}-of-{m}.json")
    };
    let path = opts.out_dir.join(name);
    write_json_atomic(&path, &agg)?;
    Ok((agg, path))
}

/// Every `run_*/summary.json` below the folders (a folder that is itself a run counts too),
/// with its file, in folder order.
///
/// # Errors
/// Unreadable folders or malformed summaries (named).
pub fn collect_summary_files(dirs: &[PathBuf]) -> anyhow::Result<Vec<(PathBuf, Summary)>> {
    let mut files = Vec::new();
    for d in dirs {
        let own = d.join("summary.json");
        if own.exists() {
            files.push(own);
        }
        let mut entries: Vec<PathBuf> = std::fs::read_dir(d)
            .with_context(|| format!("cannot read {}", d.display()))?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| {
                p.is_dir()
                    && p.file_name()
                        .is_some_and(|n| n.to_string_lossy().starts_with("run_"))
            })
            .collect();
        entries.sort();
        files.extend(
            entries
                .into_iter()
                .map(|p| p.join("summary.json"))
                .filter(|p| p.exists()),
        );
    }
    let mut out = Vec::new();
    for f in files {
        let text =
            std::fs::read_to_string(&f).with_context(|| format!("cannot read {}", f.display()))?;
        let s: Summary = serde_json::from_str(&text)
            .with_context(|| format!("{} is not a run summary", f.display()))?;
        out.push((f, s));
    }
    Ok(out)
}

/// Every run summary below the folders, one per (scenario, seed) (the first found).
///
/// # Errors
/// Unreadable folders or malformed summaries (named).
pub fn collect_summaries(dirs: &[PathBuf]) -> anyhow::Result<Vec<Summary>> {
    let mut out: Vec<Summary> = Vec::new();
    for (_, s) in collect_summary_files(dirs)? {
        if !out
            .iter()
            .any(|o| o.seed == s.seed && o.scenario == s.scenario)
        {
            out.push(s);
        }
    }
    Ok(out)
}

/// The campaign descriptions (`aggregate*.json` written by `monte-carlo`) in the folders.
fn campaign_infos(dirs: &[PathBuf]) -> anyhow::Result<Vec<(PathBuf, CampaignInfo)>> {
    let mut out = Vec::new();
    for d in dirs {
        let mut files: Vec<PathBuf> = std::fs::read_dir(d)
            .with_context(|| format!("cannot read {}", d.display()))?
            .filter_map(Result::ok)
            .map(|e| e.path())
            .filter(|p| {
                p.file_name().is_some_and(|n| {
                    let n = n.to_string_lossy();
                    n.starts_with("aggregate") && n.ends_with(".json")
                })
            })
            .collect();
        files.sort();
        for f in files {
            let text = std::fs::read_to_string(&f)
                .with_context(|| format!("cannot read {}", f.display()))?;
            let agg: Aggregate = serde_json::from_str(&text)
                .with_context(|| format!("{} is not an aggregate", f.display()))?;
            if let Some(c) = agg.campaign {
                out.push((f, c));
            }
        }
    }
    Ok(out)
}

/// Shards and runs belong to one campaign: one scenario and duration for every run, one seed
/// once; the `monte-carlo` descriptions agree on scenario, runs, first seed, duration and
/// shard count, every shard is present once, and the seeds are the campaign's.
///
/// # Errors
/// The first disagreement, naming the two files.
pub fn check_mergeable(
    summaries: &[(PathBuf, Summary)],
    infos: &[(PathBuf, CampaignInfo)],
) -> anyhow::Result<()> {
    let Some((f0, s0)) = summaries.first() else {
        anyhow::bail!("no run_*/summary.json found under the given folders");
    };
    for (f, s) in summaries {
        if s.scenario != s0.scenario {
            anyhow::bail!(
                "{} is scenario {:?} but {} is {:?}: merge combines the runs of one campaign only",
                f.display(),
                s.scenario,
                f0.display(),
                s0.scenario
            );
        }
        if (s.timing.sim_seconds - s0.timing.sim_seconds).abs() > 1e-6 {
            anyhow::bail!(
                "{} simulated {} s but {} simulated {} s: merge combines runs of one duration only",
                f.display(),
                s.timing.sim_seconds,
                f0.display(),
                s0.timing.sim_seconds
            );
        }
    }
    for (i, (fa, a)) in summaries.iter().enumerate() {
        for (fb, b) in &summaries[i + 1..] {
            if a.seed == b.seed {
                anyhow::bail!(
                    "seed {} appears twice ({} and {}): the folders overlap; give each shard once",
                    a.seed,
                    fa.display(),
                    fb.display()
                );
            }
        }
    }
    let Some((g0, c0)) = infos.first() else {
        return Ok(());
    };
    let mut shards = Vec::new();
    for (g, c) in infos {
        let same = c.scenario == c0.scenario
            && c.runs == c0.runs
            && c.first_seed == c0.first_seed
            && (c.duration_s - c0.duration_s).abs() < 1e-9
            && c.shard.1 == c0.shard.1;
        if !same {
            anyhow::bail!(
                "{} (scenario {:?}, {} runs from seed {}, {} s, {} shard(s)) and {} (scenario {:?}, {} runs from seed {}, {} s, {} shard(s)) describe different campaigns",
                g.display(), c.scenario, c.runs, c.first_seed, c.duration_s, c.shard.1,
                g0.display(), c0.scenario, c0.runs, c0.first_seed, c0.duration_s, c0.shard.1
            );
        }
        if shards.contains(&c.shard.0) {
            anyhow::bail!(
                "shard {} of {} given twice ({})",
                c.shard.0,
                c.shard.1,
                g.display()
            );
        }
        shards.push(c.shard.0);
    }
    if c0.scenario != s0.scenario {
        anyhow::bail!(
            "{} describes scenario {:?} but the runs are {:?}",
            g0.display(),
            c0.scenario,
            s0.scenario
        );
    }
    let missing: Vec<u32> = (0..c0.shard.1).filter(|k| !shards.contains(k)).collect();
    if !missing.is_empty() {
        anyhow::bail!(
            "shard(s) {missing:?} of {} missing: give every shard's folder (the aggregate would be of part of the campaign)",
            c0.shard.1
        );
    }
    let mut seeds: Vec<u64> = summaries.iter().map(|(_, s)| s.seed).collect();
    seeds.sort_unstable();
    let want: Vec<u64> = (0..u64::from(c0.runs))
        .map(|i| c0.first_seed.wrapping_add(i))
        .collect();
    if seeds != want {
        anyhow::bail!(
            "the runs found have seeds {:?}..{:?} ({} runs) but the campaign is {} runs from seed {}: a run is missing or foreign",
            seeds.first(),
            seeds.last(),
            seeds.len(),
            c0.runs,
            c0.first_seed
        );
    }
    Ok(())
}

/// `merge`: aggregate every run below `dirs` into `out` (default `dirs[0]/aggregate.json`),
/// after [`check_mergeable`].
///
/// # Errors
/// [`crate::InputError`] when no runs are found or they are not of one campaign; I/O.
pub fn merge(dirs: &[PathBuf], out: Option<&Path>) -> anyhow::Result<(Aggregate, PathBuf)> {
    let found = collect_summary_files(dirs).map_err(crate::InputError::from)?;
    let infos = campaign_infos(dirs).map_err(crate::InputError::from)?;
    check_mergeable(&found, &infos).map_err(crate::InputError::from)?;
    let summaries: Vec<Summary> = found.into_iter().map(|(_, s)| s).collect();
    let agg = aggregate(&summaries);
    let path = out.map_or_else(
        || {
            dirs.first()
                .map_or_else(|| PathBuf::from("."), Clone::clone)
                .join("aggregate.json")
        },
        Path::to_path_buf,
    );
    write_json_atomic(&path, &agg)?;
    Ok((agg, path))
}

fn write_json_atomic(path: &Path, v: &impl Serialize) -> anyhow::Result<()> {
    let partial = PathBuf::from(format!("{}.partial", path.display()));
    std::fs::write(&partial, serde_json::to_string_pretty(v)? + "\n")
        .with_context(|| format!("writing {}", partial.display()))?;
    std::fs::rename(&partial, path).with_context(|| format!("renaming to {}", path.display()))?;
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn shard_parsing_and_order_independent_aggregate() {
        assert_eq!(parse_shard("2/5").unwrap(), (2, 5));
        assert!(parse_shard("5/5").is_err());
        assert!(parse_shard("x").is_err());
        let mk = |seed: u64, rms: f64| Summary {
            scenario: "s".into(),
            seed,
            attitude_error_arcsec: crate::run::ErrorStats {
                rms: [rms; 3],
                ..Default::default()
            },
            post_maneuver_error_deg: vec![rms / 100.0],
            ..Summary::default()
        };
        let a = aggregate(&[mk(1, 2.0), mk(2, 4.0), mk(3, 6.0)]);
        let b = aggregate(&[mk(3, 6.0), mk(1, 2.0), mk(2, 4.0)]);
        assert_eq!(a, b);
        assert_eq!(a.seeds, vec![1, 2, 3]);
        assert!((a.attitude_error_rms_arcsec[0].mean - 4.0).abs() < 1e-12);
        assert!((a.attitude_error_rms_arcsec[0].std - 2.0).abs() < 1e-12);
        assert!((a.post_maneuver_error_max_deg - 0.06).abs() < 1e-12);
    }
}
