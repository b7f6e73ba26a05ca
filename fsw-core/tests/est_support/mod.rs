//! Shared helpers of the `est_*` integration tests: a deterministic PRNG, Gaussian samples,
//! random rotations, and a reader for the reference CSV files in `data/`.
#![allow(dead_code)]

pub mod filter_truth;

use fsw_core::attitude::Quat;
use nalgebra::Vector3;

// SplitMix64, the workspace's one definition (fsw-core cannot depend on gro-reference).
#[path = "../../../gro-reference/src/splitmix.rs"]
mod splitmix;

/// SplitMix64: small, deterministic, good enough for test noise.
pub struct Rng(splitmix::SplitMix64);

impl Rng {
    pub fn new(seed: u64) -> Self {
        Self(splitmix::SplitMix64::new(seed))
    }

    pub fn next_u64(&mut self) -> u64 {
        self.0.next_u64()
    }

    /// Uniform in [0, 1).
    pub fn uniform(&mut self) -> f64 {
        self.0.unit()
    }

    /// Uniform in [lo, hi).
    pub fn range(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.uniform()
    }

    /// Standard normal (Box–Muller).
    pub fn gauss(&mut self) -> f64 {
        let u1 = self.uniform().max(1e-300);
        let u2 = self.uniform();
        (-2.0 * u1.ln()).sqrt() * (std::f64::consts::TAU * u2).cos()
    }

    pub fn gauss3(&mut self) -> Vector3<f64> {
        Vector3::new(self.gauss(), self.gauss(), self.gauss())
    }

    /// Uniform on the unit sphere.
    pub fn unit_vector(&mut self) -> Vector3<f64> {
        let z = self.range(-1.0, 1.0);
        let phi = self.range(0.0, std::f64::consts::TAU);
        let r = (1.0 - z * z).sqrt();
        Vector3::new(r * phi.cos(), r * phi.sin(), z)
    }

    /// Uniform random rotation.
    pub fn quaternion(&mut self) -> Quat {
        Quat::new(self.gauss(), self.gauss(), self.gauss(), self.gauss()).normalized()
    }
}

/// A CSV file of `data/`: `#` comment lines, one header, comma-separated rows.
pub struct Csv {
    pub header: Vec<String>,
    pub rows: Vec<Vec<String>>,
}

impl Csv {
    pub fn read(name: &str) -> Self {
        let path = format!("{}/../data/{name}", env!("CARGO_MANIFEST_DIR"));
        let text = std::fs::read_to_string(&path).unwrap_or_else(|e| panic!("{path}: {e}"));
        let mut lines = text
            .lines()
            .filter(|l| !l.starts_with('#') && !l.trim().is_empty());
        let header = lines
            .next()
            .expect("header")
            .split(',')
            .map(str::to_owned)
            .collect();
        let rows = lines
            .map(|l| l.split(',').map(str::to_owned).collect())
            .collect();
        Self { header, rows }
    }

    pub fn col(&self, name: &str) -> usize {
        self.header
            .iter()
            .position(|h| h == name)
            .unwrap_or_else(|| panic!("no column {name}"))
    }

    pub fn f64(&self, row: &[String], col: usize) -> f64 {
        row[col]
            .parse()
            .unwrap_or_else(|e| panic!("{}: {e}", row[col]))
    }

    /// The three columns `prefix` + `x`, `y`, `z` (as `app_x`, `app_y`, `app_z`).
    pub fn cols3(&self, prefix: &str) -> [usize; 3] {
        ["x", "y", "z"].map(|axis| self.col(&format!("{prefix}{axis}")))
    }

    /// The vector of `row` in the columns `cols` ([`Csv::cols3`]).
    pub fn vec3(&self, row: &[String], cols: [usize; 3]) -> Vector3<f64> {
        Vector3::from(cols.map(|c| self.f64(row, c)))
    }
}
