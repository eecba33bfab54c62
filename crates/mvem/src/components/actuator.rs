//! Actuator position responses to piecewise-constant command sequences (sections 5.2, 6.2.3):
//! the closed-form responses of the linear actuator models (eqs (39)-(41), (57)) to the
//! commands after the model's command saturation (authors' implementation, items 3-4). Used by
//! the actuator fit (tuning step 2), the actuator validation and the virtual test cell, so all
//! three see the commands the model sees.

/// Saturation range (lo, hi) [%] applied to a command before the actuator (infinite: none).
pub type Saturation = (f64, f64);

/// Steps of a sampled command after the saturation `sat`: (time of the first sample at the new
/// level \[s\], size of the saturated step [%]). Changes that the saturation hides (e.g. 15 -> 10 %
/// with VGT limited to [20, 100] %) give no step.
pub fn command_steps(t: &[f64], u: &[f64], sat: Saturation) -> Vec<(f64, f64)> {
    let c = |v: f64| v.clamp(sat.0, sat.1);
    (1..u.len().min(t.len()))
        .filter(|&i| c(u[i]) != c(u[i - 1]))
        .map(|i| (t[i], c(u[i]) - c(u[i - 1])))
        .collect()
}

/// Actuator position at the times `t` \[s\] for the command samples `u` [%] (held between
/// samples, settled at the saturated `u[0]` before `t[0]`): the saturated initial level plus the
/// sum of the unit step responses `h(s)` (s seconds after a step) of the saturated command
/// steps. Exact for linear actuator models (superposition).
pub fn position(t: &[f64], u: &[f64], sat: Saturation, h: impl Fn(f64) -> f64) -> Vec<f64> {
    let steps = command_steps(t, u, sat);
    let u0 = u.first().map_or(0.0, |v| v.clamp(sat.0, sat.1));
    positions_of_steps(t, u0, &steps, h)
}

/// Position at the times `t` for the initial level `u0` and the (already saturated) command
/// steps `steps` (see [`position`]).
pub fn positions_of_steps(
    t: &[f64],
    u0: f64,
    steps: &[(f64, f64)],
    h: impl Fn(f64) -> f64,
) -> Vec<f64> {
    t.iter()
        .map(|&tt| {
            u0 + steps
                .iter()
                .filter(|(ts, _)| *ts <= tt)
                .map(|(ts, d)| d * h(tt - ts))
                .sum::<f64>()
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::components::{egr, turbine};
    use crate::params::Params;

    #[test]
    fn saturated_steps_and_superposition() {
        let t: Vec<f64> = (0..6).map(|i| i as f64).collect();
        let u = [100.0, 50.0, 10.0, 15.0, 30.0, 30.0];
        // VGT range [20, 100]: 10 and 15 both read 20, the 10 -> 15 change is no step
        let s = command_steps(&t, &u, (20.0, 100.0));
        assert_eq!(s, vec![(1.0, -50.0), (2.0, -30.0), (4.0, 10.0)]);
        // instantaneous actuator: the position is the saturated command
        let x = position(&t, &u, (20.0, 100.0), |_| 1.0);
        assert_eq!(x, vec![100.0, 50.0, 20.0, 20.0, 30.0, 30.0]);
    }

    #[test]
    fn step_responses_by_hand() {
        let p = Params::published();
        let v = &p.vgt_actuator; // tau 25 ms, delay 40 ms
        assert_eq!(turbine::actuator_step_response(v, 0.04), 0.0);
        let r = turbine::actuator_step_response(v, 0.065);
        assert!((r - (1.0 - (-1.0f64).exp())).abs() < 1e-12, "{r}");
        let e = &p.egr_actuator; // K 1.8, tau 50/130 ms, delay 65 ms
        assert_eq!(egr::actuator_step_response(e, 0.065), 0.0);
        // settles at 1; overshoots (K > 1) on the way
        assert!((egr::actuator_step_response(e, 10.0) - 1.0).abs() < 1e-12);
        let peak = (1..200)
            .map(|k| egr::actuator_step_response(e, 0.065 + k as f64 * 0.005))
            .fold(0.0, f64::max);
        assert!(peak > 1.05, "{peak}");
    }
}
