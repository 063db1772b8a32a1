//! `f64` reference of the lag compensator (eq. 4.5), written independently of model-core:
//! the continuous transfer function `Kc p (s + z) / (s (s + p))` is mapped by Tustin's
//! substitution on its polynomial coefficients and run in direct form II transposed, in
//! `f64`, with no limits (tests compare inside the window). In `f64` the direct form is
//! accurate: the pole at `1 - 8e-6` is represented to 1e-11 relative.

/// Tustin-discretised second-order section `b(z)/a(z)` in `f64`.
#[derive(Clone, Debug)]
pub struct RefLag {
    b: [f64; 3],
    a: [f64; 3],
    s1: f64,
    s2: f64,
}

/// Bilinear map of `c2 s^2 + c1 s + c0` with `s = k (z - 1)/(z + 1)`, multiplied by
/// `(z + 1)^2`: coefficients of `z^2, z^1, z^0`.
fn bilinear2(c: [f64; 3], k: f64) -> [f64; 3] {
    let [c2, c1, c0] = c;
    [
        c2 * k * k + c1 * k + c0,
        -2.0 * c2 * k * k + 2.0 * c0,
        c2 * k * k - c1 * k + c0,
    ]
}

impl RefLag {
    /// The compensator `Kc (s + z)/(s (s/p + 1))` at period `t_s`, starting from output
    /// `u0_v` with zero error history.
    pub fn new(kc: f64, zero_rad_s: f64, pole_rad_s: f64, t_s: f64, u0_v: f64) -> Self {
        let k = 2.0 / t_s;
        let num = bilinear2([0.0, kc * pole_rad_s, kc * pole_rad_s * zero_rad_s], k);
        let den = bilinear2([1.0, pole_rad_s, 0.0], k);
        let a0 = den[0];
        let b = num.map(|v| v / a0);
        let a = den.map(|v| v / a0);
        // Rest at u0 with zero input: the DF2T states with x = 0, y = u0 are s2 = -a2 u0 and
        // s1 = -(a1 + a2) u0, which equals u0 because a(1) = 0 (the free integrator).
        let s2 = -a[2] * u0_v;
        let s1 = -a[1] * u0_v + s2;
        Self { b, a, s1, s2 }
    }

    /// One sample.
    pub fn step(&mut self, e_v: f64) -> f64 {
        let y = self.b[0] * e_v + self.s1;
        self.s1 = self.b[1] * e_v - self.a[1] * y + self.s2;
        self.s2 = self.b[2] * e_v - self.a[2] * y;
        y
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn holds_its_initial_output_and_integrates() {
        let mut r = RefLag::new(1e4, 1.0, 0.398, 20e-6, 5.0);
        for _ in 0..1000 {
            assert!((r.step(0.0) - 5.0).abs() < 1e-9);
        }
        // A constant 1e-4 V for 0.1 s. Tustin's trapezoid sees the step as if it came half a
        // sample late, so the continuous response to a step at T/2 is the reference:
        // u = u0 + Kc e (t + (p - z)/p (1 - e^{-p t})), t measured from T/2.
        let mut u = 0.0;
        for _ in 0..5000 {
            u = r.step(1e-4);
        }
        let t = 0.1 - 10e-6;
        let want = 5.0 + 1e-4 * 1e4 * (t + (0.398 - 1.0) / 0.398 * (1.0 - (-0.398f64 * t).exp()));
        assert!((u - want).abs() < 1e-6, "{u} vs {want}");
    }
}
