//! `momentum-plot`: fly a scenario and draw the true wheel momentum and the torquer bars'
//! dipole against time (issue 20's momentum-unloading must-show, `docs/magnetics.md` §7).
//!
//! Why a binary of the `tests` crate: the plot needs the simulator's truth wheel momentum
//! every cycle (the OBC has no tachometers and the telemetry does not carry it), and the
//! figure code of the ground tool (`ground_tool::report::figure`); the `tests` crate is the
//! one that depends on both. The flight is `sim-harness run`'s closed loop, cycle by cycle.
//!
//! Writes OUT/wheel_momentum.png and OUT/wheel_momentum.csv (one row per `--every-s`, by
//! default an orbit: the interval's end time, each wheel's largest `|h|`, the largest norm of
//! the wheels' vector sum, the RMS dipole of each bar — per interval, so that the orbit's own
//! swings do not hide the trend and the PNG stays small) and prints the largest wheel
//! momentum (`summary.json`'s `max_wheel_momentum_nms`, taken over every cycle).

use std::fmt::Write as _;
use std::path::PathBuf;

use clap::Parser;
use ground_tool::report::figure::{draw, Figure, Kind, Layer, Panel};
use plotters::style::RGBColor;
use sim_harness::closed_loop::Simulation;
use sim_harness::scenario::Scenario;

#[derive(Parser)]
#[command(
    name = "momentum-plot",
    about = "Fly a scenario; plot the true wheel momentum and the torquer-bar dipoles against time"
)]
struct Cli {
    /// Scenario TOML file.
    scenario: PathBuf,
    /// Output folder (created).
    #[arg(long)]
    out: PathBuf,
    /// Override the scenario's seed.
    #[arg(long)]
    seed: Option<u64>,
    /// Override the scenario's duration (s).
    #[arg(long)]
    duration: Option<f64>,
    /// Interval of the plot's and the CSV's maxima and RMS (s; default one orbit).
    #[arg(long, default_value_t = 5_400.0)]
    every_s: f64,
}

const COLORS: [RGBColor; 5] = [
    RGBColor(31, 119, 180),
    RGBColor(255, 127, 14),
    RGBColor(44, 160, 44),
    RGBColor(214, 39, 40),
    RGBColor(0, 0, 0),
];

/// Per interval: (end time in days, largest |h| per wheel, largest |Σ h|, RMS bar dipoles).
struct Samples {
    rows: Vec<(f64, [f64; 4], f64, [f64; 3])>,
    max_wheel_nms: f64,
    limit_nms: f64,
}

fn fly(cli: &Cli) -> anyhow::Result<Samples> {
    let mut scenario = Scenario::load(&cli.scenario)?;
    if let Some(s) = cli.seed {
        scenario.seed = s;
    }
    if let Some(d) = cli.duration {
        scenario.duration_s = d;
    }
    scenario.validate()?;
    let axes = scenario.dynamics.wheel_axes_acs.clone();
    let limit_nms = scenario.dynamics.wheel_momentum_limit_nms;
    let mut sim = Simulation::new(scenario, None)?;
    let mut out = Samples {
        rows: Vec::new(),
        max_wheel_nms: 0.0,
        limit_nms,
    };
    let mut next_t = cli.every_s;
    let mut dipole_sq = [0.0; 3];
    let mut wheel_max = [0.0_f64; 4];
    let mut total_max = 0.0_f64;
    let mut n = 0.0;
    while let Some(rec) = sim.step() {
        let h = sim.true_attitude().wheel_momentum_nms;
        for (m, x) in wheel_max.iter_mut().zip(h) {
            *m = m.max(x.abs());
            out.max_wheel_nms = out.max_wheel_nms.max(x.abs());
        }
        let total = axes
            .iter()
            .zip(h)
            .fold(nalgebra::Vector3::zeros(), |acc, (a, hk)| {
                acc + nalgebra::Vector3::from(*a).normalize() * hk
            });
        total_max = total_max.max(total.norm());
        for (s, d) in dipole_sq.iter_mut().zip(rec.torquer_dipole_am2) {
            *s += d * d;
        }
        n += 1.0;
        if rec.truth.t_s + 1e-9 >= next_t {
            let rms = dipole_sq.map(|s| (s / n).sqrt());
            out.rows
                .push((rec.truth.t_s / 86_400.0, wheel_max, total_max, rms));
            dipole_sq = [0.0; 3];
            wheel_max = [0.0; 4];
            total_max = 0.0;
            n = 0.0;
            next_t += cli.every_s;
        }
    }
    Ok(out)
}

fn line(label: Option<String>, color: RGBColor, points: Vec<(f64, f64)>) -> Layer {
    Layer {
        label,
        color,
        kind: Kind::Line { points, gap: 1.0 },
    }
}

fn main() -> anyhow::Result<()> {
    let cli = Cli::parse();
    std::fs::create_dir_all(&cli.out)?;
    let s = fly(&cli)?;
    let mut csv = String::from(
        "t_day,max_abs_h_wheel1_nms,max_abs_h_wheel2_nms,max_abs_h_wheel3_nms,max_abs_h_wheel4_nms,max_h_wheels_norm_nms,rms_m_bar1_am2,rms_m_bar2_am2,rms_m_bar3_am2\n",
    );
    for (t, h, norm, m) in &s.rows {
        writeln!(
            csv,
            "{t:.6},{:.4},{:.4},{:.4},{:.4},{norm:.4},{:.2},{:.2},{:.2}",
            h[0], h[1], h[2], h[3], m[0], m[1], m[2]
        )?;
    }
    std::fs::write(cli.out.join("wheel_momentum.csv"), csv)?;
    let mut wheels: Vec<Layer> = (0..4)
        .map(|k| {
            line(
                Some(format!("wheel {}: largest |h|", k + 1)),
                COLORS[k],
                s.rows.iter().map(|r| (r.0, r.1[k])).collect(),
            )
        })
        .collect();
    wheels.push(line(
        Some("largest |Σ h| (vector sum)".into()),
        COLORS[4],
        s.rows.iter().map(|r| (r.0, r.2)).collect(),
    ));
    wheels.push(Layer {
        label: None,
        color: RGBColor(150, 150, 150),
        kind: Kind::HLine(s.limit_nms),
    });
    wheels.push(Layer {
        label: None,
        color: RGBColor(150, 150, 150),
        kind: Kind::HLine(0.0),
    });
    let bars: Vec<Layer> = (0..3)
        .map(|k| {
            line(
                Some(format!("bar {} (ACS {})", k + 1, ["x", "y", "z"][k])),
                COLORS[k],
                s.rows.iter().map(|r| (r.0, r.3[k])).collect(),
            )
        })
        .collect();
    let fig = Figure {
        title: format!(
            "{}: wheel momentum with the torquer bars",
            cli.scenario
                .file_stem()
                .unwrap_or_default()
                .to_string_lossy()
        ),
        x_label: "time (days)".into(),
        x_range: None,
        shared_y: false,
        panels: vec![
            Panel {
                title: format!(
                    "true wheel momentum, largest per {} s (wheel limit {} N·m·s, grey)",
                    cli.every_s, s.limit_nms
                ),
                y_label: "N·m·s".into(),
                layers: wheels,
                y_quantile: None,
            },
            Panel {
                title: format!("torquer-bar dipole, RMS per {} s", cli.every_s),
                y_label: "A·m²".into(),
                layers: bars,
                y_quantile: None,
            },
        ],
        notes: vec![format!(
            "largest |h| of a wheel: {:.1} N·m·s",
            s.max_wheel_nms
        )],
    };
    draw(&cli.out.join("wheel_momentum.png"), &fig)?;
    println!(
        "max_wheel_momentum_nms {:.3}; wrote {}/wheel_momentum.png, wheel_momentum.csv",
        s.max_wheel_nms,
        cli.out.display()
    );
    Ok(())
}
