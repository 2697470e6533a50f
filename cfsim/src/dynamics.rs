//! Point-mass dynamics: a double integrator behind a cascaded first-order position → velocity
//! controller with bounded acceleration, gravity when the motors are off, and a flat ground at
//! z = 0.

/// Standard gravity (m/s²).
pub const G: f64 = 9.81;

/// What the controller tracks on one axis.
#[derive(Debug, Clone, Copy, PartialEq)]
pub enum Axis {
    /// Position `p` with velocity `v` and acceleration `a` feed-forward.
    Pos {
        /// Position (m).
        p: f64,
        /// Velocity feed-forward (m/s).
        v: f64,
        /// Acceleration feed-forward (m/s²).
        a: f64,
    },
    /// Velocity (m/s).
    Vel(f64),
    /// Acceleration (m/s²), open loop.
    Acc(f64),
}

impl Axis {
    /// Hold position `p`.
    pub fn hold(p: f64) -> Self {
        Axis::Pos { p, v: 0.0, a: 0.0 }
    }
}

/// Controller gains and limits.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Gains {
    /// Position gain (1/s): velocity command per metre of error.
    pub kp: f64,
    /// Velocity gain (1/s): acceleration command per m/s of error.
    pub kv: f64,
    /// Bound on the norm of the commanded acceleration (m/s²).
    pub max_accel: f64,
    /// Bound on the commanded velocity of the position loop (m/s).
    pub max_speed: f64,
}

/// Position, velocity and the last acceleration of the vehicle.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
pub struct Body {
    /// Position (m).
    pub p: [f64; 3],
    /// Velocity (m/s).
    pub v: [f64; 3],
    /// Acceleration applied during the last step (m/s²).
    pub a: [f64; 3],
}

impl Body {
    /// At rest at `p`.
    pub fn at(p: [f64; 3]) -> Self {
        Self { p, ..Self::default() }
    }

    /// One step of `dt` seconds with the motors tracking `refs`.
    pub fn step_controlled(&mut self, refs: [Axis; 3], g: &Gains, dt: f64) {
        let mut a = [0.0; 3];
        for k in 0..3 {
            a[k] = match refs[k] {
                Axis::Pos { p, v, a } => {
                    let vc = (v + g.kp * (p - self.p[k])).clamp(-g.max_speed, g.max_speed);
                    a + g.kv * (vc - self.v[k])
                }
                Axis::Vel(v) => g.kv * (v - self.v[k]),
                Axis::Acc(a) => a,
            };
        }
        // Motors cannot pull down harder than gravity.
        a[2] = a[2].max(-G);
        let n = (a[0] * a[0] + a[1] * a[1] + a[2] * a[2]).sqrt();
        if n > g.max_accel && n > 0.0 {
            a = a.map(|x| x * g.max_accel / n);
        }
        self.integrate(a, dt);
    }

    /// One step of `dt` seconds with the motors off: free fall, or resting on the ground.
    pub fn step_free(&mut self, dt: f64) {
        self.integrate([0.0, 0.0, -G], dt);
    }

    fn integrate(&mut self, a: [f64; 3], dt: f64) {
        let on_ground = self.p[2] <= 0.0;
        if on_ground && a[2] <= 0.0 {
            // Resting on the ground: no thrust to lift off, friction stops any sliding.
            self.v = [0.0; 3];
            self.a = [0.0; 3];
            self.p[2] = 0.0;
            return;
        }
        self.a = a;
        for ((p, v), a) in self.p.iter_mut().zip(&mut self.v).zip(a) {
            *v += a * dt;
            *p += *v * dt;
        }
        if self.p[2] < 0.0 {
            // Touch-down (or impact): stop on the ground.
            self.p[2] = 0.0;
            self.v = [0.0; 3];
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    const GAINS: Gains = Gains { kp: 2.0, kv: 8.0, max_accel: 4.0, max_speed: 5.0 };

    #[test]
    fn tracks_a_position_without_overshoot_and_within_bounds() {
        let mut b = Body::at([0.0, 0.0, 1.0]);
        let mut max_x = 0.0f64;
        for _ in 0..2000 {
            b.step_controlled([Axis::hold(1.0), Axis::hold(0.0), Axis::hold(1.0)], &GAINS, 0.002);
            let n = b.a.iter().map(|x| x * x).sum::<f64>().sqrt();
            assert!(n <= 4.0 + 1e-9);
            max_x = max_x.max(b.p[0]);
        }
        assert!((b.p[0] - 1.0).abs() < 1e-3, "{:?}", b.p);
        assert!(max_x < 1.01);
    }

    #[test]
    fn falls_and_rests_on_the_ground() {
        let mut b = Body::at([0.0, 0.0, 1.0]);
        for _ in 0..1000 {
            b.step_free(0.002);
        }
        assert_eq!(b.p[2], 0.0);
        assert_eq!(b.v, [0.0; 3]);
        // Sitting on the ground with a target below it.
        b.step_controlled([Axis::Vel(1.0), Axis::hold(0.0), Axis::hold(-1.0)], &GAINS, 0.002);
        assert_eq!(b.v, [0.0; 3]);
    }

    #[test]
    fn velocity_mode_reaches_the_velocity() {
        let mut b = Body::at([0.0, 0.0, 1.0]);
        for _ in 0..1000 {
            b.step_controlled([Axis::Vel(0.5), Axis::Vel(0.0), Axis::Vel(0.0)], &GAINS, 0.002);
        }
        assert!((b.v[0] - 0.5).abs() < 1e-6);
    }
}
