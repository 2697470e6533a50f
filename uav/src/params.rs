//! Scenario parameters with the paper's symbols and the documented defaults.

use serde::{Deserialize, Serialize};

/// Parameters shared by the filter, navigation and simulator. JSON keys are the paper's symbols;
/// unknown keys are rejected.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize, schemars::JsonSchema)]
#[serde(deny_unknown_fields, default)]
#[schemars(transform = state_ranges)]
pub struct Params {
    /// Control period dt (s), 0.001 to 0.1 ([`MIN_DT_S`], [`MAX_DT_S`]). Default 0.05 (20 Hz).
    pub dt: f64,
    /// Input bound δ: ‖u‖ ≤ δ (m/s²). Default 5.
    pub delta: f64,
    /// Radius r_s of the temporary target around the UAV (m), Algorithm 1. Default 5.
    pub r_s: f64,
    /// Safe distance D_s to a road wall (m). Default 0.1.
    #[serde(rename = "D_s")]
    pub d_s: f64,
    /// Safe distance D_c between two UAVs (m). Default 0.3.
    #[serde(rename = "D_c")]
    pub d_c: f64,
    /// Class-K gain ζ of α(b) = ζ b³ (s/m²). Default 0.05.
    pub zeta: f64,
    /// Arrival tolerance ε: a UAV has arrived when ‖p − p_g‖ ≤ ε (m). Default 0.1.
    pub epsilon: f64,
    /// Simulated time limit of a headless run (s). Default 120.
    pub t_max: f64,
    /// Model-error allowance η_p (m): how much closer than it reads a UAV may truly be to a wall
    /// (twice to another UAV), docs/safety.md §12. Default 0: the simulated double integrator is
    /// exact; real quadrotors need it (docs/crazyflies.md).
    pub eta_p: f64,
    /// Model-error allowance η_v (m/s): how much faster than the double integrator predicts a UAV
    /// may truly close in while it brakes (lag, estimate, gusts), docs/safety.md §12. Default 0.
    pub eta_v: f64,
}

impl Default for Params {
    fn default() -> Self {
        Self {
            dt: 0.05,
            delta: 5.0,
            r_s: 5.0,
            d_s: 0.1,
            d_c: 0.3,
            zeta: 0.05,
            epsilon: 0.1,
            t_max: 120.0,
            eta_p: 0.0,
            eta_v: 0.0,
        }
    }
}

/// Largest control period dt (s): 10 Hz. An emergency stop or a land request waits for the next
/// tick, so a longer period would leave the fleet unattended for too long.
pub const MAX_DT_S: f64 = 0.1;
/// Smallest control period dt (s): 1 kHz, beyond what the fleet loop (QPs, policies) can keep up.
pub const MIN_DT_S: f64 = 1e-3;

/// A parameter outside its valid range, e.g.
/// `params.dt: is outside its valid range 0.001..=0.1 (got 1)`.
#[derive(Debug, Clone, PartialEq, thiserror::Error)]
#[error("params.{field}: {}", self.detail())]
pub struct ParamError {
    /// JSON key of the offending parameter.
    pub field: &'static str,
    /// What is wrong with it.
    pub reason: &'static str,
    /// The rejected value.
    pub value: f64,
    /// Smallest valid value.
    pub min: f64,
    /// Largest valid value.
    pub max: f64,
}

impl ParamError {
    /// The message without the `params.FIELD: ` prefix: the reason, the valid range and the value.
    pub fn detail(&self) -> String {
        format!("{} {}..={} (got {})", self.reason, self.min, self.max, self.value)
    }
}

/// The valid range of one parameter: `min..=max`, or `min < value <= max` when `above_min`.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct ParamRange {
    /// Its JSON key.
    pub key: &'static str,
    /// Smallest valid value (excluded when `above_min`).
    pub min: f64,
    /// Largest valid value.
    pub max: f64,
    /// The value must be more than `min`.
    pub above_min: bool,
}

const fn range(key: &'static str, min: f64, max: f64) -> ParamRange {
    ParamRange { key, min, max, above_min: false }
}

/// Every parameter's valid range, in [`Params::values`]' order: [`Params::validate`] checks them
/// and the JSON schema states them.
pub const PARAM_RANGES: [ParamRange; 10] = [
    range("dt", MIN_DT_S, MAX_DT_S),
    range("delta", 1e-3, 100.0),
    range("r_s", 1e-2, 1e3),
    ParamRange { key: "D_s", min: 0.0, max: 100.0, above_min: true },
    range("D_c", 1e-3, 100.0),
    range("zeta", 0.0, 1e3),
    range("epsilon", 1e-4, 100.0),
    range("t_max", 1e-3, 1e6),
    range("eta_p", 0.0, 1.0),
    range("eta_v", 0.0, 10.0),
];

/// Adds [`PARAM_RANGES`] to the derived schema of [`Params`].
fn state_ranges(schema: &mut schemars::Schema) {
    let Some(properties) = schema.get_mut("properties").and_then(|p| p.as_object_mut()) else { return };
    for r in PARAM_RANGES {
        let Some(property) = properties.get_mut(r.key).and_then(|p| p.as_object_mut()) else { continue };
        let low = if r.above_min { "exclusiveMinimum" } else { "minimum" };
        property.insert(low.into(), r.min.into());
        property.insert("maximum".into(), r.max.into());
    }
}

impl Params {
    /// The parameters' values in [`PARAM_RANGES`]' order.
    pub fn values(&self) -> [f64; 10] {
        [
            self.dt,
            self.delta,
            self.r_s,
            self.d_s,
            self.d_c,
            self.zeta,
            self.epsilon,
            self.t_max,
            self.eta_p,
            self.eta_v,
        ]
    }

    /// Checks that every parameter is finite and within a physically meaningful range.
    pub fn validate(&self) -> Result<(), ParamError> {
        for (ParamRange { key: field, min, max, .. }, value) in PARAM_RANGES.into_iter().zip(self.values()) {
            if !value.is_finite() {
                return Err(ParamError { field, reason: "must be a finite number within", value, min, max });
            }
            if value < min || value > max {
                return Err(ParamError { field, reason: "is outside its valid range", value, min, max });
            }
        }
        for (ParamRange { key: field, min, max, above_min }, value) in
            PARAM_RANGES.into_iter().zip(self.values())
        {
            if above_min && value == min {
                return Err(ParamError { field, reason: "must be positive, within", value, min, max });
            }
        }
        Ok(())
    }

    /// The distance (m) the filter keeps between two UAVs at rest: D_c with both UAVs' model-error
    /// allowances, D_c + 2η_p + (2η_v)²/(2·2δ) (docs/safety.md §12); D_c when they are 0. The
    /// traffic rules space UAVs by it.
    pub fn kept_d_c(&self) -> f64 {
        self.d_c + 2.0 * self.eta_p + self.eta_v * self.eta_v / self.delta
    }

    /// The distance (m) the filter keeps from a wall at rest: D_s + η_p + η_v²/(2δ) (docs/safety.md
    /// §12); D_s when the allowances are 0.
    pub fn kept_d_s(&self) -> f64 {
        self.d_s + self.eta_p + self.eta_v * self.eta_v / (2.0 * self.delta)
    }

    /// Number of control ticks in `t_max`.
    pub fn max_ticks(&self) -> u64 {
        (self.t_max / self.dt).ceil() as u64
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_and_partial_json() {
        let p: Params = serde_json::from_str(r#"{"D_c": 0.5, "t_max": 30}"#).unwrap();
        assert_eq!(p.d_c, 0.5);
        assert_eq!(p.t_max, 30.0);
        assert_eq!(p.delta, 5.0);
        assert!(p.validate().is_ok());
    }

    #[test]
    fn unknown_key_is_named() {
        let err = serde_json::from_str::<Params>(r#"{"Dc": 0.5}"#).unwrap_err().to_string();
        assert!(err.contains("unknown field `Dc`"), "{err}");
    }

    #[test]
    fn out_of_range_is_named() {
        let p = Params { delta: -1.0, ..Params::default() };
        assert_eq!(p.validate().unwrap_err().field, "delta");
        let p = Params { zeta: f64::NAN, ..Params::default() };
        assert_eq!(p.validate().unwrap_err().field, "zeta");
        let p = Params { d_s: 0.0, ..Params::default() };
        assert_eq!(
            p.validate().unwrap_err().to_string(),
            "params.D_s: must be positive, within 0..=100 (got 0)"
        );
    }

    #[test]
    fn allowances_default_to_zero_and_are_checked() {
        let p: Params = serde_json::from_str(r#"{"eta_p": 0.07, "eta_v": 0.5}"#).unwrap();
        assert_eq!((p.eta_p, p.eta_v), (0.07, 0.5));
        assert_eq!((Params::default().eta_p, Params::default().eta_v), (0.0, 0.0));
        assert_eq!((Params::default().kept_d_c(), Params::default().kept_d_s()), (0.3, 0.1));
        let kept = (p.kept_d_c(), p.kept_d_s());
        assert!(
            (kept.0 - (0.3 + 0.14 + 0.05)).abs() < 1e-12 && (kept.1 - (0.1 + 0.07 + 0.025)).abs() < 1e-12
        );
        let e = Params { eta_p: -0.01, ..Params::default() }.validate().unwrap_err();
        assert_eq!(e.to_string(), "params.eta_p: is outside its valid range 0..=1 (got -0.01)");
        let e = Params { eta_v: f64::NAN, ..Params::default() }.validate().unwrap_err();
        assert_eq!(e.field, "eta_v");
    }

    #[test]
    fn dt_is_at_most_a_tenth_of_a_second() {
        for dt in [MIN_DT_S, 0.01, 0.05, MAX_DT_S] {
            assert_eq!(Params { dt, ..Params::default() }.validate(), Ok(()), "dt = {dt}");
        }
        for dt in [1.0, 0.1000001, 0.5, 1e-4, 0.0, -0.05] {
            let e = Params { dt, ..Params::default() }.validate().unwrap_err();
            assert_eq!(e.field, "dt");
            assert_eq!(
                e.to_string(),
                format!("params.dt: is outside its valid range 0.001..=0.1 (got {dt})")
            );
        }
        let e = Params { dt: f64::INFINITY, ..Params::default() }.validate().unwrap_err();
        assert_eq!(e.to_string(), "params.dt: must be a finite number within 0.001..=0.1 (got inf)");
    }
}
