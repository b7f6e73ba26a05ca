/// A fixed synthetic scenario for cost measurements (shared by `examples/step_cost.rs` and
/// `benches/step.rs` through `include!`): an inertial hold with one star in each FHST, the
/// Sun in FSS1, and IRU counters that drift with a constant bias. Frames are generated once;
/// the measured loop is `FlightCore::step` only.
#[allow(dead_code)]
mod synthetic {
    use fsw_core::attitude::{rot, Quat};
    use fsw_core::executive::{Command, FlightCore};
    use fsw_core::fhst::{hv_from_dir, FHST_RAD_PER_COUNT};
    use fsw_core::fss::{angles_from_dir, FSS_RAD_PER_COUNT};
    use fsw_core::raw::{
        FhstSample, FssSample, RawSensorFrame, TimeTag, FHST_FLAG_TRACKING, FHST_FLAG_VALID,
        FSS_FLAG_SUN_ALPHA, FSS_FLAG_SUN_BETA,
    };
    use fsw_core::tables::image::encode_image;
    use fsw_core::tables::types::matrix_from_rows;
    use fsw_core::tables::{AlignmentTable, CatalogStar, StarCatalogTable, TableId};
    use nalgebra::{Matrix3, Vector3};

    /// Start time: 1991-04-10, seconds since 1958 TAI.
    pub const T0_TAI1958_S: f64 = 1_049_932_800.0;

    /// The scenario: boot commands (owned image bytes) and the frames.
    pub struct Scenario {
        /// Star catalog image.
        pub catalog_image: Vec<u8>,
        /// True attitude.
        pub q_true: Quat,
        /// One frame per cycle.
        pub frames: Vec<RawSensorFrame>,
    }

    fn round_i16(x: f64) -> i16 {
        x.round().clamp(-32768.0, 32767.0) as i16
    }

    /// Build `cycles` frames.
    pub fn build(cycles: usize) -> Scenario {
        let align = AlignmentTable::prelaunch();
        let m_fhst = [
            matrix_from_rows(&align.m_acs_from_fhst1),
            matrix_from_rows(&align.m_acs_from_fhst2),
        ];
        let m_fss1 = matrix_from_rows(&align.m_acs_from_fss1);
        let t0 = TimeTag::from_seconds(T0_TAI1958_S).unwrap_or_default();
        let sun_eci = fsw_core::sun_ephemeris::sun_dir_eci(t0.seconds_since_j2000_tt())
            .unwrap_or_else(|_| Vector3::x());
        // Attitude that puts the Sun 10° off FSS1's boresight: TRIAD on (Sun, J2000 z).
        let sun_body = m_fss1 * (rot(&Vector3::new(0.12, 0.1, 0.0)) * Vector3::z());
        let triad = |a: Vector3<f64>, b: Vector3<f64>| {
            let t1 = a.normalize();
            let t2 = a.cross(&b).normalize();
            Matrix3::from_columns(&[t1, t2, t1.cross(&t2)])
        };
        let a_true = triad(sun_body, Vector3::new(0.3, 0.2, 0.9))
            * triad(sun_eci, Vector3::z()).transpose();
        let q_true = Quat::from_dcm(&a_true);
        // One catalog star near each FHST boresight.
        let mut catalog = StarCatalogTable::default();
        let mut star_sensor = [Vector3::zeros(); 2];
        for (k, m) in m_fhst.iter().enumerate() {
            let s = Vector3::new(0.01 + 0.005 * k as f64, -0.008, 1.0).normalize();
            star_sensor[k] = s;
            let r = a_true.transpose() * (m * s);
            let _ = catalog.stars.push(CatalogStar {
                id: 1000 + k as u32,
                dir_eci: [r.x as f32, r.y as f32, r.z as f32],
                magnitude_centimag: 400,
            });
        }
        let mut buf = vec![0u8; 4096];
        let n = encode_image(TableId::StarCatalog, t0, &catalog, &mut buf).unwrap_or(0);
        buf.truncate(n);
        let mut frames = Vec::with_capacity(cycles);
        let bias_pulses_per_s = [3.1, 2.2, -1.7, 2.9, 1.3, -0.8];
        for k in 0..cycles {
            let mut f = RawSensorFrame::default();
            f.time = TimeTag::from_seconds(T0_TAI1958_S + k as f64).unwrap_or_default();
            for (c, rate) in f.iru.counts.iter_mut().zip(bias_pulses_per_s) {
                *c = ((rate * k as f64).floor() as i64).rem_euclid(65_536) as u16;
            }
            for (i, s) in star_sensor.iter().enumerate() {
                let (h, v) = hv_from_dir(s).unwrap_or((0.0, 0.0));
                f.fhst[i] = FhstSample {
                    h_counts: round_i16(h / FHST_RAD_PER_COUNT),
                    v_counts: round_i16(v / FHST_RAD_PER_COUNT),
                    magnitude_centimag: 400,
                    flags: FHST_FLAG_VALID | FHST_FLAG_TRACKING,
                };
            }
            let (a, b) = angles_from_dir(&(m_fss1.transpose() * sun_body)).unwrap_or((0.0, 0.0));
            f.fss[0] = FssSample {
                alpha_counts: round_i16(a / FSS_RAD_PER_COUNT),
                beta_counts: round_i16(b / FSS_RAD_PER_COUNT),
                flags: FSS_FLAG_SUN_ALPHA | FSS_FLAG_SUN_BETA,
            };
            frames.push(f);
        }
        Scenario {
            catalog_image: buf,
            q_true,
            frames,
        }
    }

    /// Boot a core on the scenario (catalog loaded and activated, filter initialised) by
    /// stepping the first frame with the boot commands.
    pub fn boot(s: &Scenario) -> Box<FlightCore> {
        let mut core = Box::new(FlightCore::new());
        let commands = [
            Command::TableLoad(&s.catalog_image),
            Command::TableActivate(TableId::StarCatalog),
            Command::FilterInitialize(s.q_true),
        ];
        if let Some(first) = s.frames.first() {
            let _ = core.step(first, &commands);
        }
        core
    }
}
