//! Sensor noise from a log of the robot standing still (`twin calibrate noise`).
//!
//! - **IMUs** (`sensor_msgs/msg/Imu`, every such topic of the bag): per gyro and accelerometer
//!   axis, the overlapping Allan deviation with its confidence band and the fitted white-noise
//!   density `N`, bias instability `B` and bias random walk `K` ([`crate::allan`]).
//! - **Encoders** (`sensor_msgs/msg/JointState`, when the bag has one): per joint, the position
//!   noise σ (standard deviation about the mean) and the quantization step Δ (the common step
//!   of the distinct values, when they lie on a grid; `σ = Δ/√12` for a pure quantizer).
//!
//! The log must be still: before any statistics, every signal's 1-second means are compared
//! with their median; a departure beyond a threshold (robot or IMU moved, someone touched it)
//! is refused, naming the sensor, the axis and the time span.
//!
//! Results go into the URDF's Gazebo IMU `<noise>` tags ([`imu_noise_updates`] →
//! [`crate::writeback::rewrite_imu_noise`]): `stddev = N·√f` (f: the sensor's `<update_rate>`,
//! else the log's rate); the bias instability as Gazebo's first-order Gauss–Markov bias
//! (`dynamic_bias_stddev` σ_b, `dynamic_bias_correlation_time` τc) whose Allan peak (0.618 of
//! its stationary deviation `σ_b·√(τc/2)`, at τ ≈ 1.89·τc) equals the floor `0.664·B` at the
//! τ where the fitted curve bottoms out (`√3·N/K`, between the white and random-walk lines);
//! and the bias random walk `K` as `<bias_random_walk>` (a twin extension Gazebo ignores: one
//! Gauss–Markov process cannot give both a flat floor and the +½ slope past it). `twin sim`
//! simulates all three ([`twin_core::convert::ImuBias`]), so its IMU reproduces the Allan
//! curve. They also go into a `twin randomize` spec fragment ([`NoiseReport::spec_fragment`]).

use crate::allan::{self, AllanPoint, NoiseFit};
use crate::error::{Error, Result};
use crate::log::JointLog;
use rand::{Rng, SeedableRng};
use rand_chacha::ChaCha8Rng;
use rand_distr::StandardNormal;
use serde::Serialize;
use std::fmt::Write as _;
use std::path::Path;

/// IMU readings of one `sensor_msgs/msg/Imu` topic.
#[derive(Debug, Clone, Default, PartialEq)]
pub struct ImuLog {
    /// The topic.
    pub topic: String,
    /// `header.frame_id` of its messages (the IMU link).
    pub frame_id: String,
    /// Sample times, nanoseconds.
    pub t_nanos: Vec<i64>,
    /// Angular velocity per axis (x, y, z), rad/s, IMU frame.
    pub gyro: [Vec<f64>; 3],
    /// Linear acceleration (specific force) per axis, m/s², IMU frame.
    pub accel: [Vec<f64>; 3],
}

impl ImuLog {
    /// Median sample rate, Hz (0 with fewer than 2 samples).
    pub fn rate_hz(&self) -> f64 {
        let mut dt: Vec<i64> = self.t_nanos.windows(2).map(|w| w[1] - w[0]).filter(|&d| d > 0).collect();
        if dt.is_empty() {
            return 0.0;
        }
        dt.sort_unstable();
        1e9 / dt[dt.len() / 2] as f64
    }

    /// Duration, seconds.
    pub fn duration_secs(&self) -> f64 {
        match (self.t_nanos.first(), self.t_nanos.last()) {
            (Some(a), Some(b)) => (b - a) as f64 * 1e-9,
            _ => 0.0,
        }
    }

    /// Writes the readings as a ROS 2 bag topic of `writer`.
    ///
    /// # Errors
    /// [`Error::Core`] when writing fails.
    pub fn write_to(&self, writer: &mut twin_core::log::LogWriter) -> Result<()> {
        use twin_core::log::{Header, Imu};
        let topic = writer.add_topic::<Imu>(&self.topic)?;
        let mut msg = Imu {
            header: Header { stamp_nanos: 0, frame_id: self.frame_id.clone() },
            orientation_xyzw: [0.0, 0.0, 0.0, 1.0],
            orientation_covariance: [-1.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0],
            ..Default::default()
        };
        for (k, &t) in self.t_nanos.iter().enumerate() {
            msg.header.stamp_nanos = t;
            msg.angular_velocity = [self.gyro[0][k], self.gyro[1][k], self.gyro[2][k]];
            msg.linear_acceleration = [self.accel[0][k], self.accel[1][k], self.accel[2][k]];
            writer.write(topic, t.max(0) as u64, &msg)?;
        }
        Ok(())
    }
}

/// Reads every `sensor_msgs/msg/Imu` topic of a ROS 2 bag (or only `topic`). Times are the
/// header stamps (log times when a stamp is 0); out-of-order or repeated stamps are dropped.
///
/// # Errors
/// [`Error::Core`] for unreadable files; [`Error::BadLog`] when the bag has no Imu topic or a
/// reading is not finite.
pub fn read_imus(path: &Path, topic: Option<&str>) -> Result<(Vec<ImuLog>, Vec<String>)> {
    use twin_core::log::{Imu, Log, ReadOptions};
    let bag = Log::open(path, ReadOptions::default())?;
    let info = bag.info()?;
    let source_name = path.display().to_string();
    let topics: Vec<String> = match topic {
        Some(t) => vec![t.to_string()],
        None => info.topics_of_type("Imu").into_iter().map(str::to_string).collect(),
    };
    if topics.is_empty() {
        let listing = info.topics.iter().map(|t| format!("{} ({})", t.topic, t.type_name)).collect::<Vec<_>>();
        return Err(Error::BadLog {
            source_name,
            message: format!(
                "no sensor_msgs/msg/Imu topic in the log (topics: {}); record the IMU while the robot stands still",
                if listing.is_empty() { "none".into() } else { listing.join(", ") }
            ),
        });
    }
    let mut out = Vec::new();
    let mut warnings = Vec::new();
    for name in topics {
        let (msgs, report) = bag.read_typed::<Imu>(&name)?;
        warnings.extend(report.warnings());
        let mut imu = ImuLog { topic: name.clone(), ..Default::default() };
        for (log_time, m) in &msgs {
            let t = if m.header.stamp_nanos != 0 { m.header.stamp_nanos } else { *log_time as i64 };
            if imu.t_nanos.last().is_some_and(|&l| t <= l) {
                continue;
            }
            if m.angular_velocity.iter().chain(&m.linear_acceleration).any(|v| !v.is_finite()) {
                return Err(Error::BadLog {
                    source_name,
                    message: format!("{name}: reading at t = {:.6} s is not finite", t as f64 * 1e-9),
                });
            }
            if imu.frame_id.is_empty() {
                imu.frame_id = m.header.frame_id.clone();
            }
            imu.t_nanos.push(t);
            for a in 0..3 {
                imu.gyro[a].push(m.angular_velocity[a]);
                imu.accel[a].push(m.linear_acceleration[a]);
            }
        }
        out.push(imu);
    }
    Ok((out, warnings))
}

/// Reads a still log (IMU topics and, when there is one, the joint states) and measures its
/// noise: the whole of `twin calibrate noise` but the write-back. Returns the report and
/// warnings from reading.
///
/// # Errors
/// [`Error::BadLog`] for a log with neither IMU nor joint states, a moving robot or a too short
/// log; reading errors as [`read_imus`] and [`JointLog::read_mcap`].
pub fn calibrate_noise(
    path: &Path,
    imu_topic: Option<&str>,
    joint_topic: Option<&str>,
    opts: &NoiseOptions,
) -> Result<(NoiseReport, Vec<String>)> {
    use twin_core::log::{Log, ReadOptions};
    opts.check()?;
    let info = Log::open(path, ReadOptions::default())?.info()?;
    let has = |suffix: &str| info.topics.iter().any(|t| t.type_name.ends_with(suffix));
    let mut warnings = Vec::new();
    let imus = if imu_topic.is_some() || has("Imu") {
        let (imus, w) = read_imus(path, imu_topic)?;
        warnings.extend(w);
        imus
    } else {
        Vec::new()
    };
    let joints = if joint_topic.is_some() || has("JointState") {
        let (log, w) = JointLog::read_mcap(path, joint_topic)?;
        warnings.extend(w);
        Some(log)
    } else {
        None
    };
    if imus.is_empty() && joints.is_none() {
        let listing = info.topics.iter().map(|t| format!("{} ({})", t.topic, t.type_name)).collect::<Vec<_>>();
        return Err(Error::BadLog {
            source_name: path.display().to_string(),
            message: format!(
                "neither sensor_msgs/msg/Imu nor sensor_msgs/msg/JointState in the log (topics: {}); record the \
                 IMU and /joint_states while the robot stands still",
                if listing.is_empty() { "none".into() } else { listing.join(", ") }
            ),
        });
    }
    // Stillness of every sensor first: a moving robot is refused before any statistics.
    for imu in &imus {
        check_imu_still(imu, opts)?;
    }
    let encoders = match &joints {
        Some(log) => analyze_encoders(log, opts)?,
        None => Vec::new(),
    };
    let imus = imus.iter().map(|imu| analyze_imu(imu, opts)).collect::<Result<Vec<_>>>()?;
    Ok((NoiseReport { log: path.display().to_string(), imus, encoders, confidence: opts.confidence }, warnings))
}

/// Options of the noise calibration. Defaults suit a MEMS IMU at 100–1000 Hz and 12–20-bit
/// encoders.
#[derive(Debug, Clone, PartialEq, smart_default::SmartDefault)]
pub struct NoiseOptions {
    /// Largest averaging time of the Allan deviation, s (default: `None`, a quarter of the
    /// log). A log shorter than [`MIN_CLUSTERS`]·τ_max is refused.
    pub tau_max_secs: Option<f64>,
    /// Shortest usable log, s (default: 60): below, not even the white noise is measured well.
    #[default(60.0)]
    pub min_duration_secs: f64,
    /// Allan deviation points per decade of τ (default: 10).
    #[default(10)]
    pub points_per_decade: usize,
    /// Confidence level of the band (default: 0.95).
    #[default(0.95)]
    pub confidence: f64,
    /// Window of the stillness check, s (default: 1).
    #[default(1.0)]
    pub still_window_secs: f64,
    /// A gyro axis whose window mean departs from its median by more moved, rad/s
    /// (default: 0.02, about 1°/s).
    #[default(0.02)]
    pub gyro_motion_rad_s: f64,
    /// Same for an accelerometer axis, m/s² (default: 0.1, a tilt of about 0.6°).
    #[default(0.1)]
    pub accel_motion_mps2: f64,
    /// Same for a joint position, rad or m (default: 0.002).
    #[default(0.002)]
    pub encoder_motion: f64,
}

/// A τ is only estimated from at least this many clusters' worth of log.
pub const MIN_CLUSTERS: f64 = 4.0;

impl NoiseOptions {
    fn check(&self) -> Result<()> {
        let bad = |name, message: String| Err(Error::Option { name, message });
        if let Some(t) = self.tau_max_secs
            && !(t > 0.0 && t.is_finite())
        {
            return bad("tau_max_secs", format!("must be a positive time, got {t}"));
        }
        if !(self.confidence > 0.0 && self.confidence < 1.0) {
            return bad("confidence", format!("must be in (0, 1), got {}", self.confidence));
        }
        for (name, v) in [
            ("still_window_secs", self.still_window_secs),
            ("gyro_motion_rad_s", self.gyro_motion_rad_s),
            ("accel_motion_mps2", self.accel_motion_mps2),
            ("encoder_motion", self.encoder_motion),
        ] {
            if !(v > 0.0 && v.is_finite()) {
                return bad(name, format!("must be positive, got {v}"));
            }
        }
        Ok(())
    }
}

/// Allan deviation and fitted noise of one IMU axis.
#[derive(Debug, Clone, Serialize)]
pub struct AxisNoise {
    /// `gyro` or `accel`.
    pub sensor: &'static str,
    /// `x`, `y` or `z`.
    pub axis: &'static str,
    /// The curve with its confidence band.
    pub points: Vec<AllanPoint>,
    /// The fitted coefficients.
    pub fit: NoiseFit,
}

/// Noise of one IMU.
#[derive(Debug, Clone, Serialize)]
pub struct ImuNoise {
    /// Topic.
    pub topic: String,
    /// Frame (IMU link).
    pub frame_id: String,
    /// Median rate, Hz.
    pub rate_hz: f64,
    /// Duration used, s.
    pub duration_secs: f64,
    /// Gyro x, y, z then accelerometer x, y, z.
    pub axes: Vec<AxisNoise>,
}

/// Noise of one joint encoder.
#[derive(Debug, Clone, Serialize)]
pub struct EncoderNoise {
    /// Joint.
    pub joint: String,
    /// Standard deviation of the position about its mean, rad or m.
    pub sigma: f64,
    /// Quantization step, when the readings lie on a grid.
    pub quantization_step: Option<f64>,
    /// Number of distinct readings.
    pub distinct_values: usize,
}

/// Everything `twin calibrate noise` measured.
#[derive(Debug, Clone, Serialize)]
pub struct NoiseReport {
    /// The log.
    pub log: String,
    /// Per IMU.
    pub imus: Vec<ImuNoise>,
    /// Per joint encoder (empty without a JointState topic).
    pub encoders: Vec<EncoderNoise>,
    /// Confidence level of the bands.
    pub confidence: f64,
}

/// Window means within this many windows either side form a window's resting reference:
/// bias drift over a few tens of seconds is far below any motion threshold, hours of it are not.
const REFERENCE_WINDOWS: usize = 15;

/// The first stretch where a signal's window means depart from their local resting value (the
/// median of the means of the windows around) by more than `limit`: `(start_s, end_s,
/// departure)` relative to the first sample. A trailing window with less than half the
/// samples of a full one is left out (its mean is noisier).
fn first_motion(t_nanos: &[i64], x: &[f64], window_secs: f64, limit: f64) -> Option<(f64, f64, f64)> {
    let t0 = *t_nanos.first()?;
    let win = (window_secs * 1e9) as i64;
    let mut means: Vec<(i64, i64, f64, usize)> = Vec::new();
    let (mut start, mut acc, mut count) = (0usize, 0.0, 0usize);
    for (k, (&t, &v)) in t_nanos.iter().zip(x).enumerate() {
        if t - t_nanos[start] >= win && count > 0 {
            means.push((t_nanos[start], t_nanos[k - 1], acc / count as f64, count));
            start = k;
            acc = 0.0;
            count = 0;
        }
        if v.is_finite() {
            acc += v;
            count += 1;
        }
    }
    let full = means.iter().map(|m| m.3).max().unwrap_or(0);
    if count > 0 && 2 * count >= full {
        means.push((t_nanos[start], *t_nanos.last()?, acc / count as f64, count));
    }
    let departure = |i: usize| {
        let (a, b) = (i.saturating_sub(REFERENCE_WINDOWS), (i + REFERENCE_WINDOWS + 1).min(means.len()));
        let mut around: Vec<f64> = means[a..b].iter().map(|m| m.2).collect();
        around.sort_by(f64::total_cmp);
        (means[i].2 - around[around.len() / 2]).abs()
    };
    let first = (0..means.len()).find(|&i| departure(i) > limit)?;
    let mut last = first;
    let mut worst = departure(first);
    while last + 1 < means.len() && departure(last + 1) > limit {
        last += 1;
        worst = worst.max(departure(last));
    }
    Some(((means[first].0 - t0) as f64 * 1e-9, (means[last].1 - t0) as f64 * 1e-9, worst))
}

const AXES: [&str; 3] = ["x", "y", "z"];

/// Refuses an IMU log in which the IMU moved.
///
/// # Errors
/// [`Error::BadLog`] naming the topic, sensor, axis, the time span and the departure.
pub fn check_imu_still(imu: &ImuLog, opts: &NoiseOptions) -> Result<()> {
    for (sensor, series, limit, unit, flag) in [
        ("gyro", &imu.gyro, opts.gyro_motion_rad_s, "rad/s", "--gyro-motion"),
        ("accelerometer", &imu.accel, opts.accel_motion_mps2, "m/s²", "--accel-motion"),
    ] {
        for (a, x) in series.iter().enumerate() {
            if let Some((t0, t1, dep)) = first_motion(&imu.t_nanos, x, opts.still_window_secs, limit) {
                return Err(Error::BadLog {
                    source_name: imu.topic.clone(),
                    message: format!(
                        "the robot moved: {sensor} {} departs from its resting value by {dep:.3} {unit} at t = \
                         {t0:.1}–{t1:.1} s (allowed {limit} {unit}, {flag}); noise is measured on a log of the \
                         robot standing still: record one, or cut the log to its still part",
                        AXES[a]
                    ),
                });
            }
        }
    }
    Ok(())
}

/// Refuses a joint log in which a joint moved.
///
/// # Errors
/// [`Error::BadLog`] naming the joint and the time span.
pub fn check_joints_still(log: &JointLog, opts: &NoiseOptions) -> Result<()> {
    for (j, name) in log.joint_names.iter().enumerate() {
        if let Some((t0, t1, dep)) =
            first_motion(&log.t_nanos, &log.position[j], opts.still_window_secs, opts.encoder_motion)
        {
            return Err(log.bad(format!(
                "the robot moved: joint \"{name}\" departs from its resting position by {dep:.4} at t = {t0:.1}–{t1:.1} \
                 s (allowed {}, --encoder-motion); noise is measured on a log of the robot standing still",
                opts.encoder_motion
            )));
        }
    }
    Ok(())
}

/// Allan deviation and noise fit of every axis of `imu`, after the stillness check.
///
/// # Errors
/// [`Error::BadLog`] for a moving IMU, a log shorter than [`NoiseOptions::min_duration_secs`]
/// or than [`MIN_CLUSTERS`]·τ_max; [`Error::Option`] for invalid options.
pub fn analyze_imu(imu: &ImuLog, opts: &NoiseOptions) -> Result<ImuNoise> {
    opts.check()?;
    let duration = imu.duration_secs();
    let rate = imu.rate_hz();
    if duration < opts.min_duration_secs || rate <= 0.0 {
        return Err(Error::BadLog {
            source_name: imu.topic.clone(),
            message: format!(
                "the log is {duration:.1} s long ({} samples); noise calibration needs at least {} s of the robot \
                 standing still (hours for bias instability and random walk)",
                imu.t_nanos.len(),
                opts.min_duration_secs
            ),
        });
    }
    let tau_max = match opts.tau_max_secs {
        Some(t) if duration < MIN_CLUSTERS * t => {
            return Err(Error::BadLog {
                source_name: imu.topic.clone(),
                message: format!(
                    "the log is {duration:.1} s long: too short for τ up to {t} s, which needs at least {:.0} s \
                     ({MIN_CLUSTERS} × τ); record longer or lower --tau-max",
                    MIN_CLUSTERS * t
                ),
            });
        }
        Some(t) => t,
        None => duration / MIN_CLUSTERS,
    };
    check_imu_still(imu, opts)?;
    let n = imu.t_nanos.len();
    let max_m = ((tau_max * rate).floor() as usize).min((n - 1) / 2);
    let ms = allan::cluster_sizes(max_m, opts.points_per_decade);
    let mut axes = Vec::with_capacity(6);
    for (sensor, series) in [("gyro", &imu.gyro), ("accel", &imu.accel)] {
        for (a, x) in series.iter().enumerate() {
            let mut points = allan::overlapping_adev(x, rate, &ms);
            let fit = allan::fit_noise(&mut points, n, opts.confidence);
            axes.push(AxisNoise { sensor, axis: AXES[a], points, fit });
        }
    }
    Ok(ImuNoise {
        topic: imu.topic.clone(),
        frame_id: imu.frame_id.clone(),
        rate_hz: rate,
        duration_secs: duration,
        axes,
    })
}

/// Encoder noise of every joint of a still log.
///
/// # Errors
/// [`Error::BadLog`] when a joint moved or has no finite position.
pub fn analyze_encoders(log: &JointLog, opts: &NoiseOptions) -> Result<Vec<EncoderNoise>> {
    opts.check()?;
    log.check_shape()?;
    check_joints_still(log, opts)?;
    let mut out = Vec::new();
    for (j, name) in log.joint_names.iter().enumerate() {
        let x: Vec<f64> = log.position[j].iter().copied().filter(|v| v.is_finite()).collect();
        if x.is_empty() {
            return Err(log.bad(format!("joint \"{name}\" has no finite position")));
        }
        let mean = x.iter().sum::<f64>() / x.len() as f64;
        let sigma = (x.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (x.len().max(2) - 1) as f64).sqrt();
        let mut distinct = x.clone();
        distinct.sort_by(f64::total_cmp);
        distinct.dedup();
        out.push(EncoderNoise {
            joint: name.clone(),
            sigma,
            quantization_step: quantization_step(&distinct),
            distinct_values: distinct.len(),
        });
    }
    Ok(out)
}

/// The grid step of sorted distinct `values`: the smallest gap, if every gap is a whole multiple
/// of it (to 2 %) and there are far fewer values than a continuous signal would give.
fn quantization_step(values: &[f64]) -> Option<f64> {
    if values.len() < 2 {
        return None;
    }
    let gaps: Vec<f64> = values.windows(2).map(|w| w[1] - w[0]).collect();
    let min = gaps.iter().copied().fold(f64::INFINITY, f64::min);
    if min.is_nan() || min <= 0.0 {
        return None;
    }
    // Refine as the mean of the gaps that are one step (the smallest gap alone carries the
    // rounding of the numbers).
    let ones: Vec<f64> = gaps.iter().copied().filter(|g| *g < 1.5 * min).collect();
    let step = ones.iter().sum::<f64>() / ones.len() as f64;
    let on_grid = gaps.iter().all(|g| {
        let r = g / step;
        (r - r.round()).abs() < 0.02
    });
    on_grid.then_some(step)
}

/// A per-sample Gazebo noise of one IMU axis.
#[derive(Debug, Clone, Copy, PartialEq, Serialize)]
pub struct AxisNoiseUpdate {
    /// `<stddev>`: white noise per sample, `N·√f`.
    pub stddev: f64,
    /// `<dynamic_bias_stddev>` σ_b of the bias-instability Gauss–Markov process (`None`: not
    /// resolved, left as is).
    pub dynamic_bias_stddev: Option<f64>,
    /// `<dynamic_bias_correlation_time>` τc, s.
    pub dynamic_bias_correlation_time: Option<f64>,
    /// `<bias_random_walk>` = `K` (`None`: not resolved with the floor, left as is).
    pub bias_random_walk: Option<f64>,
}

/// Allan deviation peak of a first-order Gauss–Markov process over its stationary deviation,
/// reached at τ ≈ [`GAUSS_MARKOV_PEAK_TAU`]·τc.
pub const GAUSS_MARKOV_PEAK: f64 = 0.6174;
/// Where the Gauss–Markov Allan deviation peaks, in correlation times.
pub const GAUSS_MARKOV_PEAK_TAU: f64 = 1.8926;

impl AxisNoiseUpdate {
    /// The Gazebo noise of an axis fitted `fit`, sampled at `rate_hz`. The bias instability
    /// needs the random walk to place its Gauss–Markov peak (the curve's minimum `√3·N/K`):
    /// the bias terms are written when both are resolved, else left as they are.
    pub fn from_fit(fit: &NoiseFit, rate_hz: f64) -> AxisNoiseUpdate {
        let (n, b, k) = (fit.white_density, fit.bias_instability, fit.bias_random_walk);
        let stddev = n * rate_hz.sqrt();
        let (dyn_std, corr) = if k > 0.0 && b > 0.0 && n > 0.0 {
            let tau_c = 3f64.sqrt() * n / k / GAUSS_MARKOV_PEAK_TAU;
            let stationary = allan::BIAS_INSTABILITY_FLOOR * b / GAUSS_MARKOV_PEAK;
            (Some(stationary / (tau_c / 2.0).sqrt()), Some(tau_c))
        } else {
            (None, None)
        };
        AxisNoiseUpdate {
            stddev,
            dynamic_bias_stddev: dyn_std,
            dynamic_bias_correlation_time: corr,
            // Only with the floor resolved too: a white-noise log's fit can show a spurious
            // slope at its last few τ, which is no reason to add a bias to the URDF.
            bias_random_walk: dyn_std.map(|_| k),
        }
    }
}

/// New noise of one Gazebo IMU sensor.
#[derive(Debug, Clone, PartialEq, Serialize)]
pub struct ImuNoiseUpdate {
    /// `<gazebo reference>` of the sensor (its link).
    pub reference: String,
    /// Where the numbers came from (topic), for messages.
    pub topic: String,
    /// Sample rate the stddev is for, Hz.
    pub rate_hz: f64,
    /// Angular velocity x, y, z.
    pub gyro: [AxisNoiseUpdate; 3],
    /// Linear acceleration x, y, z.
    pub accel: [AxisNoiseUpdate; 3],
}

/// Gazebo IMU sensors of a URDF: `(reference, <update_rate>)`.
///
/// # Errors
/// [`Error::Urdf`] for malformed XML.
pub fn urdf_imus(path: &Path, text: &str) -> Result<Vec<(String, Option<f64>)>> {
    let doc = roxmltree::Document::parse(text)
        .map_err(|e| Error::Urdf { path: path.to_path_buf(), message: format!("not well-formed XML: {e}") })?;
    let mut out = Vec::new();
    for g in doc.root_element().children().filter(|n| n.has_tag_name("gazebo")) {
        for s in g.children().filter(|n| n.has_tag_name("sensor") && n.attribute("type") == Some("imu")) {
            let rate = s
                .children()
                .find(|c| c.has_tag_name("update_rate"))
                .and_then(|r| r.text())
                .and_then(|t| t.trim().parse::<f64>().ok())
                .filter(|r| *r > 0.0);
            out.push((g.attribute("reference").unwrap_or("").to_string(), rate));
        }
    }
    Ok(out)
}

/// Matches measured IMUs to the URDF's Gazebo IMU sensors (by `header.frame_id` = `<gazebo
/// reference>`, or one to one when each side has a single IMU) and builds their updates.
/// Returns the updates and warnings (a frame mismatch matched one to one, a rate difference).
///
/// # Errors
/// [`Error::Urdf`] when an IMU of the log has no sensor in the URDF.
pub fn imu_noise_updates(path: &Path, text: &str, imus: &[ImuNoise]) -> Result<(Vec<ImuNoiseUpdate>, Vec<String>)> {
    let sensors = urdf_imus(path, text)?;
    let mut warnings = Vec::new();
    let mut out = Vec::new();
    for imu in imus {
        let found = sensors.iter().find(|(r, _)| *r == imu.frame_id).or_else(|| {
            (sensors.len() == 1 && imus.len() == 1).then(|| {
                warnings.push(format!(
                    "{}: frame \"{}\" is not a <gazebo reference> of the URDF; updating its only IMU sensor (on \"{}\")",
                    imu.topic, imu.frame_id, sensors[0].0
                ));
                &sensors[0]
            })
        });
        let Some((reference, rate)) = found else {
            let have: Vec<&str> = sensors.iter().map(|(r, _)| r.as_str()).collect();
            return Err(Error::Urdf {
                path: path.to_path_buf(),
                message: format!(
                    "no <gazebo reference=\"{}\"><sensor type=\"imu\"> for the IMU of {} (IMU sensors in the URDF: {}); \
                     add one, or publish the IMU with header.frame_id set to its link",
                    imu.frame_id,
                    imu.topic,
                    if have.is_empty() { "none".into() } else { have.join(", ") }
                ),
            });
        };
        let rate_hz = rate.unwrap_or(imu.rate_hz);
        if (rate_hz / imu.rate_hz - 1.0).abs() > 0.05 {
            warnings.push(format!(
                "{}: the URDF samples the IMU at {rate_hz} Hz, the log at {:.1} Hz: per-sample stddev written for {rate_hz} Hz",
                imu.topic, imu.rate_hz
            ));
        }
        let axis = |k: usize| AxisNoiseUpdate::from_fit(&imu.axes[k].fit, rate_hz);
        out.push(ImuNoiseUpdate {
            reference: reference.clone(),
            topic: imu.topic.clone(),
            rate_hz,
            gyro: [axis(0), axis(1), axis(2)],
            accel: [axis(3), axis(4), axis(5)],
        });
    }
    Ok((out, warnings))
}

impl NoiseReport {
    /// The terminal table.
    pub fn table(&self) -> String {
        let mut out = String::new();
        let g = crate::number::format_number;
        for imu in &self.imus {
            let _ = writeln!(
                out,
                "IMU {} (frame {}): {:.1} Hz, {:.0} s still; Allan deviation fit ({:.0} % band):",
                imu.topic,
                imu.frame_id,
                imu.rate_hz,
                imu.duration_secs,
                100.0 * self.confidence
            );
            let _ =
                writeln!(out, "  {:<8} {:>14} {:>14} {:>14} {:>10}", "axis", "N (/√Hz)", "B", "K (/s/√Hz)", "fit rms");
            for a in &imu.axes {
                let f = &a.fit;
                let show = |v: f64, rel: f64| {
                    if v > 0.0 { format!("{} ±{:.0}%", g(v), 100.0 * rel) } else { "not seen".into() }
                };
                let _ = writeln!(
                    out,
                    "  {:<8} {:>14} {:>14} {:>14} {:>9.1}%",
                    format!("{} {}", a.sensor, a.axis),
                    show(f.white_density, f.rel_std[0]),
                    show(f.bias_instability, f.rel_std[1]),
                    show(f.bias_random_walk, f.rel_std[2]),
                    100.0 * f.log_rms_residual
                );
            }
            let _ = writeln!(out, "  units: gyro rad/s, accelerometer m/s² (N per √Hz, K per s per √Hz)");
        }
        if !self.encoders.is_empty() {
            let _ = writeln!(out, "Encoders:");
            let _ = writeln!(out, "  {:<24} {:>12} {:>14} {:>9}", "joint", "σ", "quantization", "levels");
            for e in &self.encoders {
                let _ = writeln!(
                    out,
                    "  {:<24} {:>12} {:>14} {:>9}",
                    e.joint,
                    g(e.sigma),
                    e.quantization_step.map_or("-".into(), g),
                    e.distinct_values
                );
            }
        }
        out
    }

    /// The report as JSON.
    pub fn to_json(&self) -> String {
        serde_json::to_string_pretty(self).expect("the report serializes")
    }

    /// A `twin randomize` spec fragment (TOML) from the measured noise: IMU white noise scaled
    /// around the values written into the URDF by the fits' 95 % relative uncertainty (at least
    /// ±10 %), encoder noise drawn up to the largest measured σ (or Δ/√12).
    pub fn spec_fragment(&self) -> String {
        let mut out = String::from("# Sensor noise measured by `twin calibrate noise`");
        let _ = writeln!(out, " from {}.", self.log);
        let rel =
            self.imus.iter().flat_map(|i| &i.axes).map(|a| 1.96 * a.fit.rel_std[0]).fold(0.1_f64, f64::max).min(0.9);
        if !self.imus.is_empty() {
            let _ = writeln!(
                out,
                "# IMU white noise: the URDF's <noise><stddev> (written by the same run) scaled by ±{:.0} %.",
                100.0 * rel
            );
            let _ = writeln!(
                out,
                "[imu_noise_std]\nmode = \"scale\"\ndist = \"uniform\"\nlow = {}\nhigh = {}\n",
                crate::number::format_number(1.0 - rel),
                crate::number::format_number(1.0 + rel)
            );
        }
        let enc = self
            .encoders
            .iter()
            .map(|e| e.sigma.max(e.quantization_step.map_or(0.0, |d| d / 12f64.sqrt())))
            .fold(0.0_f64, f64::max);
        if enc > 0.0 {
            let _ = writeln!(out, "# Encoder noise: up to the largest measured σ (or quantization step/√12), rad.");
            let _ = writeln!(
                out,
                "[encoder_noise_std]\nmode = \"absolute\"\ndist = \"uniform\"\nlow = 0\nhigh = {}",
                crate::number::format_number(enc)
            );
        }
        out
    }

    /// The Allan deviation curves of [`NoiseReport::svg`] for a rerun recording: per IMU axis,
    /// `allan/<topic>/<sensor>_<axis>/{data,low,high,fit}` with points `(log10 τ, log10 σ)`
    /// (rerun plots scalars against a linear timeline, so both axes are logarithms).
    pub fn allan_curves(&self) -> Vec<(String, Vec<(f64, f64)>)> {
        let mut out = Vec::new();
        for imu in &self.imus {
            let topic: String =
                imu.topic.chars().map(|c| if c.is_alphanumeric() || c == '_' { c } else { '_' }).collect();
            for a in &imu.axes {
                let base = format!("allan/{}/{}_{}", topic.trim_matches('_'), a.sensor, a.axis);
                let curve = |f: &dyn Fn(&crate::allan::AllanPoint) -> f64| -> Vec<(f64, f64)> {
                    a.points.iter().map(|p| (p.tau_secs.log10(), f(p).log10())).collect()
                };
                out.push((format!("{base}/data"), curve(&|p| p.adev)));
                out.push((format!("{base}/low"), curve(&|p| p.adev_low)));
                out.push((format!("{base}/high"), curve(&|p| p.adev_high)));
                out.push((format!("{base}/fit"), curve(&|p| a.fit.adev_at(p.tau_secs))));
            }
        }
        out
    }

    /// SVG plot of each IMU's Allan deviations (band, points, fitted model), one panel per
    /// sensor (gyro, accelerometer).
    pub fn svg(&self) -> String {
        let mut panels = Vec::new();
        for imu in &self.imus {
            for (sensor, unit) in [("gyro", "rad/s"), ("accel", "m/s²")] {
                let mut plot = crate::plot::Plot::new(
                    &format!("Allan deviation, {} {}", imu.topic, sensor),
                    "τ (s)",
                    &format!("σ(τ) ({unit})"),
                );
                plot.log_x = true;
                plot.log_y = true;
                for (c, a) in imu.axes.iter().filter(|a| a.sensor == sensor).enumerate() {
                    let color = crate::plot::COLORS[c % crate::plot::COLORS.len()];
                    plot.band(a.points.iter().map(|p| (p.tau_secs, p.adev_low, p.adev_high)).collect(), color);
                    plot.points(
                        &format!("{} data", a.axis),
                        a.points.iter().map(|p| (p.tau_secs, p.adev)).collect(),
                        color,
                    );
                    plot.line(
                        &format!("{} fit", a.axis),
                        a.points.iter().map(|p| (p.tau_secs, a.fit.adev_at(p.tau_secs))).collect(),
                        color,
                    );
                }
                panels.push(plot);
            }
        }
        crate::plot::stack_svg(&panels)
    }
}

/// Known noise of one synthetic IMU axis (units of the axis).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct AxisTruth {
    /// Constant value (gravity, bias), added.
    pub offset: f64,
    /// White-noise density `N`, per √Hz.
    pub white_density: f64,
    /// Bias instability `B`: the Allan floor is `0.664·B`.
    pub bias_instability: f64,
    /// Bias random walk `K`, per s per √Hz.
    pub bias_random_walk: f64,
}

/// A synthetic still axis: white noise `N·√f` per sample, a bias random walk with steps
/// `K·√Δt`, and flicker (1/f) noise of level `B` made of first-order Gauss–Markov processes
/// with correlation times spaced 3 per decade from 2 samples to 100× the duration and equal
/// variances `c`: their summed spectrum is `c/(f·ln r)` (r = 10^⅓), whose Allan deviation is
/// flat at `√(2·ln 2·c/ln r)`, set to `0.664·B`.
pub fn synth_axis(truth: &AxisTruth, rate_hz: f64, samples: usize, rng: &mut ChaCha8Rng) -> Vec<f64> {
    let dt = 1.0 / rate_hz;
    let white = truth.white_density * rate_hz.sqrt();
    let walk = truth.bias_random_walk * dt.sqrt();
    let ln_r = 10f64.ln() / 3.0;
    let floor = allan::BIAS_INSTABILITY_FLOOR * truth.bias_instability;
    let c = floor * floor * ln_r / (2.0 * 2f64.ln());
    // Slow processes are advanced every `every` samples (T/200 of their correlation time) and
    // interpolated linearly in between: the same spectrum where it matters, far fewer draws.
    struct Gm {
        every: usize,
        phi: f64,
        drive: f64,
        prev: f64,
        next: f64,
    }
    let mut gm: Vec<Gm> = Vec::new();
    if c > 0.0 {
        let t_max = 100.0 * samples as f64 * dt;
        let mut t = 2.0 * dt;
        while t < t_max {
            let every = ((t / (200.0 * dt)).floor() as usize).max(1);
            let phi = (-(every as f64) * dt / t).exp();
            let prev = c.sqrt() * rng.sample::<f64, _>(StandardNormal);
            let next = phi * prev + (c * (1.0 - phi * phi)).sqrt() * rng.sample::<f64, _>(StandardNormal);
            gm.push(Gm { every, phi, drive: (c * (1.0 - phi * phi)).sqrt(), prev, next });
            t *= ln_r.exp();
        }
    }
    let mut bias = 0.0;
    let mut out = Vec::with_capacity(samples);
    for k in 0..samples {
        let mut flicker = 0.0;
        for g in gm.iter_mut() {
            let phase = k % g.every;
            if phase == 0 && k > 0 {
                g.prev = g.next;
                g.next = g.phi * g.prev + g.drive * rng.sample::<f64, _>(StandardNormal);
            }
            flicker += g.prev + (g.next - g.prev) * phase as f64 / g.every as f64;
        }
        out.push(truth.offset + bias + flicker + white * rng.sample::<f64, _>(StandardNormal));
        bias += walk * rng.sample::<f64, _>(StandardNormal);
    }
    out
}

/// A synthetic still IMU on `topic` (frame `frame_id`): axes from `gyro` and `accel` truths,
/// `duration_secs` at `rate_hz`, deterministic for `seed`.
pub fn synth_imu(
    topic: &str,
    frame_id: &str,
    gyro: [AxisTruth; 3],
    accel: [AxisTruth; 3],
    rate_hz: f64,
    duration_secs: f64,
    seed: u64,
) -> ImuLog {
    let n = (duration_secs * rate_hz).round() as usize + 1;
    let step = (1e9 / rate_hz).round() as i64;
    let t_nanos: Vec<i64> = (0..n as i64).map(|k| 1_000_000_000 + k * step).collect();
    let mut rng = ChaCha8Rng::seed_from_u64(seed);
    let gyro = gyro.map(|t| synth_axis(&t, rate_hz, n, &mut rng));
    let accel = accel.map(|t| synth_axis(&t, rate_hz, n, &mut rng));
    ImuLog { topic: topic.into(), frame_id: frame_id.into(), t_nanos, gyro, accel }
}
