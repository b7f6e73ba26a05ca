//! # Distribution functions and multiple-test correction
//!
//! Why here: the structure tests and the effect selection need p-values of χ² and F
//! statistics; the workspace has no statistics crate, so the two special functions
//! (regularised incomplete gamma and beta, Numerical Recipes §6.2 and §6.4 forms) are
//! implemented once, with unit tests against tabulated quantiles.

/// `ln Γ(x)` for `x > 0` (Lanczos, g = 7, 9 terms; relative error < 1e-14).
#[must_use]
pub fn ln_gamma(x: f64) -> f64 {
    const G: f64 = 7.0;
    const C: [f64; 9] = [
        0.999_999_999_999_809_9,
        676.520_368_121_885_1,
        -1_259.139_216_722_402_8,
        771.323_428_777_653_1,
        -176.615_029_162_140_6,
        12.507_343_278_686_905,
        -0.138_571_095_265_720_12,
        9.984_369_578_019_572e-6,
        1.505_632_735_149_311_6e-7,
    ];
    if x < 0.5 {
        // Reflection.
        let pi = std::f64::consts::PI;
        return (pi / (pi * x).sin()).ln() - ln_gamma(1.0 - x);
    }
    let x = x - 1.0;
    let mut a = C[0];
    let t = x + G + 0.5;
    for (i, c) in C.iter().enumerate().skip(1) {
        a += c / (x + i as f64);
    }
    0.5 * (2.0 * std::f64::consts::PI).ln() + (x + 0.5) * t.ln() - t + a.ln()
}

/// Regularised upper incomplete gamma `Q(a, x) = Γ(a, x)/Γ(a)`.
#[must_use]
pub fn gamma_q(a: f64, x: f64) -> f64 {
    if !(a > 0.0) || x.is_nan() {
        return f64::NAN;
    }
    if x <= 0.0 {
        return 1.0;
    }
    if x < a + 1.0 {
        // Series for P.
        let mut sum = 1.0 / a;
        let mut term = sum;
        let mut ap = a;
        for _ in 0..10_000 {
            ap += 1.0;
            term *= x / ap;
            sum += term;
            if term.abs() < sum.abs() * 1e-16 {
                break;
            }
        }
        let p = sum * (-x + a * x.ln() - ln_gamma(a)).exp();
        (1.0 - p).clamp(0.0, 1.0)
    } else {
        // Continued fraction for Q (modified Lentz).
        let tiny = 1e-300;
        let mut b = x + 1.0 - a;
        let mut c = 1.0 / tiny;
        let mut d = 1.0 / b;
        let mut h = d;
        for i in 1..10_000 {
            let an = -(i as f64) * (i as f64 - a);
            b += 2.0;
            d = an * d + b;
            if d.abs() < tiny {
                d = tiny;
            }
            c = b + an / c;
            if c.abs() < tiny {
                c = tiny;
            }
            d = 1.0 / d;
            let del = d * c;
            h *= del;
            if (del - 1.0).abs() < 1e-16 {
                break;
            }
        }
        ((-x + a * x.ln() - ln_gamma(a)).exp() * h).clamp(0.0, 1.0)
    }
}

/// Survival function of χ² with `k` degrees of freedom.
#[must_use]
pub fn chi2_sf(x: f64, k: f64) -> f64 {
    if x <= 0.0 {
        return 1.0;
    }
    gamma_q(0.5 * k, 0.5 * x)
}

/// `χ²/dof` and the probability of a χ² at least `chi2` over `dof` degrees of freedom
/// ([`chi2_sf`]); both NaN without a degree of freedom.
#[must_use]
pub fn chi2_per_dof(chi2: f64, dof: usize) -> (f64, f64) {
    if dof > 0 {
        (chi2 / dof as f64, chi2_sf(chi2, dof as f64))
    } else {
        (f64::NAN, f64::NAN)
    }
}

/// One step of the modified Lentz algorithm for a continued fraction's term `aa`:
/// `d ← 1/(1 + aa d)`, `c ← 1 + aa/c`, each kept away from zero by `tiny`.
fn lentz_step(aa: f64, c: &mut f64, d: &mut f64, tiny: f64) {
    *d = 1.0 + aa * *d;
    if d.abs() < tiny {
        *d = tiny;
    }
    *c = 1.0 + aa / *c;
    if c.abs() < tiny {
        *c = tiny;
    }
    *d = 1.0 / *d;
}

fn beta_cf(a: f64, b: f64, x: f64) -> f64 {
    let tiny = 1e-300;
    let qab = a + b;
    let qap = a + 1.0;
    let qam = a - 1.0;
    let mut c = 1.0;
    let mut d = 1.0 - qab * x / qap;
    if d.abs() < tiny {
        d = tiny;
    }
    d = 1.0 / d;
    let mut h = d;
    for m in 1..10_000 {
        let m = m as f64;
        let m2 = 2.0 * m;
        let aa = m * (b - m) * x / ((qam + m2) * (a + m2));
        lentz_step(aa, &mut c, &mut d, tiny);
        h *= d * c;
        let aa = -(a + m) * (qab + m) * x / ((a + m2) * (qap + m2));
        lentz_step(aa, &mut c, &mut d, tiny);
        let del = d * c;
        h *= del;
        if (del - 1.0).abs() < 1e-15 {
            break;
        }
    }
    h
}

/// Regularised incomplete beta `I_x(a, b)`.
#[must_use]
pub fn beta_inc(a: f64, b: f64, x: f64) -> f64 {
    if x <= 0.0 {
        return 0.0;
    }
    if x >= 1.0 {
        return 1.0;
    }
    let ln_front = ln_gamma(a + b) - ln_gamma(a) - ln_gamma(b) + a * x.ln() + b * (1.0 - x).ln();
    let front = ln_front.exp();
    if x < (a + 1.0) / (a + b + 2.0) {
        (front * beta_cf(a, b, x) / a).clamp(0.0, 1.0)
    } else {
        (1.0 - front * beta_cf(b, a, 1.0 - x) / b).clamp(0.0, 1.0)
    }
}

/// Survival function of Fisher's F with `(d1, d2)` degrees of freedom.
#[must_use]
pub fn f_sf(f: f64, d1: f64, d2: f64) -> f64 {
    if !(f > 0.0) {
        return 1.0;
    }
    if d2 > 1e7 {
        // F·d1 → χ²(d1).
        return chi2_sf(f * d1, d1);
    }
    let x = d2 / (d2 + d1 * f);
    beta_inc(0.5 * d2, 0.5 * d1, x)
}

/// Two-sided normal tail probability of `|z|`.
#[must_use]
pub fn normal_two_sided(z: f64) -> f64 {
    chi2_sf(z * z, 1.0)
}

/// Holm–Bonferroni: adjusted p-values (same order as the input), monotone, ≤ 1.
#[must_use]
pub fn holm_adjust(p: &[f64]) -> Vec<f64> {
    let m = p.len();
    let mut order: Vec<usize> = (0..m).collect();
    order.sort_by(|&a, &b| p[a].total_cmp(&p[b]));
    let mut out = vec![1.0; m];
    let mut running: f64 = 0.0;
    for (rank, &i) in order.iter().enumerate() {
        let adj = ((m - rank) as f64 * p[i]).min(1.0);
        running = running.max(adj);
        out[i] = running;
    }
    out
}

#[cfg(test)]
#[allow(clippy::unwrap_used, clippy::expect_used, clippy::panic)]
mod tests {
    use super::*;

    #[test]
    fn chi2_quantiles() {
        // Tabulated: χ²₁ 3.841 → 0.05; χ²₅ 11.07 → 0.05; χ²₁₀ 23.21 → 0.01; χ²₂ 13.82 → 0.001.
        assert!((chi2_sf(3.841_458_8, 1.0) - 0.05).abs() < 1e-6);
        assert!((chi2_sf(11.070_497_7, 5.0) - 0.05).abs() < 1e-6);
        assert!((chi2_sf(23.209_251, 10.0) - 0.01).abs() < 1e-6);
        assert!((chi2_sf(13.815_511, 2.0) - 0.001).abs() < 1e-7);
        assert!((chi2_sf(1000.0, 1000.0) - 0.4940).abs() < 1e-3);
    }

    #[test]
    fn f_quantiles() {
        // F(3, 20) 3.098 → 0.05; F(1, 1000) 6.66 → 0.01; F(10, 100) 2.51 → 0.01.
        assert!((f_sf(3.098_391, 3.0, 20.0) - 0.05).abs() < 1e-5);
        assert!((f_sf(6.660_3, 1.0, 1000.0) - 0.01).abs() < 1e-4);
        assert!((f_sf(2.502_5, 10.0, 100.0) - 0.01).abs() < 2e-4);
        assert!((f_sf(2.0, 4.0, 1e9) - chi2_sf(8.0, 4.0)).abs() < 1e-9);
    }

    #[test]
    fn holm_is_monotone() {
        let adj = holm_adjust(&[0.01, 0.04, 0.03, 0.005]);
        assert!((adj[3] - 0.02).abs() < 1e-12);
        assert!((adj[0] - 0.03).abs() < 1e-12);
        assert!((adj[2] - 0.06).abs() < 1e-12);
        assert!((adj[1] - 0.06).abs() < 1e-12);
    }
}
