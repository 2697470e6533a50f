//! The Kalman estimator's covariance, for the `kalman.var*` log variables.
//!
//! The simulated estimate is the truth, but clients judge whether the estimator has settled by
//! its variances (cflib's examples wait until `kalman.varPX/PY/PZ` vary by less than 0.001 over a
//! window). Each axis keeps the covariance of a position/velocity pair as the firmware's
//! `kalman_core.c` does: initial standard deviations of 100 m (x, y), 1 m (z) and 0.01 m/s, process
//! noise of 0.5 m/s² (x, y) and 1 m/s² (z) added every 1 ms as `(noise·dt)²` to the velocity and
//! `(noise·dt²)²` to the position, predicted at 100 Hz. A simulated positioning system measures
//! the position at 100 Hz with the standard deviation of param `locSrv.extPosStdDev` (0.01 m by
//! default), so a position variance starts large after a boot or a `kalman.resetEstimation` and
//! settles within a fraction of a second, to about 6e-6 m² (x, y) and 8e-6 m² (z); the velocity
//! variances stay near 1e-4 (m/s)² (x, y) and 3e-4 (m/s)² (z).
//!
//! As in the firmware, `varX/varY/varZ` are the position variances and `varPX/varPY/varPZ` the
//! (body-frame) velocity variances (`P[KC_STATE_PX][KC_STATE_PX]`, ...).

/// Filter cycle (s): the firmware predicts at 100 Hz; the simulated positioning system measures
/// at the same rate.
pub const CYCLE: f64 = 0.01;
/// Initial position standard deviation, x and y (m).
const INITIAL_POSITION_XY: f64 = 100.0;
/// Initial position standard deviation, z (m).
const INITIAL_POSITION_Z: f64 = 1.0;
/// Initial velocity standard deviation (m/s).
const INITIAL_VELOCITY: f64 = 0.01;
/// Process noise on the acceleration, per axis (m/s²).
const PROCESS_NOISE_ACC: [f64; 3] = [0.5, 0.5, 1.0];
/// The firmware adds the process noise on every 1 kHz stabilizer step (s).
const PROCESS_NOISE_STEP: f64 = 0.001;

/// Covariance of one axis' (position, velocity) pair.
#[derive(Debug, Clone, Copy, PartialEq)]
struct AxisCovariance {
    pp: f64,
    pv: f64,
    vv: f64,
}

impl AxisCovariance {
    fn initial(position_std: f64) -> Self {
        Self { pp: position_std.powi(2), pv: 0.0, vv: INITIAL_VELOCITY.powi(2) }
    }

    /// Constant-velocity prediction over `dt` plus the firmware's diagonal process noise, added
    /// once per [`PROCESS_NOISE_STEP`].
    fn predict(&mut self, dt: f64, acc_noise: f64) {
        let Self { pp, pv, vv } = *self;
        let (n, s) = (dt / PROCESS_NOISE_STEP, PROCESS_NOISE_STEP);
        self.pp = pp + 2.0 * dt * pv + dt * dt * vv + n * (acc_noise * s * s).powi(2);
        self.pv = pv + dt * vv;
        self.vv = vv + n * (acc_noise * s).powi(2);
    }

    /// A position measurement with variance `r`.
    fn measure(&mut self, r: f64) {
        let Self { pp, pv, vv } = *self;
        let s = pp + r;
        self.pp = pp * r / s;
        self.pv = pv * r / s;
        self.vv = vv - pv * pv / s;
    }
}

/// The estimator's position and velocity variances on the three axes.
#[derive(Debug, Clone, PartialEq)]
pub struct Estimator {
    axes: [AxisCovariance; 3],
    /// Time not yet run through a filter cycle (s).
    pending: f64,
}

impl Default for Estimator {
    fn default() -> Self {
        Self::new()
    }
}

impl Estimator {
    /// Just reset: position unknown (large variance), velocity known to be about zero.
    pub fn new() -> Self {
        let axes =
            [INITIAL_POSITION_XY, INITIAL_POSITION_XY, INITIAL_POSITION_Z].map(AxisCovariance::initial);
        Self { axes, pending: 0.0 }
    }

    /// Reset the estimation (param `kalman.resetEstimation`, or a reboot).
    pub fn reset(&mut self) {
        *self = Self::new();
    }

    /// Advance by `dt` (s), measuring the position with standard deviation `measurement_std` (m)
    /// once per [`CYCLE`].
    pub fn step(&mut self, dt: f64, measurement_std: f64) {
        // A client can write any float: a tiny one is floored so the variance stays positive, a
        // non-finite one means no usable measurement.
        let r = measurement_std.is_finite().then(|| measurement_std.abs().max(1e-4).powi(2));
        self.pending += dt;
        while self.pending >= CYCLE - 1e-12 {
            self.pending -= CYCLE;
            for (axis, noise) in self.axes.iter_mut().zip(PROCESS_NOISE_ACC) {
                axis.predict(CYCLE, noise);
                if let Some(r) = r {
                    axis.measure(r);
                }
            }
        }
    }

    /// Position variances x, y, z (m²): `kalman.varX/varY/varZ`.
    pub fn position_variance(&self) -> [f64; 3] {
        self.axes.map(|a| a.pp)
    }

    /// Velocity variances x, y, z ((m/s)²): `kalman.varPX/varPY/varPZ`.
    pub fn velocity_variance(&self) -> [f64; 3] {
        self.axes.map(|a| a.vv)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// cflib's "wait for the position estimator": the last 10 samples of each variance (at
    /// `period` s) spread by less than 0.001. Returns the time it took, or `None` within `limit`.
    fn settles(e: &mut Estimator, period: f64, limit: f64, var: fn(&Estimator) -> [f64; 3]) -> Option<f64> {
        let mut history = vec![[1000.0; 3]; 10];
        let mut t = 0.0;
        while t < limit {
            e.step(period, 0.01);
            t += period;
            history.remove(0);
            history.push(var(e));
            let spread = |k: usize| {
                let v = history.iter().map(|h| h[k]);
                v.clone().fold(f64::MIN, f64::max) - v.fold(f64::MAX, f64::min)
            };
            if (0..3).all(|k| spread(k) < 0.001) {
                return Some(t);
            }
        }
        None
    }

    #[test]
    fn starts_uncertain_and_settles_small() {
        let mut e = Estimator::new();
        assert_eq!(e.position_variance(), [1e4, 1e4, 1.0]);
        assert!((e.velocity_variance()[0] - 1e-4).abs() < 1e-12);
        e.step(0.5, 0.01);
        for k in 0..3 {
            let (p, v) = (e.position_variance()[k], e.velocity_variance()[k]);
            assert!(p > 1e-6 && p < 1e-4, "position variance {p}");
            assert!(v > 1e-5 && v < 1e-3, "velocity variance {v}");
        }
        // Settled: it stays put.
        e.step(1.5, 0.01);
        let before = e.clone();
        e.step(5.0, 0.01);
        for k in 0..3 {
            for (a, b) in [
                (before.position_variance()[k], e.position_variance()[k]),
                (before.velocity_variance()[k], e.velocity_variance()[k]),
            ] {
                assert!((a - b).abs() < 1e-3 * a, "{a} -> {b}");
            }
        }
        // Reset: uncertain again.
        e.reset();
        assert_eq!(e.position_variance()[0], 1e4);
    }

    #[test]
    fn cflib_wait_for_estimator_passes_after_a_window() {
        // The window is full after 10 samples and passes at once: every sample is already small.
        let t = settles(&mut Estimator::new(), 0.5, 20.0, Estimator::velocity_variance).expect("settles");
        assert!((t - 5.0).abs() < 1e-9, "{t}");
        let t = settles(&mut Estimator::new(), 0.1, 20.0, Estimator::position_variance).expect("settles");
        assert!((t - 1.0).abs() < 1e-9, "{t}");
        // Without measurements (a huge standard deviation) the position never settles.
        let mut lost = Estimator::new();
        lost.step(0.5, 1e6);
        assert!(lost.position_variance()[0] > 1e3);
    }

    #[test]
    fn odd_steps_and_bad_noise() {
        let (mut a, mut b) = (Estimator::new(), Estimator::new());
        for _ in 0..250 {
            a.step(0.002, 0.01);
        }
        b.step(0.5, 0.01);
        assert!((a.position_variance()[2] - b.position_variance()[2]).abs() < 1e-12);
        for std in [0.0, f64::NAN, -1.0, f64::INFINITY] {
            let mut e = Estimator::new();
            e.step(1.0, std);
            assert!(
                e.position_variance().iter().chain(&e.velocity_variance()).all(|v| v.is_finite() && *v > 0.0)
            );
        }
    }
}
