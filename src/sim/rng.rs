//! A small seedable random source (xorshift64*) for sensor noise and fault
//! dice: reproducible runs, and no dependency for a few random numbers.

/// Multiplier of xorshift64* (Vigna).
const MULTIPLIER: u64 = 0x2545_F491_4F6C_DD1D;
/// Replaces a zero seed, which xorshift cannot leave.
const NONZERO_SEED: u64 = 0x9E37_79B9_7F4A_7C15;

#[derive(Debug, Clone)]
pub(crate) struct Rng(u64);

impl Rng {
    pub(crate) fn new(seed: u64) -> Self {
        Self(if seed == 0 { NONZERO_SEED } else { seed })
    }

    pub(crate) fn next_u64(&mut self) -> u64 {
        let mut x = self.0;
        x ^= x >> 12;
        x ^= x << 25;
        x ^= x >> 27;
        self.0 = x;
        x.wrapping_mul(MULTIPLIER)
    }

    /// Uniform in `[0, 1)`.
    pub(crate) fn unit(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 / (1u64 << 53) as f64
    }

    /// Uniform in `[-amp, amp)`.
    pub(crate) fn noise(&mut self, amp: f64) -> f64 {
        (self.unit() * 2.0 - 1.0) * amp
    }

    /// Normally distributed with standard deviation `sigma` (Box–Muller).
    pub(crate) fn gauss(&mut self, sigma: f64) -> f64 {
        let u = 1.0 - self.unit();
        let v = self.unit();
        sigma * (-2.0 * u.ln()).sqrt() * (std::f64::consts::TAU * v).cos()
    }

    /// True with probability `p`.
    pub(crate) fn chance(&mut self, p: f64) -> bool {
        p > 0.0 && self.unit() < p
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn chance_follows_its_rate() {
        let mut r = Rng::new(1);
        let hits = (0..10_000).filter(|_| r.chance(0.25)).count();
        assert!((2_200..2_800).contains(&hits), "{hits}");
        assert!(!Rng::new(0).chance(0.0));
    }

    #[test]
    fn gauss_has_its_standard_deviation() {
        let mut r = Rng::new(7);
        let xs: Vec<f64> = (0..20_000).map(|_| r.gauss(0.5)).collect();
        let mean = xs.iter().sum::<f64>() / xs.len() as f64;
        let var = xs.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / xs.len() as f64;
        assert!(mean.abs() < 0.02, "{mean}");
        assert!((var.sqrt() - 0.5).abs() < 0.02, "{}", var.sqrt());
    }
}
