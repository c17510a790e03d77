//! Repeated runs of a benchmark: the runs of every variant interleaved, and the median, min and
//! max of what each run measured.
//!
//! These machines are shared and noisy, so a figure is the median of several runs, shown with
//! its spread. Interleaving (run 1 of every variant, then run 2 of every variant, …) lets slow
//! drift in the machine's load weigh on every variant alike instead of on whichever ran last.
//!
//! ```
//! use bench_harness::repeat::{Spread, interleaved};
//!
//! // Two variants, three runs each: the closure sees (round, variant).
//! let runs = interleaved(3, 2, |round, variant| Ok::<_, std::convert::Infallible>((round * 10 + variant) as f64))
//!     .unwrap();
//! assert_eq!(runs[1], vec![1.0, 11.0, 21.0]);
//! let s = Spread::of(&runs[1]).unwrap();
//! assert_eq!((s.median, s.min, s.max, s.runs), (11.0, 1.0, 21.0, 3));
//! ```

/// Median, min and max of the values one variant measured over its runs.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct Spread {
    /// The median (the mean of the two middle values for an even count).
    pub median: f64,
    /// The smallest value.
    pub min: f64,
    /// The largest value.
    pub max: f64,
    /// How many values.
    pub runs: usize,
}

impl Spread {
    /// The spread of `values`; `None` when there are none.
    pub fn of(values: &[f64]) -> Option<Spread> {
        let mut sorted = values.to_vec();
        sorted.sort_unstable_by(f64::total_cmp);
        let n = sorted.len();
        let (&min, &max) = (sorted.first()?, sorted.last()?);
        let median = if n % 2 == 1 { sorted[n / 2] } else { (sorted[n / 2 - 1] + sorted[n / 2]) / 2.0 };
        Some(Spread { median, min, max, runs: n })
    }
}

/// Runs `measure(round, variant)` for `runs` rounds of `variants` variants, round by round, and
/// returns the results per variant in run order (`result[variant][round]`). Stops at the first
/// error.
pub fn interleaved<T, E>(
    runs: usize,
    variants: usize,
    mut measure: impl FnMut(usize, usize) -> Result<T, E>,
) -> Result<Vec<Vec<T>>, E> {
    let mut out: Vec<Vec<T>> = (0..variants).map(|_| Vec::with_capacity(runs)).collect();
    for round in 0..runs {
        for (variant, results) in out.iter_mut().enumerate() {
            results.push(measure(round, variant)?);
        }
    }
    Ok(out)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn spread_of_an_odd_count_is_the_middle_value() {
        let s = Spread::of(&[900.0, 700.0, 800.0, 1200.0, 650.0]).expect("values");
        assert_eq!(s, Spread { median: 800.0, min: 650.0, max: 1200.0, runs: 5 });
    }

    #[test]
    fn spread_of_an_even_count_takes_the_mean_of_the_two_middle_values() {
        let s = Spread::of(&[4.0, 1.0, 3.0, 2.0]).expect("values");
        assert_eq!((s.median, s.min, s.max, s.runs), (2.5, 1.0, 4.0, 4));
    }

    #[test]
    fn spread_of_one_run_is_that_run() {
        let s = Spread::of(&[42.0]).expect("values");
        assert_eq!(s, Spread { median: 42.0, min: 42.0, max: 42.0, runs: 1 });
    }

    #[test]
    fn spread_of_nothing_is_none() {
        assert_eq!(Spread::of(&[]), None);
    }

    #[test]
    fn runs_go_round_by_round_through_every_variant() {
        let mut order = Vec::new();
        let out = interleaved(2, 3, |round, variant| {
            order.push((round, variant));
            Ok::<_, ()>(round * 10 + variant)
        })
        .expect("no error");
        assert_eq!(order, vec![(0, 0), (0, 1), (0, 2), (1, 0), (1, 1), (1, 2)]);
        assert_eq!(out, vec![vec![0, 10], vec![1, 11], vec![2, 12]]);
    }

    #[test]
    fn the_first_error_stops_the_runs() {
        let mut calls = 0;
        let out = interleaved(3, 2, |round, variant| {
            calls += 1;
            if (round, variant) == (1, 0) { Err("hub failed") } else { Ok(()) }
        });
        assert_eq!(out, Err("hub failed"));
        assert_eq!(calls, 3);
    }
}
