//! The world's random generators: xoshiro256++ seeded through SplitMix64, with a ziggurat
//! Gaussian, and counter-style streams derived from (seed, robot, tick, purpose).
//!
//! Written here rather than taken from a crate so that the stream for a seed can never change
//! under us with a dependency update: lock-step runs with one seed must stay bit-identical.
//! The ziggurat matters for speed: a 10,000-robot tick draws ~140,000 Gaussians.
//!
//! Each robot draws from its own stream for each tick and purpose ([`Rng::stream`]), never
//! from one shared generator: which robot is stepped first, on which thread, or whether other
//! robots exist at all cannot change a single draw, so a run is the same on any thread count.

use std::sync::OnceLock;

/// A seeded pseudo-random generator (xoshiro256++).
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct Rng {
    s: [u64; 4],
}

fn splitmix64(state: &mut u64) -> u64 {
    *state = state.wrapping_add(0x9E37_79B9_7F4A_7C15);
    let mut z = *state;
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

/// What a stream's draws are for: each purpose has its own stream, so turning one noise off
/// leaves every other draw of the run as it was.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
#[repr(u64)]
pub enum Draw {
    /// Motor output noise (drive phase).
    Motor = 1,
    /// Encoder slip (commit phase).
    Slip = 2,
    /// Sensor noise: proximity, compass, GPS, beacons (sense phase).
    Sense = 3,
}

/// SplitMix64's finaliser: a bijective mix in which every input bit moves every output bit.
#[inline]
fn mix64(mut z: u64) -> u64 {
    z = (z ^ (z >> 30)).wrapping_mul(0xBF58_476D_1CE4_E5B9);
    z = (z ^ (z >> 27)).wrapping_mul(0x94D0_49BB_1331_11EB);
    z ^ (z >> 31)
}

impl Rng {
    /// The generator for one robot's draws of one purpose in one tick: a function of its four
    /// inputs only (counter-style), so draws never depend on the order robots are visited in.
    /// `robot` is any key that names the robot for the run (the world uses its slot and the
    /// slot's generation).
    #[inline]
    pub fn stream(seed: u64, robot: u64, tick: u64, purpose: Draw) -> Self {
        // Chained mixes, each with an odd constant between, so (seed, robot, tick, purpose)
        // tuples that differ anywhere give unrelated 64-bit keys.
        let k = mix64(seed ^ 0x6A09_E667_F3BC_C909);
        let k = mix64(k ^ robot.wrapping_mul(0x9E37_79B9_7F4A_7C15));
        let k = mix64(k ^ tick.wrapping_mul(0xD1B5_4A32_D192_ED03));
        Self::seed_from_u64(k ^ (purpose as u64).wrapping_mul(0xAEF1_7502_108E_F2D9))
    }

    /// A generator whose whole stream is fixed by `seed`.
    pub fn seed_from_u64(seed: u64) -> Self {
        let mut sm = seed;
        let s = [splitmix64(&mut sm), splitmix64(&mut sm), splitmix64(&mut sm), splitmix64(&mut sm)];
        Self { s }
    }

    /// The generator's internal state (for state hashes).
    pub fn state(&self) -> [u64; 4] {
        self.s
    }

    /// The next 64 random bits.
    #[inline]
    pub fn next_u64(&mut self) -> u64 {
        let s = &mut self.s;
        let result = s[0].wrapping_add(s[3]).rotate_left(23).wrapping_add(s[0]);
        let t = s[1] << 17;
        s[2] ^= s[0];
        s[3] ^= s[1];
        s[1] ^= s[2];
        s[0] ^= s[3];
        s[2] ^= t;
        s[3] = s[3].rotate_left(45);
        result
    }

    /// Uniform in [0, 1) with 53 bits of precision.
    #[inline]
    pub fn next_f64(&mut self) -> f64 {
        (self.next_u64() >> 11) as f64 * (1.0 / (1u64 << 53) as f64)
    }

    /// Uniform in [lo, hi).
    #[inline]
    pub fn uniform(&mut self, lo: f64, hi: f64) -> f64 {
        lo + (hi - lo) * self.next_f64()
    }

    /// A standard normal deviate (mean 0, standard deviation 1).
    #[inline]
    pub fn gaussian(&mut self) -> f64 {
        let t = tables();
        let bits = self.next_u64();
        let hz = bits as i32;
        let iz = (bits >> 32) as usize & 127;
        if hz.unsigned_abs() < t.k[iz] {
            return hz as f64 * t.w[iz];
        }
        self.gaussian_slow(hz, iz)
    }

    /// Adds N(0, σ²) to `x`; with σ = 0 it draws nothing, so switching a noise off also removes
    /// its draws from the stream.
    #[inline]
    pub fn noisy(&mut self, x: f64, sigma: f64) -> f64 {
        if sigma > 0.0 { x + sigma * self.gaussian() } else { x }
    }

    #[cold]
    fn gaussian_slow(&mut self, mut hz: i32, mut iz: usize) -> f64 {
        let t = tables();
        loop {
            let x = hz as f64 * t.w[iz];
            if iz == 0 {
                // The base strip: sample the tail beyond R (Marsaglia's method).
                loop {
                    let x = -(1.0 - self.next_f64()).ln() / ZIG_R;
                    let y = -(1.0 - self.next_f64()).ln();
                    if y + y >= x * x {
                        return if hz > 0 { ZIG_R + x } else { -ZIG_R - x };
                    }
                }
            }
            if t.f[iz] + self.next_f64() * (t.f[iz - 1] - t.f[iz]) < (-0.5 * x * x).exp() {
                return x;
            }
            let bits = self.next_u64();
            hz = bits as i32;
            iz = (bits >> 32) as usize & 127;
            if hz.unsigned_abs() < t.k[iz] {
                return hz as f64 * t.w[iz];
            }
        }
    }
}

const ZIG_R: f64 = 3.442_619_855_899;
const ZIG_V: f64 = 9.912_563_035_262_17e-3;

struct Tables {
    k: [u32; 128],
    w: [f64; 128],
    f: [f64; 128],
}

/// The 128-strip ziggurat tables of Marsaglia & Tsang (2000), built once.
fn tables() -> &'static Tables {
    static T: OnceLock<Tables> = OnceLock::new();
    T.get_or_init(|| {
        let m1 = 2_147_483_648.0f64;
        let mut k = [0u32; 128];
        let mut w = [0f64; 128];
        let mut f = [0f64; 128];
        let mut dn = ZIG_R;
        let mut tn = dn;
        let q = ZIG_V / (-0.5 * dn * dn).exp();
        k[0] = ((dn / q) * m1) as u32;
        k[1] = 0;
        w[0] = q / m1;
        w[127] = dn / m1;
        f[0] = 1.0;
        f[127] = (-0.5 * dn * dn).exp();
        for i in (1..=126).rev() {
            dn = (-2.0 * (ZIG_V / dn + (-0.5 * dn * dn).exp()).ln()).sqrt();
            k[i + 1] = ((dn / tn) * m1) as u32;
            tn = dn;
            f[i] = (-0.5 * dn * dn).exp();
            w[i] = dn / m1;
        }
        Tables { k, w, f }
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn one_seed_gives_one_stream_and_another_seed_another() {
        let mut a = Rng::seed_from_u64(42);
        let mut b = Rng::seed_from_u64(42);
        let mut c = Rng::seed_from_u64(43);
        let xa: Vec<u64> = (0..8).map(|_| a.next_u64()).collect();
        let xb: Vec<u64> = (0..8).map(|_| b.next_u64()).collect();
        let xc: Vec<u64> = (0..8).map(|_| c.next_u64()).collect();
        assert_eq!(xa, xb);
        assert_ne!(xa, xc);
    }

    #[test]
    fn a_stream_is_fixed_by_its_four_keys_and_changes_with_each() {
        let first = |seed, robot, tick, purpose| Rng::stream(seed, robot, tick, purpose).next_u64();
        let base = first(7, 3 << 32, 100, Draw::Sense);
        assert_eq!(base, first(7, 3 << 32, 100, Draw::Sense));
        for other in [
            first(8, 3 << 32, 100, Draw::Sense),
            first(7, 4 << 32, 100, Draw::Sense),
            first(7, (3 << 32) | 1, 100, Draw::Sense),
            first(7, 3 << 32, 101, Draw::Sense),
            first(7, 3 << 32, 100, Draw::Motor),
            first(7, 3 << 32, 100, Draw::Slip),
        ] {
            assert_ne!(base, other);
        }
    }

    #[test]
    fn neighbouring_robots_and_ticks_draw_uncorrelated_noise() {
        // The keys of adjacent slots and ticks differ in a bit or two: their Gaussians must
        // still be independent, or two chairs side by side would share their noise.
        let n = 20_000u64;
        let corr = |pairs: &mut dyn Iterator<Item = (f64, f64)>| {
            let (mut sxy, mut sxx, mut syy) = (0.0, 0.0, 0.0);
            for (x, y) in pairs {
                sxy += x * y;
                sxx += x * x;
                syy += y * y;
            }
            sxy / (sxx * syy).sqrt()
        };
        let by_robot = corr(&mut (0..n).map(|i| {
            (
                Rng::stream(1, i << 32, 5, Draw::Sense).gaussian(),
                Rng::stream(1, (i + 1) << 32, 5, Draw::Sense).gaussian(),
            )
        }));
        let by_tick = corr(&mut (0..n).map(|t| {
            (Rng::stream(1, 9 << 32, t, Draw::Motor).gaussian(), Rng::stream(1, 9 << 32, t + 1, Draw::Motor).gaussian())
        }));
        // 4 standard errors of a correlation over 20,000 pairs is 0.028.
        assert!(by_robot.abs() < 0.028, "adjacent robots correlate {by_robot}");
        assert!(by_tick.abs() < 0.028, "adjacent ticks correlate {by_tick}");
        let mut all = (0..n).map(|i| Rng::stream(3, i << 32, i, Draw::Slip).gaussian());
        let (mut s, mut s2) = (0.0, 0.0);
        for g in &mut all {
            s += g;
            s2 += g * g;
        }
        let (mean, var) = (s / n as f64, s2 / n as f64 - (s / n as f64).powi(2));
        assert!(mean.abs() < 0.03 && (var - 1.0).abs() < 0.04, "first draws: mean {mean}, variance {var}");
    }

    #[test]
    fn gaussian_has_unit_variance_and_normal_tails() {
        let mut r = Rng::seed_from_u64(1);
        let n = 400_000;
        let (mut sum, mut sum2, mut beyond2, mut beyond3) = (0.0, 0.0, 0usize, 0usize);
        for _ in 0..n {
            let g = r.gaussian();
            sum += g;
            sum2 += g * g;
            if g.abs() > 2.0 {
                beyond2 += 1;
            }
            if g.abs() > 3.0 {
                beyond3 += 1;
            }
        }
        let mean = sum / n as f64;
        let var = sum2 / n as f64 - mean * mean;
        assert!(mean.abs() < 0.01, "mean {mean}");
        assert!((var - 1.0).abs() < 0.01, "variance {var}");
        // P(|Z| > 2) = 4.55 %, P(|Z| > 3) = 0.27 %.
        let p2 = beyond2 as f64 / n as f64;
        let p3 = beyond3 as f64 / n as f64;
        assert!((p2 - 0.0455).abs() < 0.002, "P(|Z|>2) = {p2}");
        assert!((p3 - 0.0027).abs() < 0.0005, "P(|Z|>3) = {p3}");
    }

    #[test]
    fn uniform_stays_in_range() {
        let mut r = Rng::seed_from_u64(9);
        for _ in 0..10_000 {
            let u = r.uniform(-2.0, 3.0);
            assert!((-2.0..3.0).contains(&u));
        }
    }
}
