//! Discrete PID controller with output limits and tracking anti-windup for selector structures.

/// A discrete PID controller `u = kp e + I + kd (e - e_prev) / dt` (backward-Euler integral).
///
/// Anti-windup by tracking: after the selectors and saturations have chosen the applied command,
/// [`Pid::commit`] resets the integral so that this controller's output equals the applied
/// command whenever it did not give it (a controller that lost a min/max selection, or was
/// saturated). Its next output is then the applied command plus its own increment
/// `kp (e_k - e_{k-1}) + ki dt e_k` (the velocity form), so a selector switches between loops
/// without bumps and no integral winds up.
///
/// Gain scheduling: [`Pid::set_scale`] multiplies kp, ki and kd by a factor g; the integral is
/// corrected so that the next output is the previous one plus the scaled increment
/// `g (kp (e_k - e_{k-1}) + ki dt e_k)` (bumpless for a PI; kd is not compensated).
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Pid {
    /// Proportional gain [command unit per error unit].
    pub kp: f64,
    /// Integral gain [command unit per error unit and second].
    pub ki: f64,
    /// Derivative gain [command unit per error unit per (1/s)].
    pub kd: f64,
    /// Integral state [command unit].
    pub integral: f64,
    e_prev: f64,
    /// Gain factor g of the schedule [-] (1: the gains as given).
    scale: f64,
}

impl Pid {
    /// A PID with zero integral.
    pub fn new(kp: f64, ki: f64, kd: f64) -> Self {
        Self {
            kp,
            ki,
            kd,
            integral: 0.0,
            e_prev: f64::NAN,
            scale: 1.0,
        }
    }

    /// Schedule the gains: from now on the controller acts with `g kp`, `g ki`, `g kd`. The
    /// integral takes the change of the proportional part at the previous error, so the output
    /// does not jump when g changes (the velocity form with the new gains). A factor equal to
    /// the current one changes nothing.
    pub fn set_scale(&mut self, g: f64) {
        if g == self.scale {
            return;
        }
        if !self.e_prev.is_nan() {
            self.integral += (self.scale - g) * self.kp * self.e_prev;
        }
        self.scale = g;
    }

    /// The current gain factor g [-].
    pub fn scale(&self) -> f64 {
        self.scale
    }

    /// Start bumplessly at the command `u` (integral = u, no derivative kick).
    pub fn reset(&mut self, u: f64) {
        self.integral = u;
        self.e_prev = f64::NAN;
    }

    /// The output for error `e` at sample time `dt` (does not change the state).
    pub fn output(&self, e: f64, dt: f64) -> f64 {
        let de = if self.e_prev.is_nan() {
            0.0
        } else {
            e - self.e_prev
        };
        let g = self.scale;
        self.integral + g * self.ki * dt * e + g * self.kp * e + g * self.kd * de / dt
    }

    /// Accept the sample: integrate, then track the `applied` command if it differs from this
    /// controller's `output(e, dt)`.
    pub fn commit(&mut self, e: f64, dt: f64, applied: f64) {
        let own = self.output(e, dt);
        self.integral += self.scale * self.ki * dt * e;
        if (own - applied).abs() > 1e-12 * applied.abs().max(1.0) {
            self.integral += applied - own;
        }
        self.e_prev = e;
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pi_drives_a_first_order_plant_to_the_set_point() {
        // y' = (K u - y)/T, K = 2, T = 0.5 s, sampled at 10 ms
        let (k, tau, dt) = (2.0, 0.5, 0.01);
        let mut c = Pid::new(0.5, 1.0, 0.0);
        let mut y = 0.0;
        for _ in 0..1000 {
            let e = 1.0 - y;
            let u = c.output(e, dt).clamp(-10.0, 10.0);
            c.commit(e, dt, u);
            y += dt * (k * u - y) / tau;
        }
        assert!((y - 1.0).abs() < 1e-6, "y = {y}");
        assert!((c.integral - 0.5).abs() < 1e-4);
    }

    #[test]
    fn tracking_prevents_windup() {
        let dt = 0.01;
        let mut c = Pid::new(1.0, 10.0, 0.0);
        // saturated at 1 for 10 s with a persistent error
        for _ in 0..1000 {
            let u = c.output(5.0, dt).min(1.0);
            c.commit(5.0, dt, u);
        }
        // the next output is the applied command plus the increment kp (e_k - e_{k-1}) + ki dt e_k:
        // no integral wound up over the 10 s to unwind
        let u = c.output(-0.1, dt);
        let expected = 1.0 + 1.0 * (-0.1 - 5.0) + 10.0 * dt * -0.1;
        assert!((u - expected).abs() < 1e-12, "u = {u}, expected {expected}");
    }

    /// A new gain factor does not move the output at an unchanged error, and the increments
    /// after it are the scaled ones; factor 1 is the unscheduled controller to the bit.
    #[test]
    fn scheduled_gains_are_bumpless() {
        let dt = 0.01;
        let mut c = Pid::new(2.0, 5.0, 0.0);
        c.reset(40.0);
        let u1 = c.output(0.3, dt);
        c.commit(0.3, dt, u1);
        // at the same error, the output moves by the integral increment only, before and after
        let same = c.output(0.3, dt) - u1;
        c.set_scale(0.25);
        let scaled = c.output(0.3, dt) - u1;
        assert!((same - 5.0 * dt * 0.3).abs() < 1e-12, "{same}");
        assert!((scaled - 0.25 * 5.0 * dt * 0.3).abs() < 1e-12, "{scaled}");
        // a step of the error moves it by g (kp de + ki dt e)
        let u2 = c.output(0.3, dt);
        c.commit(0.3, dt, u2);
        let d = c.output(0.5, dt) - u2;
        let expected = 0.25 * (2.0 * 0.2 + 5.0 * dt * 0.5);
        assert!((d - expected).abs() < 1e-12, "{d} against {expected}");
        // factor 1 again: the unscheduled increments
        let mut a = Pid::new(2.0, 5.0, 0.0);
        let mut b = a;
        b.set_scale(1.0);
        for e in [0.1, -0.2, 0.05] {
            let (ua, ub) = (a.output(e, dt), b.output(e, dt));
            assert_eq!(ua.to_bits(), ub.to_bits());
            a.commit(e, dt, ua);
            b.commit(e, dt, ub);
        }
    }
}
