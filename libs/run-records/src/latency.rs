//! Latency percentiles, as agents report them (`--report-latency`) and `iwsim bench` reads them.
//!
//! ```
//! use run_records::latency::Percentiles;
//!
//! let p = Percentiles::of_ns(&[1_000, 2_000, 3_000]);
//! assert_eq!(p.p50_us, 2.0);
//! let stdout = format!("wheelchair: done\n{}\n", p.json());
//! assert_eq!(Percentiles::parse(&stdout)?, p);
//! # Ok::<(), run_records::latency::PercentilesReadError>(())
//! ```

use serde::{Deserialize, Serialize};

/// Latency percentiles in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default, Serialize, Deserialize)]
pub struct Percentiles {
    /// Samples.
    pub samples: usize,
    /// Median, µs.
    pub p50_us: f64,
    /// 99th percentile, µs.
    pub p99_us: f64,
    /// 99.9th percentile, µs.
    pub p999_us: f64,
}

/// Why a process's output gave no percentiles.
#[derive(Debug, thiserror::Error)]
pub enum PercentilesReadError {
    /// No line is a JSON object with `p50_us`.
    #[error("no latency percentiles line (a JSON object with \"p50_us\")")]
    NoLine,
    /// The last such line is not what [`Percentiles::json`] writes.
    #[error("the latency percentiles line is not what --report-latency prints: {0}")]
    Json(#[from] serde_json::Error),
}

impl Percentiles {
    /// Percentiles of nanosecond samples.
    pub fn of_ns(samples: &[u64]) -> Self {
        let mut v = samples.to_vec();
        v.sort_unstable();
        let at = |q: f64| {
            if v.is_empty() {
                return 0.0;
            }
            let i = ((v.len() as f64 * q).ceil() as usize).clamp(1, v.len()) - 1;
            v[i] as f64 / 1000.0
        };
        Self { samples: v.len(), p50_us: at(0.50), p99_us: at(0.99), p999_us: at(0.999) }
    }

    /// One JSON object on one line, to the nanosecond.
    pub fn json(&self) -> String {
        let r = |v: f64| crate::round_to(v, 3);
        crate::to_json(&Self { p50_us: r(self.p50_us), p99_us: r(self.p99_us), p999_us: r(self.p999_us), ..*self })
    }

    /// Reads the last line of `text` that is the object [`json`](Self::json) writes (a
    /// process's stdout may hold other lines).
    pub fn parse(text: &str) -> Result<Self, PercentilesReadError> {
        let line = crate::last_json_line(text, |l| l.contains("\"p50_us\"")).ok_or(PercentilesReadError::NoLine)?;
        Ok(serde_json::from_str(line)?)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn percentiles_are_written_to_the_nanosecond_and_read_back() {
        let p = Percentiles::of_ns(&[1_234_567, 10, 20, 30]);
        assert_eq!((p.samples, p.p50_us, p.p999_us), (4, 0.02, 1234.567));
        let line = Percentiles { p99_us: 1.234_56, ..p }.json();
        assert_eq!(line, r#"{"samples":4,"p50_us":0.02,"p99_us":1.235,"p999_us":1234.567}"#);
        assert_eq!(Percentiles::parse(&format!("{{\"other\":1}}\n{line}\nbye\n")).expect("a line").p99_us, 1.235);
    }

    #[test]
    fn output_without_percentiles_is_an_error() {
        assert!(matches!(Percentiles::parse("agent: done\n"), Err(PercentilesReadError::NoLine)));
        assert!(matches!(Percentiles::parse(r#"{"p50_us":"x"}"#), Err(PercentilesReadError::Json(_))));
    }
}
