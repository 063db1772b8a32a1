//! Ground-truth hysteresis of another family than model-core's Everett table: a generalised
//! Prandtl-Ishlinskii model in `f64`, so that the table is tested as an *approximation*.
//!
//! ```text
//!   z_i[n] = min(max(z_i[n-1], u - r_i), u + r_i)          play operator, threshold r_i
//!   v      = g0 (u - u_min) + sum_i w_i (z_i - u_min - r_i) (0 at the bottom of the range)
//!   y      = c1 v + c2 v^2                                  static output map
//! ```
//!
//! Seven play operators (thresholds 0.25..3.6 V, weights `0.17 e^(-r/2)`), a reversible part
//! `g0 = 0.33`, and an output map that bends the curve upwards by 6 % of the span (the fast
//! gain grows with amplitude, sec. 3.1). With the map, minor loops at different offsets are no
//! longer congruent, so the truth is *not* a Preisach model and no Everett table reproduces it
//! exactly: higher-order reversals carry a genuine model error. Loop: output span 7.9 V for
//! 0..10 V (0.79 V/V, eq. 4.4), largest vertical width about 15 % of the span (sec. 3.2). Rate
//! independent by construction (play operators depend on the input path only).

/// The generalised Prandtl-Ishlinskii truth with its state.
#[derive(Clone, Debug)]
pub struct PlayOperatorTruth {
    u_min: f64,
    g0: f64,
    thresholds: Vec<f64>,
    weights: Vec<f64>,
    c1: f64,
    c2: f64,
    z: Vec<f64>,
}

impl PlayOperatorTruth {
    /// The stage-like truth described in the module note, over 0..10 V, at the bottom.
    pub fn thesis_like() -> Self {
        let thresholds: Vec<f64> = vec![0.25, 0.6, 1.0, 1.5, 2.1, 2.8, 3.6];
        let weights: Vec<f64> = thresholds
            .iter()
            .map(|r: &f64| 0.17 * (-r / 2.0).exp())
            .collect();
        let g0 = 0.33;
        let range: f64 = 10.0;
        // v over the full major loop.
        let v_span = g0 * range
            + thresholds
                .iter()
                .zip(&weights)
                .map(|(r, w)| w * (range - 2.0 * r).max(0.0))
                .sum::<f64>();
        let span = 7.9;
        let bow = 0.06 * span;
        let c2 = bow / (v_span * v_span);
        let c1 = (span - bow) / v_span;
        Self::new(0.0, g0, thresholds, weights, c1, c2)
    }

    /// A truth from its parameters, at the bottom `u_min` (as after coming down to it).
    pub fn new(
        u_min: f64,
        g0: f64,
        thresholds: Vec<f64>,
        weights: Vec<f64>,
        c1: f64,
        c2: f64,
    ) -> Self {
        let mut t = Self {
            u_min,
            g0,
            z: vec![0.0; thresholds.len()],
            thresholds,
            weights,
            c1,
            c2,
        };
        t.reset_bottom();
        t
    }

    /// Come down to the bottom of the range: every play operator at its lower position.
    pub fn reset_bottom(&mut self) {
        for (z, r) in self.z.iter_mut().zip(&self.thresholds) {
            *z = self.u_min + r;
        }
    }

    /// Come to rest at `u0` after a scan that died away there: every play operator centred on
    /// it (the Preisach plane's anti-diagonal through `u0`, not on the major curve).
    pub fn centre_on(&mut self, u0: f64) {
        self.z.iter_mut().for_each(|z| *z = u0);
    }

    /// Apply input `u` (volts) and return the output (sensor volts).
    pub fn step(&mut self, u: f64) -> f64 {
        let mut v = self.g0 * (u - self.u_min);
        for ((z, r), w) in self.z.iter_mut().zip(&self.thresholds).zip(&self.weights) {
            *z = z.max(u - r).min(u + r);
            v += w * (*z - self.u_min - r);
        }
        self.c1 * v + self.c2 * v * v
    }

    /// Outputs for a whole input record, continuing from the present state.
    pub fn run(&mut self, u: &[f64]) -> Vec<f64> {
        u.iter().map(|&x| self.step(x)).collect()
    }
}
