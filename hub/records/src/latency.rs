//! Latency percentiles, as agents report them (`--report-latency`) and `iwsim bench` reads them.

/// Latency percentiles in microseconds.
#[derive(Debug, Clone, Copy, PartialEq, Default)]
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

    /// One JSON object.
    pub fn json(&self) -> String {
        format!(
            "{{\"samples\":{},\"p50_us\":{:.3},\"p99_us\":{:.3},\"p999_us\":{:.3}}}",
            self.samples, self.p50_us, self.p99_us, self.p999_us
        )
    }

    /// Reads the object `json` printed.
    pub fn parse(text: &str) -> Option<Self> {
        let line = text.lines().rev().find(|l| l.contains("\"p50_us\""))?;
        let field = |k: &str| -> Option<f64> {
            let key = format!("\"{k}\":");
            let rest = &line[line.find(&key)? + key.len()..];
            rest[..rest.find([',', '}'])?].parse().ok()
        };
        Some(Self {
            samples: field("samples")? as usize,
            p50_us: field("p50_us")?,
            p99_us: field("p99_us")?,
            p999_us: field("p999_us")?,
        })
    }
}
