use super::*;

const DT: f64 = 0.001;
const CF: QuadParams = QuadParams::CRAZYFLIE_2_1;

fn run(q: &mut Quadrotor, seconds: f64) {
    for _ in 0..(seconds / DT).round() as usize {
        q.step(DT);
    }
}

/// In the air at `z`, rotors already at their hover speed under the hover PWM.
fn hovering_at(z: f64) -> Quadrotor {
    let mut q = Quadrotor::new(CF, [0.0, 0.0, z]);
    let pwm = CF.hover_pwm().round() as u16;
    q.set_pwm([pwm; 4]);
    q.state.rotor_speeds = [CF.rotor_speed_command(pwm); 4];
    q
}

fn norm(v: &[f64]) -> f64 {
    v.iter().map(|c| c * c).sum::<f64>().sqrt()
}

#[test]
fn hover_pwm_holds_altitude_and_attitude() {
    let hover = CF.hover_pwm();
    assert!((35_000.0..45_000.0).contains(&hover), "hover PWM {hover}");
    let mut q = hovering_at(1.0);
    run(&mut q, 2.0);
    let t = q.truth();
    assert!((t.position[2] - 1.0).abs() < 0.005, "z {}", t.position[2]);
    assert!(norm(&t.velocity) < 0.005, "v {:?}", t.velocity);
    assert!(t.euler.iter().all(|a| a.abs() < 1e-9), "attitude {:?}", t.euler);
    assert!(!t.on_floor);
    // The accelerometer feels the thrust: 1 g up.
    let imu = q.imu(None);
    assert!((i32::from(imu.accel[2]) - 2048).abs() <= 1, "{imu:?}");
}

#[test]
fn free_fall_accelerates_at_g_until_the_floor() {
    let mut q = Quadrotor::new(CF, [0.0, 0.0, 2.0]);
    run(&mut q, 0.3);
    let t = q.truth();
    assert!((t.velocity[2] + G * 0.3).abs() < 1e-9, "vz {}", t.velocity[2]);
    assert!((t.position[2] - (2.0 - 0.5 * G * 0.09)).abs() < 1e-3, "z {}", t.position[2]);
    assert_eq!(q.imu(None).accel, [0, 0, 0], "weightless in free fall");
    let mut steps = 0;
    while !q.state.on_floor && steps < 2_000 {
        q.step(DT);
        steps += 1;
    }
    // From 2 m the fall takes sqrt(2 h / g) = 0.64 s.
    assert!(q.state.on_floor && (0.3..0.4).contains(&(steps as f64 * DT)), "landed after {steps} ms");
    run(&mut q, 0.1);
    let t = q.truth();
    assert_eq!((t.position[2], t.velocity), (0.0, [0.0; 3]));
    assert_eq!(q.imu(None), ImuSample { accel: [0, 0, 2048], gyro: [0; 3] });
}

#[test]
fn floor_holds_until_the_thrust_exceeds_the_weight() {
    let mut q = Quadrotor::new(CF, [1.0, 2.0, 0.0]);
    q.set_pwm([30_000; 4]);
    run(&mut q, 0.5);
    assert!(q.state.on_floor && q.state.position == [1.0, 2.0, 0.0]);
    q.set_pwm([CF.hover_pwm() as u16 + 3_000; 4]);
    run(&mut q, 0.5);
    assert!(!q.state.on_floor && q.state.position[2] > 0.05, "z {}", q.state.position[2]);
}

/// The firmware's force-torque mixer raises these motors for a positive torque about x, y, z
/// and lowers the others.
const TORQUE_PATTERNS: [[i32; 4]; 3] = [[-1, -1, 1, 1], [-1, 1, 1, -1], [-1, 1, -1, 1]];

#[test]
fn torques_turn_the_body_the_way_the_firmware_expects() {
    for (axis, pattern) in TORQUE_PATTERNS.iter().enumerate() {
        let mut q = hovering_at(1.0);
        let hover = q.pwm()[0] as i32;
        q.set_pwm(pattern.map(|s| (hover + 1_000 * s) as u16));
        run(&mut q, 0.05);
        let w = q.state.body_rates;
        assert!(w[axis] > 0.05, "axis {axis}: rates {w:?}");
        for other in (0..3).filter(|&k| k != axis) {
            assert!(w[other].abs() < 1e-6 * w[axis], "axis {axis}: rates {w:?}");
        }
        assert!(q.truth().euler[axis] > 0.0, "axis {axis}");
    }
    // Rolling right (positive roll, left side up) tilts the thrust towards -y.
    let mut q = hovering_at(1.0);
    let hover = q.pwm()[0] as i32;
    q.set_pwm(TORQUE_PATTERNS[0].map(|s| (hover + 1_000 * s) as u16));
    run(&mut q, 0.05);
    q.set_pwm([hover as u16; 4]);
    run(&mut q, 0.2);
    assert!(q.state.velocity[1] < -0.01, "v {:?}", q.state.velocity);
}

#[test]
fn torque_free_rotation_keeps_energy_and_angular_momentum() {
    let mut q = Quadrotor::new(CF, [0.0, 0.0, 100.0]);
    q.state.body_rates = [3.0, 0.2, 2.0];
    let inertia = CF.inertia;
    let energy =
        |q: &Quadrotor| (0..3).map(|k| 0.5 * inertia[k] * q.state.body_rates[k].powi(2)).sum::<f64>();
    let momentum = |q: &Quadrotor| {
        let w = q.state.body_rates;
        rotate(q.state.attitude, [inertia[0] * w[0], inertia[1] * w[1], inertia[2] * w[2]])
    };
    let (e0, l0) = (energy(&q), momentum(&q));
    run(&mut q, 0.5);
    let (e1, l1) = (energy(&q), momentum(&q));
    assert!((e1 - e0).abs() < 1e-3 * e0, "energy {e0} -> {e1}");
    let dl = [l1[0] - l0[0], l1[1] - l0[1], l1[2] - l0[2]];
    assert!(norm(&dl) < 1e-3 * norm(&l0), "momentum {l0:?} -> {l1:?}");
    assert!((norm(&q.state.attitude) - 1.0).abs() < 1e-12);
    // It did turn: the attitude is far from the start.
    assert!(q.state.attitude[0].abs() < 0.99);
}

#[test]
fn rotor_drag_slows_horizontal_flight_and_wind_pushes() {
    let mut q = hovering_at(1.0);
    q.state.velocity = [1.0, 0.0, 0.0];
    run(&mut q, 1.0);
    // Decay rate k_d Σω / m ≈ 0.26 /s.
    let vx = q.state.velocity[0];
    assert!((0.7..0.85).contains(&vx), "vx {vx}");

    let mut q = hovering_at(1.0);
    q.external_force = [0.0, 0.01, 0.0];
    run(&mut q, 0.5);
    let v = q.state.velocity;
    assert!(v[1] > 0.1 && v[0].abs() < 1e-9, "v {v:?}");
    assert!(q.state.position[1] > 0.03);
}

#[test]
fn motors_lag_with_their_time_constants() {
    let mut q = Quadrotor::new(CF, [0.0, 0.0, 0.0]);
    q.set_pwm([u16::MAX; 4]);
    q.step(CF.motor_tau_up);
    let top = CF.rotor_speed_command(u16::MAX);
    let up = q.state.rotor_speeds[0] / top;
    assert!((up - (1.0 - (-1.0f64).exp())).abs() < 0.01, "{up}");
    q.state.rotor_speeds = [top; 4];
    q.set_pwm([500; 4]);
    q.step(CF.motor_tau_down);
    let down = q.state.rotor_speeds[0] / top;
    assert!((down - (-1.0f64).exp()).abs() < 0.01, "{down}");
    assert_eq!(CF.rotor_speed_command(999), 0.0);
    assert_eq!(top, CF.max_rotor_speed);
}

#[test]
fn sensors_use_the_firmware_raw_units() {
    let q = Quadrotor::new(CF, [0.0, 0.0, 0.0]);
    assert_eq!(q.imu(None), ImuSample { accel: [0, 0, 2048], gyro: [0; 3] });
    assert_eq!(gyro_to_raw(1.0), 939);
    assert_eq!(gyro_to_raw(-100.0), i16::MIN);
    assert_eq!(accel_to_raw(100.0 * G, G), i16::MAX);
    assert_eq!(accel_to_raw(f64::NAN, G), 0);
    let ground = q.barometer();
    assert_eq!((ground.pressure, ground.altitude), (1013.25, 0.0));
    let drop = pressure_at_altitude(0.0) - pressure_at_altitude(10.0);
    assert!((drop - 1.2).abs() < 0.01, "{drop} mbar in 10 m");
}

#[test]
fn imu_noise_is_seeded_and_has_the_given_spread() {
    let q = Quadrotor::new(CF, [0.0, 0.0, 0.0]);
    let sample = |seed| {
        let mut noise = ImuNoise::bmi088(seed);
        (0..20_000).map(|_| q.imu(Some(&mut noise))).collect::<Vec<_>>()
    };
    let a = sample(5);
    assert_eq!(a, sample(5));
    assert_ne!(a, sample(6));
    let z: Vec<f64> = a.iter().map(|s| f64::from(s.accel[2])).collect();
    let mean = z.iter().sum::<f64>() / z.len() as f64;
    let std = (z.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / z.len() as f64).sqrt();
    let expected = 0.04 / (G * sensors::ACCEL_G_PER_LSB);
    assert!((mean - 2048.0).abs() < 0.5, "mean {mean}");
    assert!((std / expected - 1.0).abs() < 0.05, "std {std}, expected {expected}");
}
