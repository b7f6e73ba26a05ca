//! `ground-tool`: command-line front end of the flight-dynamics ground tool.
/// jemalloc instead of glibc's malloc. Six months of telemetry free a chain's worth of mid-sized
/// blocks before the analysis allocates its own: glibc keeps that memory mapped (its mmap
/// threshold rises with every large block freed, and a fragmented heap cannot shrink), ≈ 0.1 GB
/// of the peak; jemalloc returns it. `diagnose` on six months: 0.99–1.03 × 10⁹ B peak RSS with
/// glibc, 0.92–0.95 × 10⁹ B with jemalloc, the same report (`docs/performance.md`).
#[global_allocator]
static GLOBAL: tikv_jemallocator::Jemalloc = tikv_jemallocator::Jemalloc;

use anyhow::{Context, Result};
use clap::{Parser, Subcommand};
use ground_tool::run_check::CommandArgs;

#[derive(Parser)]
#[command(
    name = "ground-tool",
    about = "CGRO flight-dynamics ground tool: telemetry processing, alignment (FFCAL) and gyro (IRUCAL) calibration, uplink tables, the paper reproduced",
    long_about = "The flight-dynamics side of the emulated Compton Gamma Ray Observatory (Davis et al., \
in-flight attitude sensor calibration, 1991).\n\n\
Typical loop:\n  sim-harness run gro-early-mission --out runs/a      # fly with the prelaunch tables\n  \
ground-tool calibrate runs/a --out runs/a-cal        # TP -> FADS -> FFCAL -> adjustment -> IRUCAL -> tables\n  \
sim-harness run gro-early-mission --out runs/b --tables runs/a-cal/tables   # fly again\n\n\
Every command reads a run folder (telemetry.bin, optional metadata.json; docs/icd.md) or table \
images; none estimates anything from the simulator's truth.json (diagnose adds a scoring section \
when one is there). `COMMAND --help` says what each reads and writes, with an example.\n\n\
Output folders (calibrate, diagnose): written as a temporary sibling .OUT.tmp-PID and renamed \
into place, so OUT holds one whole result or its previous content; OUT/tables/manifest.json names \
the tables to fly (with their CRC-32), and `sim-harness run --tables OUT/tables` loads only those. \
A non-empty OUT that is not a previous output of the same command is refused unless --force; a \
second writer into the same OUT fails (lock file .OUT.lock).\n\n\
Exit codes (every binary of the workspace): 0 success, 1 runtime failure (I/O, another writer busy), \
2 bad or insufficient input (the message names the file, the field and the cause, and what would fix it)."
)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

/// The run folder a command reads and the output folder it writes (calibrate, diagnose,
/// allan).
#[derive(clap::Args)]
struct RunOutput {
    /// Run folder with telemetry.bin.
    run_dir: std::path::PathBuf,
    /// Output folder (replaced whole when it is a previous output of the same command).
    #[arg(long)]
    out: std::path::PathBuf,
    /// Replace the whole content of a non-empty OUT that is not a previous output of the
    /// same command.
    #[arg(long)]
    force: bool,
}

/// The tables the run flew (calibrate, diagnose).
#[derive(clap::Args)]
struct FlownTables {
    /// Tables folder of the images that were flown (its manifest.json lists them, e.g. the
    /// tables/ of an earlier calibrate); default: the run's activated uploads (metadata.json
    /// `uploads`), else the boot tables. A folder that does not exist or has no manifest, or
    /// tables the housekeeping says the OBC did not fly, are refused (exit code 2).
    #[arg(long)]
    tables: Option<std::path::PathBuf>,
    /// Take the tables given with --tables as flown even where the telemetry says the OBC
    /// flew others (the housekeeping's active-table CRCs, docs/icd.md "Flown tables"): a
    /// what-if; the mismatch is then a warning instead of a refusal (exit code 2).
    #[arg(long, requires = "tables")]
    trust_tables: bool,
}

/// What a command prints (calibrate, diagnose, allan).
#[derive(clap::Args)]
struct PrintOptions {
    /// Print the JSON report (report.json; allan.json for allan) to stdout.
    #[arg(long)]
    json: bool,
    /// No progress on stderr (it is also hidden when stderr is not a terminal); the output
    /// files are the same either way.
    #[arg(long, short)]
    quiet: bool,
}

impl RunOutput {
    /// The arguments every run-folder command passes on.
    fn with<'a>(
        &'a self,
        tables: Option<&'a std::path::Path>,
        print: &PrintOptions,
    ) -> CommandArgs<'a> {
        CommandArgs {
            run_dir: &self.run_dir,
            out: &self.out,
            force: self.force,
            tables,
            json: print.json,
            quiet: print.quiet,
            trust_tables: false,
        }
    }
}

#[derive(Subcommand)]
enum Command {
    /// Calibrate from a run folder: TP -> DA/FADS -> FFCAL -> adjustment -> IRUCAL -> tables.
    ///
    /// Finds the sensor alignments (FFCAL, then the paper's adjustment that keeps the OBC's
    /// attitude frame) and the gyro scale factors and misalignments (IRUCAL) from the
    /// telemetry alone, validates each new table on held-out blocks of time, and writes the
    /// tables to uplink.
    ///
    /// Reads RUN_DIR/telemetry.bin (docs/icd.md) and RUN_DIR/metadata.json (optional: declared
    /// noise and effects, the spacecraft's identity); never truth.json. Writes OUT/report.md
    /// (with the plots it links, each under the question it answers), OUT/report.json, the
    /// PNG plots (residuals of every sensor pair before and after, the gyro bias history and
    /// the OBC's bias minus the ground's), OUT/tables/*.tbl (binary images that fsw-core
    /// loads), OUT/tables/manifest.json (the tables to fly) and OUT/tables/provenance.json
    /// (the run and spacecraft they were calibrated on; `sim-harness run --tables` warns when
    /// it flies them on another). Progress goes to stderr when it is a terminal (--quiet: none).
    #[command(
        after_help = "Example: ground-tool calibrate runs/a --out runs/a-cal && sim-harness run gro-early-mission --out runs/b --tables runs/a-cal/tables"
    )]
    Calibrate {
        #[command(flatten)]
        io: RunOutput,
        #[command(flatten)]
        flown: FlownTables,
        /// Use Shuster's 1982 scalar weights instead of the optimal (1990) weighting.
        #[arg(long)]
        shuster1982: bool,
        /// One joint FFCAL of all sensors instead of FHSTs first, then FSSs relative to them.
        #[arg(long)]
        single_stage: bool,
        /// Data of FFCAL's FHST stage: `gyro-batches` = every identified star, batch
        /// attitudes tied by the gyro (holds ≤ 20 min, slews ≤ 3 min) — the tracker rolls
        /// see every star offset; `star-pairs` = Shuster's dot products of simultaneous
        /// star pairs only (the paper's FFCAL data, about half the information on
        /// gro-early-mission).
        #[arg(long, value_enum, default_value = "gyro-batches")]
        fhst_stage: ground_tool::pipeline::calibrate::FhstStage,
        /// IRU calibration maneuver START:END in seconds since the first raw frame (repeat
        /// for each); replaces the maneuvers found as runs of high-rate frames. Each end
        /// attitude is still solved from the holds around it.
        #[arg(long = "maneuver", value_name = "START:END", value_parser = parse_span)]
        maneuvers: Vec<(f64, f64)>,
        #[command(flatten)]
        print: PrintOptions,
    },
    /// Diagnose: residual analysis that finds effects the model lacks, and the tables that fix them.
    ///
    /// Runs the calibration chain with the current model (declared effects from
    /// RUN_DIR/metadata.json), then tests every FHST/FSS residual against time, orbit phase,
    /// Sun angle, FOV position, magnitude, body rate, rate mode, velocity direction,
    /// temperatures and star id; fits a library of candidate effects (aberration, time tags,
    /// thermal/orbital alignment, alignment steps at an unknown time, FHST distortion and
    /// magnitude bias, FSS transfer function, catalog errors of every star or of a few, gyro
    /// bias drift, step, thermal bias and scale asymmetry) jointly with the alignments and
    /// keeps an effect only on the evidence (likelihood ratio with the scan of any searched
    /// parameter counted, BIC, halves). Gyro errors in the slews outside the library (a scale
    /// that grows with the rate, a scale step, a bias in high-rate mode) and every other
    /// significant structure are reported as unexplained with their size and regressor
    /// (report.json `unexplained`, `ledger`). Writes OUT/report.md, OUT/report.json, PNG plots, OUT/tables/*.tbl and
    /// OUT/tables/manifest.json for `sim-harness run ... --tables OUT/tables`, which loads
    /// the images the manifest lists: alignment.tbl and iru.tbl always, filter.tbl and
    /// star_catalog.tbl when a detected effect changes them (report.md lists what went into
    /// each). A table part (a sensor's alignment, an effect's terms) goes up only if it
    /// lowers the held-out residuals against the table `calibrate` writes for the same
    /// telemetry (report.json `flight_tables.validation`); nothing validated, calibrate's
    /// alignment table is written. Scores against RUN_DIR/truth.json only if it exists
    /// (labelled as scoring). OUT/tables/provenance.json names the run and spacecraft the
    /// tables were made for. Progress goes to stderr when it is a terminal (--quiet: none).
    #[command(after_help = "Example: ground-tool diagnose runs/a --out runs/a-diag")]
    Diagnose {
        #[command(flatten)]
        io: RunOutput,
        #[command(flatten)]
        flown: FlownTables,
        #[command(flatten)]
        print: PrintOptions,
    },
    /// Gyro noise by Allan deviation of the inertial holds: ARW, bias instability, RRW.
    ///
    /// What it is for: the OBC filter's gyro noise (σ_v = angle random walk N, σ_u = rate
    /// random walk K) should be measured, not guessed. The Allan deviation σ_A(τ) is the
    /// spread of the gyro's mean rate over clusters of length τ; each noise process has its
    /// own slope on a log-log plot: quantization (whole pulses, 0.05″) τ⁻¹, angle random walk
    /// τ^−½ (N = the line at τ = 1 s), bias instability flat (σ = 0.664 B), rate random walk
    /// τ^+½ (K = the line at τ = 3 s), a rate ramp τ⁺¹.
    ///
    /// Reads RUN_DIR/telemetry.bin; uses only low-rate hold intervals (not in a slew:
    /// housekeeping control mode ≠ 2, outside the slew events) without gaps, and by default
    /// the difference of each axis's two
    /// redundant channels (X2−X1, Y1−Y2, Z1−Z2), which cancels the body's own motion in the
    /// hold; figures are per channel (÷ √2). RRW needs holds of days (the ARW and RRW lines
    /// cross near τ = 640 s for GRO's gyro): scenarios/inertial-hold-long.toml.
    ///
    /// Writes OUT/allan.json, per axis: `points` (tau_s, sigma_rad_per_s and its interval,
    /// edf, alpha = the dominant noise type), `fit` (quantization_rad, arw_rad_per_sqrt_s,
    /// bias_instability_rad_per_s, rrw_rad_per_s_sqrt_s, rate_ramp_rad_per_s2: each value,
    /// low, high, detected, dominant_tau_s = the τ range it came from, interval_method), and
    /// the per-channel [value, low, high] of N, K, B, Q with the samples and segments used;
    /// OUT/allan.md (the same for people) and
    /// OUT/allan.png (log-log σ(τ) per axis with the interval bars, the fitted model, and the
    /// fitted ARW and RRW lines dashed). Exit code 2 when the run has no usable holds, too few
    /// samples, or holds cut by gaps (the message gives the counts).
    #[command(
        after_help = "Example: sim-harness run scenarios/inertial-hold-long.toml --out runs/hold && ground-tool allan runs/hold --out runs/hold-allan"
    )]
    Allan {
        #[command(flatten)]
        io: RunOutput,
        /// Confidence level of the intervals.
        #[arg(long, default_value_t = 0.95)]
        confidence: f64,
        /// `pair-difference`: each axis's two channels differenced (the body's motion
        /// cancels); `active-channel`: the primary channel alone (body motion included).
        #[arg(long, value_enum, default_value = "pair-difference")]
        signal: ground_tool::calibration::allan::Signal,
        /// Tables folder of the flown tables (for the pulse weight and scale factors);
        /// default: the run's activated uploads, else the boot tables.
        #[arg(long)]
        tables: Option<std::path::PathBuf>,
        #[command(flatten)]
        print: PrintOptions,
    },
    /// Reproduce the paper's numbers from data/gro_paper.toml.
    ///
    /// Recomputes what the paper's tables imply (Table 3 = Table 1 x Table 2, the rotation
    /// angles of the alignment changes, the FHST boresight separation, the adjustment that
    /// preserves the OBC's attitude frame, the IRU maneuver plan's covariance) and prints
    /// them beside the published figures. Reads the paper's facts built into the binary
    /// (data/gro_paper.toml); writes only to stdout (a table, or JSON with --json).
    #[command(after_help = "Example: ground-tool paper --json > paper.json")]
    Paper {
        /// Machine-readable JSON instead of the table.
        #[arg(long)]
        json: bool,
    },
    /// Uplink table images (fsw-core format): inspect, diff, write-paper-alignment, write-prelaunch-alignment, manifest.
    ///
    /// The images are the binary tables the OBC loads (header, payload, CRC-32;
    /// docs/tables.md). `inspect` and `diff` read images and print; the `write-*` actions
    /// write one image file; `manifest` writes DIR/manifest.json for a folder made by hand.
    #[command(
        after_help = "Examples:\n  ground-tool table inspect runs/a-cal/tables/alignment.tbl\n  ground-tool table diff prelaunch.tbl runs/a-cal/tables/alignment.tbl (prelaunch.tbl from write-prelaunch-alignment)\n  ground-tool table write-paper-alignment paper.tbl"
    )]
    Table {
        #[command(subcommand)]
        action: TableAction,
    },
    /// The downlink's packet descriptions for other ground systems, and a field-by-field dump.
    ///
    /// What it is for: Yamcs, OpenC3 COSMOS, cFS ground tools and NASA's `ccsdspy` read
    /// packets from a description, not from docs/icd.md. `describe` writes an XTCE 1.2
    /// mission database (`gro-telemetry.xtce.xml`: the CCSDS primary header, the CUC time
    /// code and every field of APIDs 0x010, 0x011, 0x012, 0x020 with its unit) and one
    /// `ccsdspy` CSV per APID (`ccsdspy/apid_0x010_raw_sensor_frame.csv`, ... for
    /// `ccsdspy.FixedLength.from_file`), generated from the flight software's one layout. The
    /// same files are shipped in docs/icd/. `decode` writes every field of every packet of a
    /// telemetry.bin as this tool reads it, one CSV per APID with the same column names, to
    /// compare with an outside decoder (tests/icd/interop_decoders.py does, for ccsdspy and
    /// an XTCE decoder).
    #[command(
        after_help = "Examples:\n  ground-tool icd describe --out icd\n  ground-tool icd decode runs/a/telemetry.bin --out runs/a-csv"
    )]
    Icd {
        #[command(subcommand)]
        action: IcdAction,
    },
    /// Time FFCAL on synthetic data (requirement: 10^6 pairs in <= 2 s, release build).
    ///
    /// Generates deterministic synthetic dot-product pairs (or, with --fhst-samples, star
    /// samples for the gyro-batch FHST stage), times the fit and prints the figures (JSON with
    /// --json). Reads and writes no file. Build with --release: a debug build is far slower.
    #[command(after_help = "Example: cargo run --release -p ground-tool -- bench --json")]
    Bench {
        /// Number of dot-product pairs per Gauss-Newton pass.
        #[arg(long, default_value_t = 1_000_000)]
        pairs: usize,
        /// Use the 1982 scalar weights instead of the optimal (1990) ones.
        #[arg(long)]
        shuster1982: bool,
        /// Time the gyro-batch FHST relative alignment (FFCAL's FHST stage) on this many
        /// synthetic star samples instead of FFCAL.
        #[arg(long, value_name = "N")]
        fhst_samples: Option<usize>,
        /// Machine-readable JSON.
        #[arg(long)]
        json: bool,
    },
}

#[derive(Subcommand)]
enum IcdAction {
    /// Write the XTCE database and the ccsdspy CSVs into OUT (OUT/ccsdspy/).
    ///
    /// Reads nothing (the layout is the flight software's); writes
    /// OUT/gro-telemetry.xtce.xml and OUT/ccsdspy/apid_0x0NN_NAME.csv, one per APID.
    #[command(after_help = "Example: ground-tool icd describe --out icd")]
    Describe {
        /// Output folder (created; the files are overwritten).
        #[arg(long)]
        out: std::path::PathBuf,
    },
    /// Decode TELEMETRY (a telemetry.bin) into OUT/apid_0x0NN_NAME.csv, every field of every
    /// packet kept by the reader (duplicates and damaged packets are reported, not written).
    #[command(
        after_help = "Example: ground-tool icd decode runs/a/telemetry.bin --out runs/a-csv"
    )]
    Decode {
        /// The telemetry file.
        telemetry: std::path::PathBuf,
        /// Output folder (created; the files are overwritten).
        #[arg(long)]
        out: std::path::PathBuf,
    },
}

#[derive(Subcommand)]
enum TableAction {
    /// Check and print one image (header, CRC, OBC validation, content).
    ///
    /// Reads FILE; prints the header, the OBC's own validation verdict, the rotation of each
    /// alignment from prelaunch and the content (JSON with --json). Exit code 2 when the OBC
    /// would reject the table.
    #[command(after_help = "Example: ground-tool table inspect runs/a-cal/tables/alignment.tbl")]
    Inspect {
        /// Image file.
        file: std::path::PathBuf,
        /// JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Differences between two images of the same table.
    ///
    /// Reads A and B; prints every field that differs, the rotation between the alignments
    /// and the largest G change (JSON with --json).
    #[command(
        after_help = "Example: ground-tool table diff prelaunch.tbl runs/a-cal/tables/alignment.tbl (prelaunch.tbl from write-prelaunch-alignment)"
    )]
    Diff {
        /// First image.
        a: std::path::PathBuf,
        /// Second image.
        b: std::path::PathBuf,
        /// JSON output.
        #[arg(long)]
        json: bool,
    },
    /// Write the alignment table the paper uplinked on 1991-05-14 (Table 1 x Table 2).
    ///
    /// Writes the image file OUT (overwritten), built from the paper's facts in the binary.
    #[command(after_help = "Example: ground-tool table write-paper-alignment paper.tbl")]
    WritePaperAlignment {
        /// Output image file.
        out: std::path::PathBuf,
    },
    /// Write the prelaunch (boot) alignment table.
    ///
    /// Writes the image file OUT (overwritten): paper Table 1, the table the OBC boots with.
    #[command(after_help = "Example: ground-tool table write-prelaunch-alignment prelaunch.tbl")]
    WritePrelaunchAlignment {
        /// Output image file.
        out: std::path::PathBuf,
    },
    /// Write DIR/manifest.json listing every *.tbl image of DIR (each checked, with its
    /// CRC-32), for a tables folder made by hand: check first that DIR holds exactly the
    /// images to fly. `calibrate` and `diagnose` write the manifest themselves.
    #[command(after_help = "Example: ground-tool table manifest my-tables/")]
    Manifest {
        /// Tables folder.
        dir: std::path::PathBuf,
    },
}

fn run_icd(action: IcdAction) -> Result<()> {
    match action {
        IcdAction::Describe { out } => {
            let written = ground_tool::icd_export::write_descriptions(&out)
                .with_context(|| format!("writing the descriptions into {}", out.display()))?;
            for p in written {
                eprintln!("wrote {}", p.display());
            }
        }
        IcdAction::Decode { telemetry, out } => {
            // A file that cannot be read, or holds no packet, is bad input (exit code 2), and
            // nothing is written for it.
            let report = ground_tool::tp::read_file(&telemetry)
                .map_err(|e| ground_tool::run_check::InputError(e.into()))?
                .report;
            let decoded: usize = report.packets.by_apid().iter().map(|c| c.1).sum();
            if decoded == 0 {
                return Err(ground_tool::run_check::InputError::msg(format!(
                    "{}: no packet decoded ({} octets, {} skipped: {}; docs/icd.md §2)",
                    telemetry.display(),
                    report.file_len,
                    report.skipped_octets(),
                    report
                        .skipped
                        .first()
                        .map_or("empty file", |s| s.reason.as_str())
                ))
                .into());
            }
            let (written, report) = ground_tool::icd_export::dump_csv(&telemetry, &out)
                .map_err(ground_tool::run_check::InputError)?;
            for p in written {
                eprintln!("wrote {}", p.display());
            }
            if !report.is_clean() {
                eprintln!(
                    "warning: {}: {} regions skipped ({} octets), {} duplicates dropped: not in the CSVs",
                    telemetry.display(),
                    report.skipped.len(),
                    report.skipped_octets(),
                    report.duplicates.len()
                );
            }
        }
    }
    Ok(())
}

fn run_table(action: TableAction) -> Result<()> {
    use ground_tool::run_check::InputError;
    use ground_tool::table::{self, AnyTable};
    // A file that cannot be read or is not a valid image is bad input (exit code 2).
    let input = |e: ground_tool::table::TableToolError| InputError(e.into());
    match action {
        TableAction::Inspect { file, json } => {
            let bytes = table::read_file(&file).map_err(input)?;
            let ins = table::inspect(&bytes, &file.display().to_string()).map_err(input)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&ins)?);
            } else {
                println!(
                    "{}: {} table, format v{}, {} bytes (payload {}), created {:.3} s TAI since 1958, CRC ok, OBC validation: {}",
                    file.display(),
                    ins.table,
                    ins.format_version,
                    ins.image_len,
                    ins.payload_len,
                    ins.created_tai_s,
                    ins.validation_error.as_deref().unwrap_or("pass")
                );
                if let Some(rot) = &ins.rotation_from_prelaunch_arcsec {
                    for (id, v, n) in rot {
                        println!("  {id:5} rotation from prelaunch [{:8.1}, {:8.1}, {:8.1}]″  |θ| {n:7.1}″", v[0], v[1], v[2]);
                    }
                }
                println!("{}", serde_json::to_string_pretty(&ins.content)?);
            }
            if let Some(why) = &ins.validation_error {
                return Err(InputError::msg(format!(
                    "{}: the OBC would reject this table: {why}",
                    file.display()
                ))
                .into());
            }
        }
        TableAction::Diff { a, b, json } => {
            let d = table::diff(
                &table::read_file(&a).map_err(input)?,
                &table::read_file(&b).map_err(input)?,
            )
            .map_err(input)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&d)?);
            } else {
                println!("{} table: {} field(s) differ", d.table, d.fields.len());
                for f in &d.fields {
                    let fmt = |x: Option<f64>| x.map_or("-".to_owned(), |v| format!("{v:.9}"));
                    println!("  {:40} {:>16} -> {:>16}", f.path, fmt(f.a), fmt(f.b));
                }
                if let Some(rot) = &d.alignment_rotation_arcsec {
                    for (id, v, n) in rot {
                        println!(
                            "  {id:5} rotation A->B [{:8.1}, {:8.1}, {:8.1}]″  |θ| {n:7.1}″",
                            v[0], v[1], v[2]
                        );
                    }
                }
                if let Some(ppm) = d.iru_max_g_change_ppm {
                    println!("  largest G change {ppm:.1} ppm");
                }
            }
        }
        TableAction::WritePaperAlignment { out } => {
            let t = AnyTable::Alignment(table::paper_alignment_table()?);
            let tag = fsw_core::raw::TimeTag {
                coarse_s: table::PAPER_UPLINK_TAI_S,
                fine: 0,
            };
            let img = table::write_image(&t, tag)?;
            std::fs::write(&out, &img)
                .with_context(|| format!("cannot write {}", out.display()))?;
            println!("wrote {} ({} bytes)", out.display(), img.len());
        }
        TableAction::WritePrelaunchAlignment { out } => {
            let t = AnyTable::Alignment(fsw_core::tables::AlignmentTable::prelaunch());
            let img = table::write_image(
                &t,
                fsw_core::raw::TimeTag {
                    coarse_s: 0,
                    fine: 0,
                },
            )?;
            std::fs::write(&out, &img)
                .with_context(|| format!("cannot write {}", out.display()))?;
            println!("wrote {} ({} bytes)", out.display(), img.len());
        }
        TableAction::Manifest { dir } => {
            let m = gro_reference::manifest::write_for_all(&dir, "ground-tool table manifest")?;
            for e in &m.tables {
                println!(
                    "{}: {} table, {} octets, CRC-32 {}",
                    e.file, e.table, e.octets, e.crc32
                );
            }
            println!(
                "wrote {}",
                dir.join(gro_reference::manifest::MANIFEST).display()
            );
        }
    }
    Ok(())
}

/// `START:END` (seconds) for `--maneuver`.
fn parse_span(s: &str) -> std::result::Result<(f64, f64), String> {
    let (a, b) = s
        .split_once(':')
        .ok_or_else(|| format!("`{s}`: expected START:END in seconds, e.g. 10515:11700"))?;
    let a: f64 = a.trim().parse().map_err(|e| format!("`{a}`: {e}"))?;
    let b: f64 = b.trim().parse().map_err(|e| format!("`{b}`: {e}"))?;
    if !(a.is_finite() && b.is_finite() && b > a && a >= 0.0) {
        return Err(format!("`{s}`: need 0 ≤ START < END"));
    }
    Ok((a, b))
}

fn run_calibrate(
    args: &CommandArgs<'_>,
    shuster1982: bool,
    single_stage: bool,
    fhst_stage: ground_tool::pipeline::calibrate::FhstStage,
    maneuvers: Vec<(f64, f64)>,
) -> Result<()> {
    use ground_tool::calibration::alignment::Weighting;
    let (run_dir, out_target, tables) = (args.run_dir, args.out, args.tables);
    let progress = ground_tool::progress::Session::start("ground-tool calibrate", !args.quiet);
    use ground_tool::pipeline::calibrate::{calibrate_run, CalibrateOptions};
    let meta = ground_tool::pipeline::flown::metadata_checked(run_dir)?;
    let with_flown = ground_tool::pipeline::flown::calibrate_options(run_dir, &meta, tables)?;
    let dir = args.begin_output("ground-tool calibrate")?;
    let out = dir.path();
    let assumed = ground_tool::pipeline::flown::assumed_tables(run_dir, &meta, tables)?;
    ground_tool::run_check::check_run_dir(run_dir, out, &assumed, args.trust_tables)?;
    let options = CalibrateOptions {
        weighting: if shuster1982 {
            Weighting::Shuster1982
        } else {
            Weighting::Optimal1990
        },
        staged_ffcal: !single_stage,
        fhst_stage,
        maneuvers_s: (!maneuvers.is_empty()).then_some(maneuvers),
        ..with_flown
    };
    // The OBC's bias at every housekeeping packet, for the bias plots: taken (and its decoded
    // telemetry dropped) before the chain decodes the file, so the peak memory stays the
    // chain's. A file that cannot be read is left to the chain, whose message says why.
    ground_tool::progress::step("the OBC's bias from every housekeeping packet (for the plots)");
    let obc_bias = ground_tool::report::ObcBiasSeries::read(run_dir).ok();
    let result = calibrate_run(run_dir, out, &options)?;
    // Whose spacecraft these tables are for (gro_reference::provenance): `sim-harness run
    // --tables` warns when it flies them on another.
    gro_reference::provenance::write(&out.join("tables"), run_dir, &meta, "ground-tool calibrate")?;
    let flown = options
        .flown_alignment
        .unwrap_or_else(fsw_core::tables::AlignmentTable::prelaunch);
    ground_tool::progress::step("report.md, report.json and the plots");
    ground_tool::report::write_calibration_report(out, &result, &flown, obc_bias.as_ref())?;
    dir.commit()?;
    drop(progress);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&result.report)?);
    } else {
        eprintln!(
            "wrote {}/report.md, report.json and tables/",
            out_target.display()
        );
    }
    Ok(())
}

/// `ground-tool allan`: read the telemetry, identify the gyro noise, write the outputs.
fn run_allan(
    args: &CommandArgs<'_>,
    options: ground_tool::calibration::allan::AllanOptions,
) -> Result<()> {
    let (run_dir, tables, quiet) = (args.run_dir, args.tables, args.quiet);
    use ground_tool::calibration::allan;
    use ground_tool::run_check::{InputError, Severity};
    if !(options.confidence > 0.0 && options.confidence < 1.0) {
        return Err(InputError::msg(format!(
            "--confidence {}: must be between 0 and 1 (e.g. 0.95)",
            options.confidence
        ))
        .into());
    }
    let meta = ground_tool::pipeline::flown::metadata_checked(run_dir)?;
    let (_, flown_iru, _) = ground_tool::pipeline::flown::flown_tables(run_dir, &meta, tables)?;
    let iru = flown_iru.unwrap_or_else(fsw_core::tables::IruTable::prelaunch);
    let progress = ground_tool::progress::Session::start("ground-tool allan", !quiet);
    ground_tool::progress::step("reading the telemetry");
    let tm = ground_tool::tp::read_file(&run_dir.join("telemetry.bin"))
        .map_err(|e| InputError(e.into()))?;
    // The IRU table sets the pulse weights and scale factors: checked against the one the
    // OBC reported active, as calibrate and diagnose check theirs.
    let iru_assumed: Vec<_> = ground_tool::pipeline::flown::assumed_tables(run_dir, &meta, tables)?
        .into_iter()
        .filter(|a| a.id == fsw_core::tables::TableId::Iru)
        .collect();
    let mut findings = ground_tool::run_check::check(&tm, Some(&meta));
    findings.extend(ground_tool::run_check::flown_table_findings(
        &tm,
        &iru_assumed,
        false,
    ));
    for f in findings.iter().filter(|f| f.severity == Severity::Warning) {
        eprintln!("warning: {}", f.message);
    }
    if let Some(f) = findings.into_iter().find(|f| f.severity == Severity::Error) {
        return Err(InputError::msg(format!("{}: {}", run_dir.display(), f.message)).into());
    }
    ground_tool::progress::step("Allan deviation of the holds and the noise fit");
    let report = allan::identify_gyro_noise(&tm, &iru, &options).map_err(|e| {
        InputError(anyhow::Error::new(e).context(format!(
            "{}: the telemetry does not support a gyro noise identification",
            run_dir.display()
        )))
    })?;
    let dir = args.begin_output("ground-tool allan")?;
    ground_tool::progress::step("allan.json, allan.md and the plot");
    allan::write_outputs(dir.path(), &report, &run_dir.display().to_string())?;
    dir.commit()?;
    drop(progress);
    if args.json {
        println!("{}", serde_json::to_string_pretty(&report)?);
    } else {
        for a in &report.axes {
            let show = |v: [f64; 3], t: &allan::NoiseTerm| {
                if t.detected {
                    format!("{:.3e} [{:.3e}, {:.3e}]", v[0], v[1], v[2])
                } else {
                    format!("not detected (≤ {:.2e})", v[2])
                }
            };
            eprintln!(
                "{} ({}, {} samples in {} segments): ARW {} rad/√s, RRW {} rad/s/√s",
                a.axis,
                a.channels,
                a.samples,
                a.segments,
                show(a.arw_rad_per_sqrt_s, &a.fit.arw_rad_per_sqrt_s),
                show(a.rrw_rad_per_s_sqrt_s, &a.fit.rrw_rad_per_s_sqrt_s)
            );
        }
        for n in &report.notes {
            eprintln!("note: {n}");
        }
        eprintln!(
            "wrote {}/allan.json, allan.md, allan.png",
            args.out.display()
        );
    }
    Ok(())
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    match run(cli) {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            // Chosen from the error's type (gro_reference::InputError = bad input), not its text.
            std::process::ExitCode::from(gro_reference::exit_code(&e))
        }
    }
}

fn run(cli: Cli) -> Result<()> {
    match cli.command {
        Command::Calibrate {
            io,
            flown,
            shuster1982,
            single_stage,
            fhst_stage,
            maneuvers,
            print,
        } => run_calibrate(
            &CommandArgs {
                trust_tables: flown.trust_tables,
                ..io.with(flown.tables.as_deref(), &print)
            },
            shuster1982,
            single_stage,
            fhst_stage,
            maneuvers,
        )?,
        Command::Diagnose { io, flown, print } => {
            ground_tool::diagnose::run::diagnose_command(
                &CommandArgs {
                    trust_tables: flown.trust_tables,
                    ..io.with(flown.tables.as_deref(), &print)
                },
                None,
            )?;
        }
        Command::Allan {
            io,
            confidence,
            signal,
            tables,
            print,
        } => run_allan(
            &io.with(tables.as_deref(), &print),
            ground_tool::calibration::allan::AllanOptions { confidence, signal },
        )?,
        Command::Paper { json } => {
            let r = ground_tool::paper::reproduce()?;
            if json {
                println!(
                    "{}",
                    serde_json::to_string_pretty(&ground_tool::paper::to_json(&r))?
                );
            } else {
                print!("{}", ground_tool::paper::render_table(&r));
            }
        }
        Command::Table { action } => run_table(action)?,
        Command::Icd { action } => run_icd(action)?,
        Command::Bench {
            fhst_samples: Some(n),
            json,
            ..
        } => {
            let t = ground_tool::bench::fhst_relative_timing(n, 1)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&t)?);
            } else {
                println!(
                    "FHST relative alignment (gyro batches): {} samples in {} batches: {:.3} s ({:.3} s per 10^6 samples); data generation {:.3} s",
                    t.samples, t.batches, t.estimate_s, t.per_million_s, t.generate_s
                );
            }
        }
        Command::Bench {
            pairs,
            shuster1982,
            json,
            fhst_samples: None,
        } => {
            use ground_tool::calibration::alignment::Weighting;
            let weighting = if shuster1982 {
                Weighting::Shuster1982
            } else {
                Weighting::Optimal1990
            };
            let t = ground_tool::bench::ffcal_timing(pairs, weighting, 1)?;
            if json {
                println!("{}", serde_json::to_string_pretty(&t)?);
            } else {
                println!(
                    "FFCAL {:?}: {} epochs, {} pairs/pass, {} passes: {:.3} s ({:.3} s/pass); data generation {:.3} s",
                    t.weighting, t.epochs, t.pairs_per_pass, t.passes, t.ffcal_s, t.per_pass_s, t.generate_s
                );
                if t.ffcal_s * 1e6 / t.pairs_per_pass.max(1) as f64 > 2.0 {
                    eprintln!("warning: slower than the requirement of 2 s per 10^6 pairs (is this a release build?)");
                }
            }
        }
    }
    Ok(())
}
